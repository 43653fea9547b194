/* shaft_edges.h — a lit run's ends placed on its blockers' silhouette (docs/design.md
 * §4.5, "Shaft edges on the blockers"). The tree decides lit and shadowed per γ texel, at
 * the texel's centre, so a lit run ends at a texel boundary, up to a texel (of the map or
 * of the row, the coarser) from the shaft's true edge; a ray that crosses many shafts adds
 * those errors up. A shaft's edge is the light ray through its blocker's silhouette, and
 * rectify keeps, per texel, the triangle the map found nearest the light there. A run's
 * end moves to where the surface that triangle belongs to turns away in the ray's own
 * epipolar half-plane, when that lies close enough to the boundary (SHAFT_EDGE_REACH).
 *
 * In the ray's half-plane (eye at the origin): a = p·axis (axis towards the light), b =
 * p·across ≥ 0 (across: the ray's direction less its part along the axis). A point's γ is
 * b for a directional light, atan2(b, d_el − a) for a point or spot light (walk.h's γ);
 * its β is atan2(b, a). A triangle cuts the plane in a segment and shadows the ray over the
 * segment's γ extent where the segment's β is below the ray's; the ray never crosses the
 * segment (it would end there), so one end tells. */
#ifndef CLRAYS_SHAFT_EDGES_H
#define CLRAYS_SHAFT_EDGES_H
#include "common.h"
#include "atan2_approx.h"
#include "gamma_texels.h"
#include "inline_math.h"
#include "walk_features.h"

typedef struct {
    float3 axis;   /* towards the light */
    float3 across; /* in the ray's half-plane, across the axis */
    float3 normal; /* of the half-plane */
    float cos_beta;
    float sin_beta;
    float d_el;
    int directional;
} ray_plane_t;

/* The half-plane of a unit ray `dir`; 0 where the ray runs along the axis (no half-plane
 * to speak of: its runs keep their texel ends). A directional light's frame has d_el = 0
 * (a point light's lamp holding the eye never reaches a walk: lamp.py). */
ALWAYS_INLINE int ray_plane_of(global const epipolar_t* ep, float3 dir, ray_plane_t* plane)
{
    float3 axis = ep->axis.xyz;
    float cos_beta = inline_dot(dir, axis);
    float3 across = dir - cos_beta * axis;
    float sin_beta = inline_length(across);
    if (!(sin_beta > 1e-4f)) return 0;
    plane->axis = axis;
    plane->across = across / sin_beta;
    plane->normal = inline_cross(axis, plane->across);
    plane->cos_beta = cos_beta;
    plane->sin_beta = sin_beta;
    plane->d_el = ep->d_el;
    plane->directional = ep->d_el == 0.0f;
    return 1;
}

/* One end of a triangle's cut with the half-plane: its γ as a direction g, any positive
 * multiple of (1, γ) for a directional light and of (d_el − along, across) for a point or
 * spot light (γ = g.y / g.x, or atan2(g.y, g.x): ends compare by a cross product, and only
 * the one a run ends on takes the division or the arc tangent),
 * whether it lies in front of the ray (its β at most the ray's), and the triangle's edge
 * (0: v0 → v1, 1: v1 → v2, 2: v2 → v0) it lies on. */
typedef struct {
    float2 g;
    int blocks;
    int edge;
} cut_end_t;

/* Whether end p's γ is below end q's. */
ALWAYS_INLINE int gamma_below(cut_end_t p, cut_end_t q)
{
    return p.g.x * q.g.y - p.g.y * q.g.x > 0.0f;
}

ALWAYS_INLINE float cut_gamma(const ray_plane_t* plane, cut_end_t end)
{
    return plane->directional ? end.g.y / end.g.x : atan2_approx(end.g.y, end.g.x);
}

/* Triangles a run's end follows across shared edges, at most. At 320×180, 4 / 8 / 16 steps:
 * lattice 1.97 / 1.99 / 1.99 %, bunny 0.066 / 0.066 / 0.066 %, sun and demo the same. */
#define SHAFT_EDGE_STEPS 8
/* How far from the texel boundary an end may move: 1/SHAFT_EDGE_REACH of the row, and at
 * least a texel. The row's texel took its state from the map texel nearest its centre, in
 * its slice's plane, not the ray's: the blocker's edge can lie a few texels off, by an
 * offset between the planes that does not shrink with the texels. Measured against `exact`
 * (relative RMSE %) at 320×180 with 1024 γ texels, a window of 0.5 / 1 / 2 / 4 / 8 texels:
 * sun 0.27 / 0.15 / 0.099 / 0.096 / 0.096, demo 0.141 / 0.133 / 0.131 / 0.116 / 0.114,
 * lattice 2.32 / 2.21 / 1.99 / 1.99 / 2.09 (0.29, 0.144 and 2.35 with texel ends); on
 * slats under a lamp at 64×36 with a 64² map and 32 γ texels, 1 / 2 / 4 texels: 1.89 /
 * 1.96 / 2.16 (1.88 with texel ends): at 32 texels a texel is already that far. */
#define SHAFT_EDGE_REACH 256

/* One end of the cut: where edge `edge` (from vertex a, at signed height ha off the
 * half-plane's plane, to vertex b, at hb) crosses the plane. An end in the other
 * half-plane (off < 0) gets edge -1, which triangle_cut refuses. */
ALWAYS_INLINE cut_end_t cut_end(const ray_plane_t* plane, float3 a, float3 b, float ha, float hb, int edge)
{
    /* the point (b·ha − a·hb) / (ha − hb), kept times w = |ha − hb| > 0: no division;
     * unfused, so an edge's two triangles, which list its ends in either order, find one point */
#pragma OPENCL FP_CONTRACT OFF
    float w = ha - hb;
    float3 p = b * ha - a * hb;
    p = w < 0.0f ? -p : p;
    w = inline_fabs(w);
    float along = inline_dot(p, plane->axis), off = inline_dot(p, plane->across);
    cut_end_t end;
    end.g = plane->directional ? (float2)(w, off) : (float2)(plane->d_el * w - along, off);
    end.blocks = off * plane->cos_beta - along * plane->sin_beta <= 0.0f; /* β_p = atan2(off, along) at most the ray's β */
    end.edge = off < 0.0f ? -1 : edge;
    return end;
}

/* Triangle `tri`'s cut with the ray's half-plane, its ends in rising γ (*low, *high); 0 when
 * the triangle misses the plane or reaches across the axis. The vertices lie on the
 * plane's two sides (h ≥ 0 or not) one against two, or all on one: the cut, if any, runs
 * over the two edges of the vertex alone on its side. Straight-line code without arrays
 * indexed at run time, which PoCL kept in memory: a loop over the edges filling an array of
 * ends had cost demo's walks 1.0 ms more and sun's 1.8 at 1280×720 (bench/RESULTS.md, "The
 * walks' run ends in straight-line code"). */
ALWAYS_INLINE int triangle_cut(const ray_plane_t* plane, global const float4* vertices, int tri, cut_end_t* low,
                               cut_end_t* high)
{
    float3 v0 = vertices[3 * tri].xyz, v1 = vertices[3 * tri + 1].xyz, v2 = vertices[3 * tri + 2].xyz;
    float h0 = inline_dot(v0, plane->normal), h1 = inline_dot(v1, plane->normal), h2 = inline_dot(v2, plane->normal);
    int s0 = h0 >= 0.0f, s1 = h1 >= 0.0f, s2 = h2 >= 0.0f;
    if (s0 == s1 && s1 == s2) return 0;
    cut_end_t first, second; /* in the edges' order (edge i: vertex i → vertex i + 1) */
    if (s1 == s2) { /* v0 alone: edges 0 and 2 */
        first = cut_end(plane, v0, v1, h0, h1, 0);
        second = cut_end(plane, v2, v0, h2, h0, 2);
    } else if (s0 == s2) { /* v1 alone: edges 0 and 1 */
        first = cut_end(plane, v0, v1, h0, h1, 0);
        second = cut_end(plane, v1, v2, h1, h2, 1);
    } else { /* v2 alone: edges 1 and 2 */
        first = cut_end(plane, v1, v2, h1, h2, 1);
        second = cut_end(plane, v2, v0, h2, h0, 2);
    }
    if (first.edge < 0 || second.edge < 0) return 0;
    int swap = gamma_below(second, first);
    *low = swap ? second : first;
    *high = swap ? first : second;
    return 1;
}

/* Whether the surface turns back in γ from `tri` across its edge `edge` into `next`, in any
 * half-plane through the light that cuts that edge: where one of the two faces the light and
 * the other does not (their normals made to agree across the edge), the edge is a silhouette
 * seen from the light. In a plane through the light the cut of a triangle runs along
 * n × plane normal, and γ grows along it on the side the triangle faces the light from; so
 * the cut goes on growing across the edge exactly where both face it alike. Read from two
 * bytes, this spares the walk the neighbour's cut at most edges it stops at (bench/RESULTS.md,
 * "The walks' run ends in straight-line code"). */
ALWAYS_INLINE int surface_turns(global const uchar* sides, int tri, int next, int edge)
{
    uint own = sides[tri], other = sides[next];
    return (((own ^ other) & FACES_LIGHT) != 0u) != ((own >> edge & 1u) != 0u);
}

/* Where a lit run ends before the shadowed texel whose blocker is `tri` (`begins`: where a
 * lit run begins after it), between γ `from` and `to` (a window either side of the
 * boundary); `fallback`, the texel boundary, where that is not found there. From the
 * blocker's cut, the surface is followed across the triangles' shared edges (`neighbours`,
 * three per triangle, -1 at a border) towards the lit side for as long as its cut goes on
 * that way in front of the ray: where it turns back, or ends at a border, is the silhouette
 * in the ray's plane, and the shaft's edge. */
ALWAYS_INLINE float shaft_edge(const ray_plane_t* plane, global const float4* vertices, global const int* neighbours,
                               global const uchar* sides, int tri, int begins, float from, float to, float fallback)
{
    cut_end_t low, high;
    if (tri < 0 || !triangle_cut(plane, vertices, tri, &low, &high)) return fallback;
    cut_end_t edge = begins ? high : low;
    if (!edge.blocks) return fallback;
    for (int step = 0; step < SHAFT_EDGE_STEPS; ++step) {
        int next = neighbours[3 * tri + edge.edge];
        if (next < 0 || surface_turns(sides, tri, next, edge.edge) || !triangle_cut(plane, vertices, next, &low, &high))
            break;
        /* the neighbour's cut shares this end, on the edge that leads back; its other end goes on */
        cut_end_t far = neighbours[3 * next + low.edge] == tri ? high : low;
        if (!(begins ? gamma_below(edge, far) : gamma_below(far, edge)) || !far.blocks) break;
        tri = next;
        edge = far;
    }
    float gamma = cut_gamma(plane, edge);
    return gamma >= from && gamma <= to ? gamma : fallback;
}

/* What a row's walk keeps to place its runs' ends: the ray's half-plane, the row's
 * blockers, where the walk began and where the last run it placed ended. */
typedef struct {
    ray_plane_t plane;
    int planar;
    global const int* blockers;
    int first;
    float previous_end;
    float gamma_begin;
    float gamma_end;
    float window; /* how far an end may move, texels */
} run_edges_t;

inline run_edges_t run_edges_of(global const epipolar_t* ep, float3 dir, const walk_features_t* features, int slice, int first, float gamma_begin,
                                float gamma_end)
{
    run_edges_t edges;
    edges.planar = ray_plane_of(ep, dir, &edges.plane);
    edges.blockers = features->edge_rows + (size_t)slice * ep->gamma_samples;
    edges.first = first;
    edges.previous_end = gamma_begin;
    edges.gamma_begin = gamma_begin;
    edges.gamma_end = gamma_end;
    edges.window = fmax(1.0f, (float)ep->gamma_samples / (float)SHAFT_EDGE_REACH);
    return edges;
}

/* A lit run of texels [run_start, run_end), at γ [*run0, *run1) (its texel boundaries,
 * clipped to the walk), with its ends moved onto the blockers' edges: its start where a
 * shadowed texel precedes it in this walk, its end where one follows (`closed`). The runs
 * stay in order, none overlapping the one before. 0: nothing of the run is left. */
inline int place_run_ends(run_edges_t* edges, const walk_features_t* features, gamma_texels_t texels,
                          int run_start, int run_end, int closed, float* run0, float* run1)
{
    if (!edges->planar) return *run1 > *run0;
    float window = edges->window;
    if (run_start > edges->first)
        *run0 = shaft_edge(&edges->plane, features->edge_vertices, features->edge_neighbours,
                           features->edge_sides, edges->blockers[run_start - 1], 1,
                           gamma_at_texel(texels, (float)run_start - window),
                           gamma_at_texel(texels, (float)run_start + window), *run0);
    if (closed)
        *run1 = shaft_edge(&edges->plane, features->edge_vertices, features->edge_neighbours,
                           features->edge_sides, edges->blockers[run_end], 0,
                           gamma_at_texel(texels, (float)run_end - window),
                           gamma_at_texel(texels, (float)run_end + window), *run1);
    *run0 = clamp(*run0, edges->previous_end, edges->gamma_end);
    *run1 = clamp(*run1, edges->gamma_begin, edges->gamma_end);
    edges->previous_end = fmax(*run0, *run1);
    return *run1 > *run0;
}

#endif
