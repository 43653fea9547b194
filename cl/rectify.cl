/* rectify — the shadow map resampled into epipolar coordinates: for each slice α and
 * light angle γ, the view angle β of the light ray's blocker, S[α, γ] (docs/design.md §2, §3).
 * Reads views, lights, shadow_depth, epipolar, slice_sides, texel_angles; writes level 0
 * of the min-max tree (float2 (S, S) per texel). rectify_bounds reads camera_depth and reduces the
 * β and γ ranges the visible rays need (as pseudo-angles, see pseudo_angle_lanes);
 * rectify_ranges turns them into epipolar->gamma_step, texel_angles and the ranges.
 *
 *   tree row α: | level 0: N texels | level 1: N/2 | level 2: N/4 | ... | 1 | (float2 min, max)
 *               0                   N            3N/2                    2N-1 */
#include "lighting.h"
#include "atan2_approx.h"
#include "lanes.h"
#include "visible_ranges.h"

#define PI_F 3.14159265358979f

/* An int8 aligned as its elements are: a row's blockers stored 8 at a time. */
typedef int8 __attribute__((aligned(4))) int8_at_int;

/* Camera samples per rectify_bounds work-item (clrays/stages/rectify.py BOUNDS_CHUNK), LANES
 * at a time. */
#ifndef BOUNDS_CHUNK
#define BOUNDS_CHUNK 64
#endif
#if BOUNDS_CHUNK % LANES != 0
#error "BOUNDS_CHUNK must be a multiple of LANES"
#endif

/* A stand-in for the angle θ ∈ [0, π] of (x, y), y ≥ 0, that rises with it: tan(θ/2) up to
 * π/2, 2 - cot(θ/2) above. rectify_bounds reduces it instead of θ and the host takes the arc
 * tangent of the extremes only (clrays/stages/rectify.py angle_of_pseudo): PoCL's atan2 cost
 * more than the rest of the kernel, twice per camera sample.
 * On each lane: both sides computed, one kept. */
inline float_lanes pseudo_angle_lanes(float_lanes x, float_lanes y)
{
    float_lanes r = sqrt_lanes(x * x + y * y);
    float_lanes ahead = r + x > 0.0f ? y / (r + x) : 0.0f;
    return x >= 0.0f ? ahead : 2.0f - y / (r - x);
}

/* One work-item per BOUNDS_CHUNK camera samples, LANES at a time as float8 (lanes.h; PoCL
 * would run the scalar loop one sample at a time, docs/design.md §4.5): it reduces their β
 * and γ in registers and then updates the three bounds, so the atomics do not serialize
 * every sample on them. Each sample's ray is view_ray's and its β and γ are the scalar
 * formulas' (docs/design.md §3), operation for operation: the bounds are the same bits. */
kernel void rectify_bounds(global const frame_t* frame, global const view_t* views,
                           global const light_t* lights, global const epipolar_t* epipolar,
                           global const uint* camera_depth, global const float2* offsets,
                           global uint* bounds)
{
    int samples = frame->width * frame->height * frame->spp;
    int first = get_global_id(0) * BOUNDS_CHUNK;
    if (first >= samples) return;
    int directional = lights[epipolar->light_index].type == LIGHT_DIRECTIONAL;
    float3 axis = epipolar->axis.xyz;
    float d_el = epipolar->d_el, far = frame->far;
    float_lanes q_beta_min = INFINITY, q_beta_max = 0.0f, gamma_max = 0.0f;
    for (int group = first; group < first + BOUNDS_CHUNK && group < samples; group += LANES) {
        /* lanes past the last sample take the last one again: min and max do not mind */
        int_lanes sample = min_lanes(group + (int_lanes)(0, 1, 2, 3, 4, 5, 6, 7), (int_lanes)(samples - 1));
        float_lanes dx, dy, dz;
        camera_ray_lanes(frame, views, offsets, sample, &dx, &dy, &dz);
        float_lanes depth = group + LANES <= samples ? load_run((global const float*)camera_depth, group)
                                                     : LOAD_LANES((global const float*)camera_depth, sample);
        float_lanes s = fmin_lanes(depth, (float_lanes)(far));
        float_lanes cos_beta = dot_lanes(dx, dy, dz, axis.x, axis.y, axis.z);
        float_lanes sin_beta = cross_length_lanes(dx, dy, dz, axis.x, axis.y, axis.z);
        float_lanes q_beta = pseudo_angle_lanes(cos_beta, sin_beta);
        /* γ (docs/design.md §3): s·sin β for a directional light, else the angle at the light. */
        float_lanes gamma = directional ? s * sin_beta : pseudo_angle_lanes(d_el - s * cos_beta, s * sin_beta);
        q_beta_min = fmin_lanes(q_beta_min, q_beta);
        q_beta_max = fmax_lanes(q_beta_max, q_beta);
        gamma_max = fmax_lanes(gamma_max, gamma);
    }
    float q_min = INFINITY, q_max = 0.0f, g_max = 0.0f;
    for (int k = 0; k < LANES; ++k) {
        q_min = inline_fmin(q_min, q_beta_min[k]);
        q_max = inline_fmax(q_max, q_beta_max[k]);
        g_max = inline_fmax(g_max, gamma_max[k]);
    }
    /* Non-negative floats order like their bit patterns, so uint atomics reduce them. Every
     * work-item updates the same three words: a plain read first spares the atomics that
     * would not change them (most, once a few work-items are done), and the cores' contest
     * for the words' cache line. */
    if (as_uint(q_min) < bounds[0]) atomic_min(bounds + 0, as_uint(q_min));
    if (as_uint(q_max) > bounds[1]) atomic_max(bounds + 1, as_uint(q_max));
    if (as_uint(g_max) > bounds[2]) atomic_max(bounds + 2, as_uint(g_max));
}


/* One work-item per texel of a row: from the bounds, the γ step of the texture (written to
 * epipolar->gamma_step by work-item 0), the texel's (γ, cos γ, sin γ, 0) and, by work-item
 * 0, ranges = (β_min, β_max, γ_max, 1/max(β_max - β_min, 1e-6)) as float. The host read the
 * bounds and computed these until a frame ran without a wait (clrays/stages/rectify.py
 * texel_angles is the same rule in numpy). When no visible ray has extent in γ (γ_max ≤ 0)
 * the texture spans γ ∈ [0, 1], where a zero step would divide by zero, and the walks find
 * every ray's span empty (integrand_rows' no_extent, walk.h finish_span): the light adds
 * nothing, as when the host skipped it. */
kernel void rectify_ranges(global const uint* bounds, global const light_t* lights, global epipolar_t* epipolar,
                           global float4* texel_angles, global float4* ranges)
{
    int texel = get_global_id(0), n = epipolar->gamma_samples;
    if (texel >= n) return;
    int directional = lights[epipolar->light_index].type == LIGHT_DIRECTIONAL;
    wide_t beta_min, beta_max, gamma_max;
    visible_ranges(bounds, directional, &beta_min, &beta_max, &gamma_max);
    float gamma_step = gamma_max > 0.0 ? (float)(gamma_max / (wide_t)n) : 1.0f / (float)n;
    /* texel centres, except texel 0 at γ = 0 (see below); even texels one float product, as
     * the host's; a point or spot light's finer near γ = 0 (gamma_texels.h) in double */
    float warp = epipolar->gamma_warp;
    wide_t centre = (wide_t)texel + 0.5, w = (wide_t)warp;
    float gamma = texel == 0     ? 0.0f
                  : warp > 0.0f ? (float)(centre * (wide_t)gamma_step * (1.0 - w + w * centre / (wide_t)n))
                                : ((float)texel + 0.5f) * gamma_step;
    texel_angles[texel] = (float4)(gamma, (float)cos((wide_t)gamma), (float)sin((wide_t)gamma), 0.0f);
    if (texel == 0) {
        epipolar->gamma_step = gamma_step;
        wide_t span = beta_max - beta_min;
        ranges[0] = (float4)((float)beta_min, (float)beta_max, (float)gamma_max,
                             (float)(1.0 / (span > 1e-6 ? span : 1e-6)));
    }
}


/* slice_sides[α] = u·cos α + w·sin α at the slice's centre comes from the host
 * (clrays/stages/rectify.py slice_sides) and texel_angles[γ] = (γ, cos γ, sin γ) from
 * rectify_ranges: the same for every texel of a row or column, they cost the kernel no
 * trigonometry. Texel centres, except
 * texel 0 at γ = 0: the eye's own light ray (through the eye, the same for every slice). A
 * ray straight away from the light (β → π) spans only γ < SIN_BETA_MIN·s, far less than
 * half a texel, and its visibility is that ray's.
 */
/* Where LANES texels of a slice read the shadow map (rectify's first half): each lane's
 * index into shadow_depth, and whether its light ray meets the map there (else the lane
 * reads the view's texel 0, unused). */
ALWAYS_INLINE int_lanes rectify_lookup(global const view_t* views, global const light_t* light,
                                       global const epipolar_t* ep, float3 r, float_lanes gamma,
                                       float_lanes cos_gamma, float_lanes sin_gamma, int_lanes* meets)
{
    if (light->type == LIGHT_DIRECTIONAL) {
        /* Light ray: γ·r + t·ω. */
        global const view_t* view = views + light->first_view;
        float3 origin = view->origin.xyz;
        /* two statements, as view_project's p - origin: no fused multiply-add */
        float_lanes px = gamma * r.x, py = gamma * r.y, pz = gamma * r.z;
        float_lanes qx = px - origin.x, qy = py - origin.y, qz = pz - origin.z;
        /* view_project, orthographic */
        float_lanes x = dot_lanes(qx, qy, qz, view->right.x, view->right.y, view->right.z);
        float_lanes y = dot_lanes(qx, qy, qz, view->up.x, view->up.y, view->up.z);
        float_lanes texel_x = (x / view->scale_x + 1.0f) * 0.5f * (float)view->width;
        float_lanes texel_y = (1.0f - y / view->scale_y) * 0.5f * (float)view->height;
        int_lanes inside = texel_x >= 0.0f & texel_y >= 0.0f & texel_x < (float)view->width
                           & texel_y < (float)view->height;
        int_lanes tx = clamp_int_lanes(int_of_lanes(texel_x), 0, view->width - 1);
        int_lanes ty = clamp_int_lanes(int_of_lanes(texel_y), 0, view->height - 1);
        *meets = inside;
        return inside ? view->depth_offset + ty * view->width + tx : view->depth_offset;
    }
    /* Light ray from l at angle γ to l → e, in slice α. */
    float3 axis = ep->axis.xyz;
    float_lanes dir_x = -axis.x * cos_gamma + r.x * sin_gamma;
    float_lanes dir_y = -axis.y * cos_gamma + r.y * sin_gamma;
    float_lanes dir_z = -axis.z * cos_gamma + r.z * sin_gamma;
    /* Spot lights: outside the cone the map has no texel and the ray counts as
     * unblocked; traverse clips each eye ray to the cone analytically, so the
     * cone's edge is exact rather than a texel wide. */
    float3 l = light->position.xyz;
    float_lanes px = l.x + dir_x, py = l.y + dir_y, pz = l.z + dir_z;
    /* view_project, perspective (a spot light's view or a cube face). The lanes of a
     * spot light, and most lanes of a point light, share one view: its fields are then
     * read once, not gathered per lane (the same values, so the same bits). */
    view_lanes_t v = views_of_lanes(views, light_view_index_lanes(light, px, py, pz));
    float_lanes qx = px - v.origin_x, qy = py - v.origin_y, qz = pz - v.origin_z;
    float_lanes x = dot_lanes_of_lanes(qx, qy, qz, v.right_x, v.right_y, v.right_z);
    float_lanes y = dot_lanes_of_lanes(qx, qy, qz, v.up_x, v.up_y, v.up_z);
    float_lanes z = dot_lanes_of_lanes(qx, qy, qz, v.forward_x, v.forward_y, v.forward_z);
    int_lanes width = v.width, height = v.height;
    float_lanes sx = x / (z * v.scale_x);
    float_lanes sy = y / (z * v.scale_y);
    float_lanes texel_x = (sx + 1.0f) * 0.5f * float_of_lanes(width);
    float_lanes texel_y = (1.0f - sy) * 0.5f * float_of_lanes(height);
    /* shadow_texel: truncated, then clamped to the map */
    int_lanes tx = min_lanes(max_lanes(int_of_lanes(texel_x), (int_lanes)(0)), width - 1);
    int_lanes ty = min_lanes(max_lanes(int_of_lanes(texel_y), (int_lanes)(0)), height - 1);
    int_lanes in_front = !(z <= 0.0f);
    *meets = in_front;
    return v.depth_offset + (in_front ? ty * width + tx : 0);
}

/* The blocker's β of LANES texels from the depths their lookups read (rectify's second
 * half): π where the light ray meets no occluder. */
ALWAYS_INLINE float_lanes rectify_beta(global const view_t* views, global const light_t* light,
                                       global const epipolar_t* ep, float_lanes gamma, float_lanes cos_gamma,
                                       float_lanes sin_gamma, float_lanes depth, int_lanes meets)
{
    float_lanes stored = meets ? depth : (float_lanes)(INFINITY);
    if (light->type == LIGHT_DIRECTIONAL) {
        /* The orthographic map stores depth along -ω from its origin o, so the blocker sits
         * at t_b = -(depth + o·(-ω)); S = atan2(γ, t_b). */
        global const view_t* view = views + light->first_view;
        float t_offset = dot(view->origin.xyz, view->forward.xyz);
        float_lanes t_blocker = -(stored + t_offset);
        return stored == INFINITY ? PI_F : atan2_approx_lanes(gamma, t_blocker);
    }
    return stored == INFINITY ? PI_F : atan2_approx_lanes(stored * sin_gamma, ep->d_el - stored * cos_gamma);
}

/* Level 0 of a row, (min, max) = (β, β), for the texels from `first` on. */
ALWAYS_INLINE void store_level0(global float* row, int first, int n, float_lanes blocker_beta)
{
    if (first >= n) return;
    if (first + LANES <= n) {
        /* each lane twice, as two float8 stores: no 16-wide vector, which PoCL 3.0
         * miscompiled on a CPU with AVX-512 (docs/design.md §4.5, "Wide vectors") */
        store_pairs_run(row, first, blocker_beta, blocker_beta);
    } else {
        for (int k = 0; first + k < n; ++k) row[2 * (first + k)] = row[2 * (first + k) + 1] = blocker_beta[k];
    }
}

/* With RECTIFY_BLOCKERS, each texel's blocking triangle too: the maps' nearest triangles
 * in, the rows' out. With RECTIFY_BLOCKER_KEYS the maps' blockers are the 64-bit keys
 * (depth << 32 | triangle) raster drew them with (clrays/stages/raster.py, ShadowMap): each
 * texel's depth and triangle come from one load, where a depth array and a triangle array
 * cost two cache misses per texel. */
#ifdef RECTIFY_BLOCKERS
#if RECTIFY_BLOCKER_KEYS
#define RECTIFY_BLOCKER_ARGS , global const ulong* shadow_keys, global int* row_triangles
#else
#define RECTIFY_BLOCKER_ARGS , global const int* shadow_triangle, global int* row_triangles
#endif
#endif
#ifndef RECTIFY_BLOCKER_ARGS
#define RECTIFY_BLOCKER_ARGS
#endif

#if defined(RECTIFY_BLOCKERS) && RECTIFY_BLOCKER_KEYS
/* The depths and triangles of LANES keys, as raster_split_runs splits them (-1: none), in
 * two ulong4 halves: no ulong8, whose stores PoCL 3.0 lost on a CPU with AVX-512
 * (docs/design.md §4.5, "Wide vectors"). */
ALWAYS_INLINE void gather_keys(global const ulong* keys, int_lanes index, float_lanes* depth, int_lanes* triangle)
{
    ulong4 low = (ulong4)(keys[index.s0], keys[index.s1], keys[index.s2], keys[index.s3]);
    ulong4 high = (ulong4)(keys[index.s4], keys[index.s5], keys[index.s6], keys[index.s7]);
    uint4 depth_low = convert_uint4(low >> 32), depth_high = convert_uint4(high >> 32);
    int4 triangle_low = depth_low == (uint4)(DEPTH_EMPTY) ? (int4)(-1) : convert_int4(convert_uint4(low));
    int4 triangle_high = depth_high == (uint4)(DEPTH_EMPTY) ? (int4)(-1) : convert_int4(convert_uint4(high));
    *depth = as_float8((uint8)(depth_low, depth_high));
    *triangle = (int8)(triangle_low, triangle_high);
}
#endif

/* One work-item per RECTIFY_BATCHES·LANES texels of a slice, as float8 batches (lanes.h,
 * docs/design.md §4.5): the operations of view_project, light_view_index and shadow_texel
 * (lighting.h) in their order, so S is the same bits as one texel per work-item. Every
 * batch finds its texels before any reads the map: the reads miss the cache (a cube face
 * is 4 MB), and more of them at once wait about as long as 8. */
kernel void rectify(global const view_t* views, global const light_t* lights,
                    global const uint* shadow_depth, global const epipolar_t* epipolar,
                    global const float4* slice_sides, global const float4* texel_angles, global float2* tree
                    RECTIFY_BLOCKER_ARGS)
{
    int first = get_global_id(0) * RECTIFY_BATCHES * LANES, slice = get_global_id(1);
    global const epipolar_t* ep = epipolar;
    int n = ep->gamma_samples;
    if (first >= n || slice >= ep->slices) return;
    global const light_t* light = lights + ep->light_index;
    float3 r = slice_sides[slice].xyz;
    float_lanes gamma[RECTIFY_BATCHES], cos_gamma[RECTIFY_BATCHES], sin_gamma[RECTIFY_BATCHES];
    float_lanes depth[RECTIFY_BATCHES];
    int_lanes index[RECTIFY_BATCHES], meets[RECTIFY_BATCHES];
    /* unrolled: the batches' vectors stay in registers, not a private array in memory */
#pragma unroll
    for (int b = 0; b < RECTIFY_BATCHES; ++b) {
        /* lanes past the last texel compute the last one again, and store nothing */
        int start = first + b * LANES;
        int_lanes texel = min_lanes(start + (int_lanes)(0, 1, 2, 3, 4, 5, 6, 7), (int_lanes)(n - 1));
        float_lanes unused;
        if (start + LANES <= n) { /* the texels' records one after another */
            load_records_run(texel_angles, start, &gamma[b], &cos_gamma[b], &sin_gamma[b], &unused);
        } else {
            gather_records(texel_angles, texel, &gamma[b], &cos_gamma[b], &sin_gamma[b], &unused);
        }
        index[b] = rectify_lookup(views, light, ep, r, gamma[b], cos_gamma[b], sin_gamma[b], &meets[b]);
    }
#if defined(RECTIFY_BLOCKERS) && RECTIFY_BLOCKER_KEYS
    int_lanes key_triangle[RECTIFY_BATCHES];
#pragma unroll
    for (int b = 0; b < RECTIFY_BATCHES; ++b) gather_keys(shadow_keys, index[b], &depth[b], &key_triangle[b]);
#else
#pragma unroll
    for (int b = 0; b < RECTIFY_BATCHES; ++b) depth[b] = LOAD_LANES((global const float*)shadow_depth, index[b]);
#endif
    global float* row = (global float*)(tree + (size_t)slice * 2 * n);
#pragma unroll
    for (int b = 0; b < RECTIFY_BATCHES; ++b)
        store_level0(row, first + b * LANES, n,
                     rectify_beta(views, light, ep, gamma[b], cos_gamma[b], sin_gamma[b], depth[b], meets[b]));
#ifdef RECTIFY_BLOCKERS
    /* Each texel's blocker, the nearest triangle the map holds there (-1: none): the walks
     * place the shafts' edges on it (shaft_edges.h). */
    global int* triangles = row_triangles + (size_t)slice * n;
#pragma unroll
    for (int b = 0; b < RECTIFY_BATCHES; ++b) {
        int start = first + b * LANES;
        if (start >= n) continue;
#if RECTIFY_BLOCKER_KEYS
        int_lanes blocker = meets[b] ? key_triangle[b] : (int_lanes)(-1);
#else
        int_lanes blocker = meets[b] ? GATHER_LANES(int_lanes, shadow_triangle, index[b]) : (int_lanes)(-1);
#endif
        if (start + LANES <= n) {
            *(global int8_at_int*)(triangles + start) = blocker; /* one plain vector store */
        } else {
            for (int k = 0; start + k < n; ++k) triangles[start + k] = blocker[k];
        }
    }
#endif
}
