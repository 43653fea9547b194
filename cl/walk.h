/* walk.h — one camera ray in a light's epipolar frame (docs/design.md §4.5 "traverse"):
 * its β and its extent in γ, the two slices nearest it, and the walk along one row of
 * the min-max tree that integrates its lit runs. traverse.cl walks two rows per camera
 * sample with it; sampling.cl walks one row per epipolar sample, and two for the pixels
 * no sample represents. */
#ifndef CLRAYS_WALK_H
#define CLRAYS_WALK_H

#include "gamma_texels.h"
#include "integrand.h"
#include "light_texture.h"
#include "minmax.h"
#include "inline_math.h"
#include "walk_features.h"
#ifdef SHAFT_EDGES
#include "shaft_edges.h"
#endif
#ifdef RELIEF_CUTS
#include "relief_cuts.h"
#endif

/* TRAVERSAL_TREE and TRAVERSAL_SCAN come from clrays/structs.py (-D). */
#ifndef TRAVERSAL
#define TRAVERSAL TRAVERSAL_TREE
#endif

/* A lit run's radiance: the integrand tables' segment, times the light's texture along
 * this row when it has one. */
inline float3 unweighted_run_radiance(global const integrand_t* in, global const float* tables,
                                      global const frame_t* frame, const integrand_row_t* ray,
                                      const walk_features_t* features, global const float* row_prefix,
                                      gamma_texels_t texels, float gamma0, float gamma1)
{
    float3 untextured = segment_radiance(in, tables, frame, ray, gamma0, gamma1);
#ifdef LIGHT_TEXTURE
    if (!features->textured->textured || !(gamma1 > gamma0)) return untextured;
    return textured_run_radiance(features->textured, features->basis, row_prefix, texels, ray, untextured, gamma0,
                                 gamma1);
#else
    return untextured;
#endif
}

#ifdef TRANSPARENCY_WEIGHTED_WALK
/* MBOIT's one walk (transparency_walk.cl): a run's radiance split at the pieces of the ray,
 * each piece's part weighted by the fog's weight there, T(s) − T(D) (docs/design.md, the
 * camera side). Piece j is [piece_gamma[j], piece_gamma[j + 1]). */
inline float3 run_radiance(global const integrand_t* in, global const float* tables, global const frame_t* frame,
                           const integrand_row_t* ray, const walk_features_t* features, global const float* row_prefix,
                           gamma_texels_t texels, float gamma0, float gamma1)
{
    float3 radiance = (float3)(0.0f);
    for (int j = 0; j <= WALK_PIECES; ++j) {
        float begin = fmax(gamma0, features->piece_gamma[j]), end = fmin(gamma1, features->piece_gamma[j + 1]);
        if (end > begin)
            radiance += features->piece_weight[j].xyz
                        * unweighted_run_radiance(in, tables, frame, ray, features, row_prefix, texels, begin, end);
    }
    return radiance;
}
#else
#define run_radiance unweighted_run_radiance
#endif

/* A camera ray's part of the light's frame: its integrand row (β), its extent
 * [gamma_begin, gamma_end) and the chord inside the lamp [gamma_lamp0, gamma_lamp1),
 * which the walks leave out. */
typedef struct {
    integrand_row_t ray;
    float gamma_begin;
    float gamma_end;
    float gamma_lamp0;
    float gamma_lamp1;
#ifdef SHAFT_EDGES
    float3 dir; /* the ray's unit direction, whose half-plane shaft_edges.h cuts the blockers with */
#endif
#ifdef RELIEF_CUTS
    relief_shadow_t relief; /* the reliefs' shadow along the ray (relief_cuts.h), once the first walk found it */
    int relief_found;
#endif
#ifdef MEDIUM_VARYING
    medium_ray_t medium; /* the ray's prefix of in-scattering (medium_walk.h), built by its first lit run */
    int medium_built;    /* whether medium.source is set */
    float3 medium_dir;     /* the ray's unit direction ... */
    float medium_distance; /* ... and length, which the prefix is built along */
#endif
} ray_span_t;

/* The unit direction of camera sample `sample` (its pixel's ray through its offset):
 * view_ray's (lighting.h) with its built-ins inlined (inline_math.h), so that gather's
 * work-items run several at a time. */
ALWAYS_INLINE float3 camera_ray(global const frame_t* frame, global const view_t* views,
                                global const float2* offsets, int sample)
{
    int pixel = sample / frame->spp;
    float2 s = view_screen(views, pixel % frame->width, pixel / frame->width, offsets[sample % frame->spp]);
    if (views->projection != PROJECTION_PERSPECTIVE) return views->forward.xyz;
    float3 right = views->right.xyz * (s.x * views->scale_x);
    float3 up = views->up.xyz * (s.y * views->scale_y);
    return inline_normalize(views->forward.xyz + right + up);
}

/* β of a unit direction, with sin β and cos β. Clamped, not tested: a ray through a
 * point light (β = 0) or straight away from a light (β = π) has a finite integral, and
 * the clamp gives it a γ extent of SIN_BETA_MIN·s that the row coordinates resolve. β
 * stays below float32(π), the S of an unblocked light ray, so that the ray away from the
 * light sees those as lit. */
ALWAYS_INLINE float ray_beta(global const epipolar_t* ep, float3 dir, float* sin_beta, float* cos_beta)
{
    *cos_beta = inline_dot(dir, ep->axis.xyz);
    *sin_beta = inline_fmax(inline_length(inline_cross(dir, ep->axis.xyz)), SIN_BETA_MIN);
    return inline_fmin(atan2_approx(*sin_beta, *cos_beta), nextafter(M_PI_F, 0.0f));
}

/* What ray_span leaves to the rest once the lit γ [span->gamma_begin, span->gamma_end] of
 * the ray up to `distance` is set: the lamp's chord and the integrand's row. Where no
 * visible ray has extent in γ (the bounds rectify reduced, which the host does not read)
 * every span is empty, and the light adds nothing. */
ALWAYS_INLINE int finish_span(global const epipolar_t* ep, global const frame_t* frame,
                              global const integrand_t* integrand, int directional, float3 dir, float beta,
                              float sin_beta, float cos_beta, float distance, ray_span_t* span)
{
#ifdef RELIEF_CUTS
    span->relief_found = 0;
#endif
    /* camera.near (lighting.h's camera_ray_start): the ray's lit γ begins at its start t0, so
     * every run [a, b] is [max(a, t0), b]; shade scales the in-scattering by e^{σt·t0}. */
    if (frame->near_plane.w > 0.0f) {
        float start = camera_ray_start(frame, dir);
        float gamma_start = directional ? start * sin_beta
                                        : atan2_approx(start * sin_beta, ep->d_el - start * cos_beta);
        span->gamma_begin = inline_fmax(span->gamma_begin, gamma_start);
    }
#ifdef MEDIUM_VARYING
    span->medium_built = 0;
    span->medium_distance = distance;
#endif
    if (!(span->gamma_end > span->gamma_begin) || integrand->no_extent) return 0;
    /* The lamp (lighting.h): a ray that passes within its radius of a point or spot light
     * leaves out the chord inside it, as exact does; this keeps a ray through the light
     * finite. For every other ray the chord is empty. Its ends are kept within the lit γ
     * (γ grows along the ray: the same as keeping them within the lit depths). */
    span->gamma_lamp0 = span->gamma_lamp1 = span->gamma_end;
    float radius = frame->lamp_radius, miss = ep->d_el * sin_beta;
    if (!directional && miss < radius) {
        float closest = ep->d_el * cos_beta, half_chord = inline_sqrt(radius * radius - miss * miss);
        float s0 = inline_clamp(closest - half_chord, 0.0f, distance);
        float s1 = inline_clamp(closest + half_chord, 0.0f, distance);
        span->gamma_lamp0 = inline_clamp(atan2_approx(s0 * sin_beta, ep->d_el - s0 * cos_beta), span->gamma_begin,
                                         span->gamma_end);
        span->gamma_lamp1 = inline_clamp(atan2_approx(s1 * sin_beta, ep->d_el - s1 * cos_beta), span->gamma_begin,
                                         span->gamma_end);
    }
    span->ray = integrand_row(integrand, beta, sin_beta, cos_beta);
#ifdef MEDIUM_VARYING
    span->ray.medium = &span->medium;
#endif
    return 1;
}

/* ray_span of a spot light's ray, its half-plane's lit wedge of γ given (lighting.h's
 * lit_wedge): the part of [0, γ_end] within it (lit_sweep). */
inline int ray_span_in_wedge(global const epipolar_t* ep, global const frame_t* frame,
                             global const integrand_t* integrand, float3 dir, float distance, float2 wedge,
                             ray_span_t* span)
{
    float sin_beta, cos_beta;
    float beta = ray_beta(ep, dir, &sin_beta, &cos_beta);
#ifdef SHAFT_EDGES
    span->dir = dir;
#endif
#ifdef MEDIUM_VARYING
    span->medium_dir = dir;
#endif
    float2 lit = lit_sweep(atan2_approx(distance * sin_beta, ep->d_el - distance * cos_beta), wedge);
    span->gamma_begin = lit.x;
    span->gamma_end = lit.y;
    return finish_span(ep, frame, integrand, 0, dir, beta, sin_beta, cos_beta, distance, span);
}

/* The γ extent of the ray along dir up to distance; 0 when it has none (it misses a
 * spot light's cone, or has no extent in γ). A spot light's cone is the wedge of the ray's
 * own half-plane (sin β not clamped there: the wedge's x and y must scale alike). */
inline int ray_span(global const epipolar_t* ep, global const light_t* light, global const frame_t* frame,
                    global const integrand_t* integrand, float3 dir, float distance, ray_span_t* span)
{
    if (light->type == LIGHT_SPOT) {
        float3 axis = ep->axis.xyz;
        float2 wedge = ray_wedge(light, axis, ep->u.xyz, dir, inline_length(inline_cross(dir, axis)));
        return ray_span_in_wedge(ep, frame, integrand, dir, distance, wedge, span);
    }
    float sin_beta, cos_beta;
    float beta = ray_beta(ep, dir, &sin_beta, &cos_beta);
    int directional = light->type == LIGHT_DIRECTIONAL;
#ifdef SHAFT_EDGES
    span->dir = dir;
#endif
#ifdef MEDIUM_VARYING
    span->medium_dir = dir;
#endif
    /* The ray from the eye starts at γ = atan2(+0, d_el) = +0: no arc tangent for it. */
    span->gamma_begin = 0.0f;
    span->gamma_end = directional ? distance * sin_beta : atan2_approx(distance * sin_beta, ep->d_el - distance * cos_beta);
    return finish_span(ep, frame, integrand, directional, dir, beta, sin_beta, cos_beta, distance, span);
}

/* The two slices whose centres bracket the angle α, and the weight t of the second. The
 * slices wrap around when they close the circle, and clamp at the ends of a partial fan. */
ALWAYS_INLINE void slices_around(global const epipolar_t* ep, float alpha, int* i0, int* i1, float* t)
{
    float offset = alpha - ep->alpha_min;
    offset -= 2.0f * M_PI_F * inline_floor(offset / (2.0f * M_PI_F));
    /* A partial fan: angles in the gap before alpha_min count as negative offsets. */
    if (!ep->full_circle && offset > M_PI_F + 0.5f * ep->alpha_step * (float)ep->slices)
        offset -= 2.0f * M_PI_F;
    float f = offset / ep->alpha_step - 0.5f;
    *i0 = (int)inline_floor(f);
    *t = f - (float)*i0;
    *i1 = *i0 + 1;
    if (ep->full_circle) {
        /* i0 ∈ [-1, slices - 1] and i1 ∈ [0, slices] here: a conditional wrap, not an
         * integer modulo (an integer division per camera sample on PoCL). */
        *i0 = *i0 < 0 ? *i0 + ep->slices : *i0;
        *i1 = *i1 >= ep->slices ? *i1 - ep->slices : *i1;
    } else {
        *i0 = inline_clamp_int(*i0, 0, ep->slices - 1);
        *i1 = inline_clamp_int(*i1, 0, ep->slices - 1);
    }
}

/* The two slices nearest dir, and the weight t of the second. */
inline void nearest_slices(global const epipolar_t* ep, float3 dir, int* i0, int* i1, float* t)
{
    slices_around(ep, atan2_approx(inline_dot(dir, ep->w.xyz), inline_dot(dir, ep->u.xyz)), i0, i1, t);
}

#ifdef RELIEF_CUTS
/* A lit run's radiance with the relief's shadow (relief_cuts.h) taken out of it: the runs
 * come in rising γ, so the stretches wholly before one are passed for good. */
inline float3 lit_run_radiance(global const integrand_t* in, global const float* tables, global const frame_t* frame,
                               const integrand_row_t* ray, const walk_features_t* features,
                               global const float* row_prefix, gamma_texels_t texels,
                               const relief_shadow_t* shadow, int* next, float gamma0, float gamma1)
{
    while (*next < shadow->bounds && shadow->bound[*next + 1] <= gamma0) *next += 2;
    float3 radiance = (float3)(0.0f);
    float from = gamma0;
    for (int k = *next; from < gamma1; k += 2) {
        if (k >= shadow->bounds || shadow->bound[k] >= gamma1) {
            radiance += run_radiance(in, tables, frame, ray, features, row_prefix, texels, from, gamma1);
            break;
        }
        if (shadow->bound[k] > from)
            radiance += run_radiance(in, tables, frame, ray, features, row_prefix, texels, from, shadow->bound[k]);
        from = inline_fmax(from, shadow->bound[k + 1]);
    }
    return radiance;
}
#endif

/* Radiance of the lit part of [gamma_begin, gamma_end) of the ray along row `slice`.
 * Adjacent lit nodes merge into one run, so the integrand is evaluated once per run; with
 * SHAFT_EDGES a run's ends move onto its blockers' silhouettes (shaft_edges.h).
 *
 * TRAVERSAL_TREE walks the tree without a stack: a node whose min > β is wholly lit,
 * one whose max ≤ β wholly shadowed, else descend; after a node, move to the next
 * one and climb while its index is even. TRAVERSAL_SCAN reads every texel. */
inline float3 walk_row(global const epipolar_t* ep, global const float2* row, ray_span_t* span, int slice,
                       float gamma_begin, float gamma_end, global const integrand_t* in,
                       global const float* tables, global const frame_t* frame, const walk_features_t* features,
                       global const float* row_prefix)
{
    const integrand_row_t* ray = &span->ray;
    float beta = ray->beta;
    int n = ep->gamma_samples;
    gamma_texels_t texels = gamma_texels_of(ep);
    int end = inline_min(n, (int)-inline_floor(-gamma_texel_coord(texels, gamma_end))); /* ceil */
    float3 radiance = (float3)(0.0f);
    int run_start = -1, run_end = 0;
    int position = inline_clamp_int((int)inline_floor(gamma_texel_coord(texels, gamma_begin)), 0, n);
#ifdef SHAFT_EDGES
    run_edges_t edges = run_edges_of(ep, span->dir, features, slice, position, gamma_begin, gamma_end);
#endif
#ifdef RELIEF_CUTS
    if (!span->relief_found) { /* once per ray: its rows share its half-plane */
        relief_shadow_of(ep, &edges.plane, edges.planar, span->gamma_end, features, &span->relief);
        span->relief_found = 1;
    }
    int relief_next = 0;
#endif
    /* Past `end` the open run, if any, closes without a shadowed texel after it. */
    for (int done = position >= end;; done = position >= end) {
        int size = 0;
        int lit = 0;
        if (!done) {
#if TRAVERSAL == TRAVERSAL_TREE
            /* The largest node starting at position: climb while the index is even. */
            int level = position == 0 ? ep->levels : inline_min(ep->levels, 31 - __builtin_clz(position & -position));
            for (;;) {
                float2 node = row[level_offset(n, level) + (position >> level)];
                if (node.x > beta) { lit = 1; break; }
                if (node.y <= beta) { lit = 0; break; }
                --level; /* mixed: descend to the left child */
            }
            size = 1 << level;
#else
            lit = row[position].x > beta;
            size = 1;
#endif
        }
        if (lit) {
            if (run_start < 0) run_start = position;
            run_end = position + size;
        } else if (run_start >= 0) {
            float run0 = inline_fmax(gamma_at_texel(texels, (float)run_start), gamma_begin);
            float run1 = inline_fmin(gamma_at_texel(texels, (float)run_end), gamma_end);
#ifdef SHAFT_EDGES
            if (place_run_ends(&edges, features, texels, run_start, run_end, !done, &run0, &run1))
#endif
#ifdef RELIEF_CUTS
            radiance += lit_run_radiance(in, tables, frame, ray, features, row_prefix, texels, &span->relief,
                                         &relief_next, run0, run1);
#else
            radiance += run_radiance(in, tables, frame, ray, features, row_prefix, texels, run0, run1);
#endif
            run_start = -1;
        }
        if (done) break;
        position += size;
    }
    return radiance;
}

#include "translucent_walk.h"

/* The radiance of a ray's lit runs along slice i's row, the lamp's chord left out. */
inline float3 row_radiance(global const epipolar_t* ep, global const float2* tree, int i, ray_span_t* span,
                           global const integrand_t* in, global const float* tables, global const frame_t* frame,
                           const walk_features_t* features)
{
    global const float2* row = tree + (size_t)i * 2 * (size_t)ep->gamma_samples;
#ifdef LIGHT_TEXTURE
    size_t prefix_stride = features->textured->textured
                               ? (size_t)3 * (features->textured->rank + 1) * (ep->gamma_samples + 1) : 0;
    global const float* row_prefix = features->prefix + i * prefix_stride;
#else
    global const float* row_prefix = 0; /* (read only for a textured light) */
#endif
#ifdef MEDIUM_VARYING /* once per ray: its rows share its prefix, which its first lit run builds */
    if (!span->medium_built) {
        medium_ray_source_t source = {features->medium, frame, ep, in->light_type == LIGHT_DIRECTIONAL,
                                      in->amplitude.xyz, span->medium_dir, span->medium_distance,
                                      span->ray.sin_beta, span->ray.cos_beta};
        span->medium.source = source;
        span->medium.built = 0;
        span->medium_built = 1;
    }
#endif
#ifdef TRANSLUCENT_LAYERS /* a row that translucent layers cross: texel by texel (translucent_walk.h) */
    if (features->layer_rows[i]) {
        size_t layers_at = (size_t)i * ep->gamma_samples * TRANSLUCENT_LAYERS;
        global const float* beta_row = features->layer_beta + layers_at;
        global const uint2* clear_row = features->layer_clear + layers_at;
        float3 radiance = walk_row_translucent(ep, row, beta_row, clear_row, &span->ray, span->gamma_begin,
                                               span->gamma_lamp0, in, tables, frame, features, row_prefix);
        if (span->gamma_lamp1 < span->gamma_end)
            radiance += walk_row_translucent(ep, row, beta_row, clear_row, &span->ray, span->gamma_lamp1,
                                             span->gamma_end, in, tables, frame, features, row_prefix);
        return radiance;
    }
#endif
    float3 radiance = walk_row(ep, row, span, i, span->gamma_begin, span->gamma_lamp0, in, tables, frame, features,
                               row_prefix);
    if (span->gamma_lamp1 < span->gamma_end)
        radiance += walk_row(ep, row, span, i, span->gamma_lamp1, span->gamma_end, in, tables, frame, features,
                             row_prefix);
    return radiance;
}

#endif
