/* walk_features.h — what a row walk (walk.h) may carry besides the tree and the integrand:
 * each feature is built only where its stage ran, and declares here, once, its kernel
 * arguments and how a kernel hands them to its walks (docs/design.md §4.5, "Features of
 * the walk"; the host side is clrays/stages/features.py).
 *
 *   LIGHT_TEXTURE        a textured light's tables (stage light_texture,
 *                        docs/light-textures.md): its integrand in γ and the prefix sums
 *   TRANSLUCENT_LAYERS   the light's translucent layers rectified along the rows (stage
 *                        translucency, translucent_walk.h), K of them per texel
 *   SHAFT_EDGES          each texel's blocker and the frame's triangles, which place a lit
 *                        run's ends on its blockers' silhouettes (shaft_edges.h)
 *   RELIEF_CUTS          the reliefs' outline seen from the light, which the walk cuts in
 *                        its ray's own half-plane (relief_cuts.h; with SHAFT_EDGES only)
 *   MEDIUM_VARYING       a bounded or heterogeneous medium (medium.h; MEDIUM_BOUNDED, _HEIGHT,
 *                        _GRID): each ray's lit runs come from its own prefix of in-scattering
 *                        (medium_walk.h) instead of the integrand tables
 *   TRANSPARENCY_WEIGHTED_WALK  MBOIT's fog weight along the ray, in pieces (the kernel
 *                        fills them itself: transparency_walk.cl)
 *
 * A walking kernel takes WALK_FEATURE_ARGS after its own arguments, in this order: light
 * texture, translucent layers, shaft edges, relief cuts, the medium (MEDIUM_ARGS); `walk_features_t features; ATTACH_WALK_FEATURES(features)`
 * hands them on. Without a feature its arguments and members are not there at all, and the
 * kernel is the one it was before the feature existed. */
#ifndef CLRAYS_WALK_FEATURES_H
#define CLRAYS_WALK_FEATURES_H

#include "common.h"
#include "medium.h"
#ifdef MEDIUM_VARYING
#include "medium_walk.h"
#endif

/* edge_sides' bit for a triangle whose normal points to the light's side of its plane. */
#define FACES_LIGHT 8u

typedef struct {
    int none; /* (a struct needs a member when no feature is built) */
#ifdef LIGHT_TEXTURE
    global const textured_integrand_t* textured;
    global const float* basis;  /* the γ basis */
    global const float* prefix; /* the prefix sums, one block per slice */
#endif
#ifdef TRANSLUCENT_LAYERS
    global const float* layer_beta;
    global const uint2* layer_clear;
    global const int* layer_rows;
#endif
#ifdef SHAFT_EDGES
    global const int* edge_rows;         /* each texel's blocker, rectify's row_triangles */
    global const float4* edge_vertices;  /* the frame's triangles, eye space */
    global const int* edge_neighbours;   /* each triangle's neighbour across each edge, -1: none */
    global const uchar* edge_sides;      /* per triangle: bit k, the neighbour across edge k wound the other
                                          * way; FACES_LIGHT, its normal towards the light (shaft_edges.cl) */
#endif
#ifdef RELIEF_CUTS
    global const float4* relief_edges;    /* the reliefs' outline by α bin, eye space: (lower end, change),
                                             (higher end, nearest distance from the eye's light ray) */
    global const int* relief_bin_offsets; /* each α bin's first edge in relief_edges */
    int relief_bins;
    int relief_eye_count; /* the reliefs' triangles between the eye and the light */
#endif
#ifdef MEDIUM_VARYING
    walk_medium_t medium;
#endif
#ifdef TRANSPARENCY_WEIGHTED_WALK
    float piece_gamma[WALK_PIECES + 2];
    float4 piece_weight[WALK_PIECES + 1];
#endif
} walk_features_t;

#ifdef LIGHT_TEXTURE
#define LIGHT_TEXTURE_ARGS                                                                                    \
    , global const textured_integrand_t* textured, global const float* texture_basis, global const float* texture_prefix
#define ATTACH_LIGHT_TEXTURE(f) (f).textured = textured; (f).basis = texture_basis; (f).prefix = texture_prefix;
#endif
#ifdef TRANSLUCENT_LAYERS
#define RECTIFIED_LAYER_ARGS                                                                                  \
    , global const float* layer_beta, global const uint2* layer_clear, global const int* layer_rows
#define ATTACH_RECTIFIED_LAYERS(f)                                                                            \
    (f).layer_beta = layer_beta; (f).layer_clear = layer_clear; (f).layer_rows = layer_rows;
#endif
#ifdef SHAFT_EDGES
#define SHAFT_EDGE_ARGS , global const int* edge_rows, global const float4* edge_vertices, \
    global const int* edge_neighbours, global const uchar* edge_sides
#define ATTACH_SHAFT_EDGES(f) (f).edge_rows = edge_rows; (f).edge_vertices = edge_vertices; \
    (f).edge_neighbours = edge_neighbours; (f).edge_sides = edge_sides;
#endif
#ifdef RELIEF_CUTS
#define RELIEF_CUT_ARGS , global const float4* relief_edges, global const int* relief_bin_offsets, \
    int relief_bins, int relief_eye_count
#define ATTACH_RELIEF_CUTS(f) (f).relief_edges = relief_edges; (f).relief_bin_offsets = relief_bin_offsets; \
    (f).relief_bins = relief_bins; (f).relief_eye_count = relief_eye_count;
#endif
#ifdef MEDIUM_VARYING /* (MEDIUM_ARGS: medium.h; a walking kernel's light_t buffer is `lights`) */
#define ATTACH_MEDIUM(f) (f).medium.medium = medium; (f).medium.density_grid = density_grid; \
    (f).medium.light_depth_grid = light_depth_grid; (f).medium.lights = lights;
#endif
/* A feature not built: no arguments, nothing to hand on. */
#ifndef LIGHT_TEXTURE_ARGS
#define LIGHT_TEXTURE_ARGS
#define ATTACH_LIGHT_TEXTURE(f)
#endif
#ifndef RECTIFIED_LAYER_ARGS
#define RECTIFIED_LAYER_ARGS
#define ATTACH_RECTIFIED_LAYERS(f)
#endif

#ifndef SHAFT_EDGE_ARGS
#define SHAFT_EDGE_ARGS
#define ATTACH_SHAFT_EDGES(f)
#endif

#ifndef RELIEF_CUT_ARGS
#define RELIEF_CUT_ARGS
#define ATTACH_RELIEF_CUTS(f)
#endif

#ifndef ATTACH_MEDIUM
#define ATTACH_MEDIUM(f)
#endif

#define WALK_FEATURE_ARGS LIGHT_TEXTURE_ARGS RECTIFIED_LAYER_ARGS SHAFT_EDGE_ARGS RELIEF_CUT_ARGS MEDIUM_ARGS
#define ATTACH_WALK_FEATURES(features) ATTACH_LIGHT_TEXTURE(features) ATTACH_RECTIFIED_LAYERS(features) \
    ATTACH_SHAFT_EDGES(features) ATTACH_RELIEF_CUTS(features) ATTACH_MEDIUM(features)

#endif
