/* sampling — epipolar sampling, `render.sampling: epipolar` (docs/design.md §4.5
 * "Epipolar sampling"). In-scattered light varies slowly along a slice's line on the
 * screen and fast across lines, so it is computed at samples on each slice's line and
 * interpolated to the camera samples:
 *
 *   line_samples  per line sample: the camera distance where it lands, and what its
 *                 ray would gather unshadowed (the "line value")
 *   line_scatter  per line sample: walk its own row where it is needed (every
 *                 `step`-th sample, the ends, both sides of a break: an edge, a spot
 *                 light's cone, the epipole); the others are left for line_fill
 *   line_refine   per line sample not computed: computed too where the computed
 *                 samples either side differ in radiance (a shadow's edge between them)
 *   line_fill     per line sample not computed: interpolate between the computed
 *                 samples either side (no break lies between them)
 *   gather        per camera sample: interpolate each of its two slices at its β when
 *                 the samples there match its distance and unshadowed weight and each
 *                 other's radiance, blending the two slices as traverse does; list it
 *                 for fix_up where a slice cannot
 *   fix_up        per listed camera sample: walk those rows for the sample itself
 *
 * Line sample j of slice i lies in the half-plane of the slice's centre at the
 * pseudo-angle q = lo_i + (hi_i - lo_i)·j/(n - 1) (pseudo_beta, a monotonic stand-in for
 * β), [lo_i, hi_i] being the range of the screen beside that slice (clrays/stages/
 * sampling.py line_ranges): along a line from the epipole β is monotonic, so it orders
 * the samples.
 * A line sample walks one row (it lies on its slice); a camera sample would walk two.
 * Radiance is kept times sin β for point and spot lights (radiance_scale): what remains
 * varies slowly even next to the light, where the brightest pixels are. */
#include "walk.h"
#include "atan2_approx.h"

/* The light's type (LIGHT_*): gather computes a camera sample's unshadowed weight for a
 * spot light only, and its work-items run as one vector loop for the others. */
#ifndef SAMPLING_LIGHT
#define SAMPLING_LIGHT LIGHT_POINT
#endif

/* Camera samples per block of the fix-up list (fixup_count, fixup_list). */
#define FIXUP_BLOCK 1024

/* The counter of clrays.stages.sampling.SampleCounts that the kernels keep: line samples
 * that walked their row. Rare next to the camera samples, so a plain global atomic does;
 * gather flags its fix-ups instead (fixup_count, fixup_list). */
#define COUNT_COMPUTED 0

/* Line samples are spaced evenly in q = tan(β/2) for β ≤ π/2 and 2 - cot(β/2) above: q
 * rises with β at between 1/2 and 1 times its rate, and needs no arc tangent from cos β
 * and sin β, nor any trigonometry back (clrays/stages/sampling.py pseudo_beta). */
ALWAYS_INLINE float pseudo_beta(float cos_beta, float sin_beta)
{
    return cos_beta >= 0.0f ? sin_beta / (1.0f + cos_beta) : 2.0f - sin_beta / (1.0f - cos_beta);
}

/* q of line sample j of slice i; 0 when the slice does not cross the screen. */
ALWAYS_INLINE int line_q(global const float2* ranges, int i, int j, int n, float* q)
{
    float2 range = ranges[i];
    if (!(range.x <= range.y)) return 0;
    *q = inline_mix(range.x, range.y, (float)j / (float)(n - 1));
    return 1;
}

/* The direction at pseudo-angle q in the half-plane of slice i's centre (sides[i]). */
ALWAYS_INLINE float3 line_direction(global const epipolar_t* ep, global const float4* sides, int i, float q,
                             float* sin_beta)
{
    float k = q <= 1.0f ? q : 2.0f - q; /* tan(β/2), or cot(β/2) */
    float across = 2.0f * k / (1.0f + k * k), along = (1.0f - k * k) / (1.0f + k * k);
    along = q <= 1.0f ? along : -along;
    *sin_beta = across;
    return inline_normalize(along * ep->axis.xyz + across * sides[i].xyz);
}

/* The camera distance where a direction lands: the depth of the pixel it points into
 * (its first camera sample), clamped to the screen and to far. */
ALWAYS_INLINE float landing_distance(global const frame_t* frame, global const view_t* views,
                              global const uint* camera_depth, float3 dir)
{
    float2 texel;
    float unused;
    if (!view_project(views, views->origin.xyz + dir, &texel, &unused)) return frame->far;
    int x = inline_clamp_int((int)inline_floor(texel.x), 0, frame->width - 1);
    int y = inline_clamp_int((int)inline_floor(texel.y), 0, frame->height - 1);
    return inline_fmin(as_float(camera_depth[(y * frame->width + x) * frame->spp]), frame->far);
}

/* What the ray along dir up to distance would gather if nothing cast a shadow, without
 * the medium's attenuation and phase, and without the factor 1/sin β of a point or spot
 * light (which `radiance_scale` takes out of the radiance exactly): the γ it sweeps,
 * divided by d_el, for a point or spot light (only the part inside a spot light's cone),
 * the lit length for a directional light. It breaks where the in-scattering breaks: at
 * the ray's end (an edge) and at a spot light's cone. */
ALWAYS_INLINE float unshadowed_weight(global const epipolar_t* ep, global const light_t* light, float3 dir,
                               float distance)
{
    float begin = 0.0f, end = distance;
    if (light->type == LIGHT_SPOT && !spot_interval(light, dir, distance, &begin, &end)) return 0.0f;
    if (light->type == LIGHT_DIRECTIONAL) return end - begin;
    float cos_beta = inline_dot(dir, ep->axis.xyz);
    float sin_beta = inline_fmax(inline_length(inline_cross(dir, ep->axis.xyz)), SIN_BETA_MIN);
    float gamma_begin = begin > 0.0f ? atan2_approx(begin * sin_beta, ep->d_el - begin * cos_beta) : 0.0f;
    float gamma_end = atan2_approx(end * sin_beta, ep->d_el - end * cos_beta);
    return (gamma_end - gamma_begin) / ep->d_el;
}

/* The factor radiance is stored and interpolated under: sin β for a point or spot light,
 * whose in-scattering grows as 1/sin β near the epipole, faster than a straight line
 * between samples follows; 1 for a directional light. */
ALWAYS_INLINE float radiance_scale(global const light_t* light, float sin_beta)
{
    return light->type == LIGHT_DIRECTIONAL ? 1.0f : inline_fmax(sin_beta, SIN_BETA_MIN);
}

/* Per line sample: (distance, unshadowed weight): where it lands, and what it would
 * gather unshadowed. Distance -1 where the slice has no camera sample beside it. */
kernel void line_samples(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                         global const epipolar_t* ep, global const uint* camera_depth, global const float2* ranges,
                         global const float4* sides, int n, global float2* line)
{
    int j = get_global_id(0), i = get_global_id(1);
    if (j >= n || i >= ep->slices) return;
    float q;
    if (!line_q(ranges, i, j, n, &q)) {
        line[i * n + j] = (float2)(-1.0f, 0.0f);
        return;
    }
    float sin_beta;
    float3 dir = line_direction(ep, sides, i, q, &sin_beta);
    float distance = landing_distance(frame, views, camera_depth, dir);
    line[i * n + j] = (float2)(distance, unshadowed_weight(ep, lights + ep->light_index, dir, distance));
}

/* Two neighbouring line samples are not interpolated across when their distances differ
 * by more than `threshold` relatively (an edge), or their unshadowed weights (a spot
 * light's cone, or the epipole, where 1/sin β grows faster than samples follow). */
ALWAYS_INLINE int distance_breaks(float2 a, float2 b, float threshold)
{
    return inline_fabs(a.x - b.x) > threshold * inline_fmin(a.x, b.x);
}

ALWAYS_INLINE int weight_breaks(float2 a, float2 b, float threshold)
{
    return inline_fabs(a.y - b.y) > threshold * inline_fmax(inline_fabs(a.y), inline_fabs(b.y));
}

/* A line value (interpolated or not) stands for a camera sample's own when both are
 * within `threshold` of it, relatively. */
ALWAYS_INLINE int line_matches(float2 value, float2 own, float threshold)
{
    return inline_fabs(value.x - own.x) <= threshold * own.x
           && inline_fabs(value.y - own.y) <= threshold * inline_fmax(inline_fabs(value.y), inline_fabs(own.y));
}

/* Every `step`-th sample, the ends, and both sides of a break. */
ALWAYS_INLINE int line_sample_needed(global const float2* line, int j, int n, int step, float threshold)
{
    if (j % step == 0 || j == n - 1) return 1;
    float2 before = line[j - 1], here = line[j], after = line[j + 1];
    return distance_breaks(before, here, threshold) || weight_breaks(before, here, threshold)
           || distance_breaks(here, after, threshold) || weight_breaks(here, after, threshold);
}

/* The radiance of line sample j of slice i, times radiance_scale: its own walk along
 * row i (0 where its ray has no extent). */
inline float3 line_sample_radiance(global const frame_t* frame, global const light_t* lights,
                                   global const epipolar_t* ep, global const float2* tree,
                                   global const integrand_t* integrand, global const float* tables,
                                   const row_texture_t* texture, global const float2* ranges,
                                   global const float4* sides, float distance, int i, int j, int n,
                                   global uint* counts)
{
    float q, sin_beta;
    line_q(ranges, i, j, n, &q);
    float3 dir = line_direction(ep, sides, i, q, &sin_beta);
    ray_span_t span;
    global const light_t* light = lights + ep->light_index;
    if (!ray_span(ep, light, frame, integrand, dir, distance, &span)) return (float3)(0.0f);
    atomic_inc(counts + COUNT_COMPUTED);
    return radiance_scale(light, sin_beta) * row_radiance(ep, tree, i, &span, integrand, tables, frame, texture);
}

ALWAYS_INLINE float luminance(float3 c) { return inline_dot(c, (float3)(0.2126f, 0.7152f, 0.0722f)); }

/* Two radiances differ by more than `threshold` of the larger (in luminance): a shadow's
 * edge lies between them, which neither their distances nor their unshadowed weights
 * show. */
ALWAYS_INLINE int radiance_breaks(float3 a, float3 b, float threshold)
{
    float la = luminance(a), lb = luminance(b);
    return inline_fabs(la - lb) > threshold * inline_fmax(la, lb);
}

/* Per line sample: its radiance times radiance_scale (w = 1) where it is needed, else w = 0. */
kernel void line_scatter(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                         global const epipolar_t* ep, global const float2* tree,
                         global const integrand_t* integrand, global const float* tables,
                         global const textured_integrand_t* textured, global const float* texture_basis,
                         global const float* texture_prefix, global const float2* ranges,
                         global const float4* sides, global const float2* line, int n, int step, float threshold,
                         global float4* radiance, global uint* counts RECTIFIED_LAYER_ARGS)
{
    row_texture_t texture = {textured, texture_basis, texture_prefix};
    ATTACH_RECTIFIED_LAYERS(texture) /* translucent objects only (translucent_walk.h) */
    int j = get_global_id(0), i = get_global_id(1);
    if (j >= n || i >= ep->slices) return;
    global const float2* samples = line + i * n;
    float4 result = (float4)(0.0f);
    if (samples[j].x < 0.0f) {
        result.w = 1.0f; /* the slice does not cross the screen: nothing reads it */
    } else if (line_sample_needed(samples, j, n, step, threshold)) {
        result.xyz = line_sample_radiance(frame, lights, ep, tree, integrand, tables, &texture, ranges, sides,
                                          samples[j].x, i, j, n, counts);
        result.w = 1.0f;
    }
    radiance[i * n + j] = result;
}

/* Per line sample line_scatter left: computed too where the computed samples either side
 * differ by more than 4 × the threshold (a shadow edge crosses the line between them),
 * so that line_fill draws no straight line across it. Not 1 ×: over `step` samples the
 * light's own falloff often changes radiance by a few percent, and refining on it walked
 * many more samples for no error gained on the bench scenes. Reads `radiance`, writes `refined`,
 * so that every decision sees line_scatter's samples only. */
kernel void line_refine(global const frame_t* frame, global const light_t* lights, global const epipolar_t* ep,
                        global const float2* tree, global const integrand_t* integrand, global const float* tables,
                        global const textured_integrand_t* textured, global const float* texture_basis,
                        global const float* texture_prefix, global const float2* ranges,
                        global const float4* sides, global const float2* line, int n, float threshold,
                        global const float4* radiance, global float4* refined, global uint* counts RECTIFIED_LAYER_ARGS)
{
    row_texture_t texture = {textured, texture_basis, texture_prefix};
    ATTACH_RECTIFIED_LAYERS(texture) /* translucent objects only (translucent_walk.h) */
    int j = get_global_id(0), i = get_global_id(1);
    if (j >= n || i >= ep->slices) return;
    global const float4* samples = radiance + i * n;
    float4 result = samples[j];
    if (result.w == 0.0f) {
        int left = j - 1, right = j + 1;
        while (samples[left].w == 0.0f) --left;   /* j % step == 0 and j = n - 1 are computed: */
        while (samples[right].w == 0.0f) ++right; /* both loops end within step samples */
        if (radiance_breaks(samples[left].xyz, samples[right].xyz, 4.0f * threshold)) {
            result.xyz = line_sample_radiance(frame, lights, ep, tree, integrand, tables, &texture, ranges, sides,
                                              line[i * n + j].x, i, j, n, counts);
            result.w = 1.0f;
        }
    }
    refined[i * n + j] = result;
}

/* Per line sample not computed: linear in j between the computed samples either side. */
kernel void line_fill(global const epipolar_t* ep, int n, global float4* radiance)
{
    int j = get_global_id(0), i = get_global_id(1);
    if (j >= n || i >= ep->slices) return;
    global float4* samples = radiance + i * n;
    if (samples[j].w != 0.0f) return;
    int left = j - 1, right = j + 1;
    while (samples[left].w == 0.0f) --left;   /* j % step == 0 and j = n - 1 are computed: */
    while (samples[right].w == 0.0f) ++right; /* both loops end within step samples */
    float t = (float)(j - left) / (float)(right - left);
    samples[j] = (float4)(mix(samples[left].xyz, samples[right].xyz, t), 0.0f);
}

/* Whether slice i interpolates at a camera sample (own line value (own_distance,
 * own_weight), pseudo-angle q, sin β): the two line samples either side of its q match
 * it (distance, and for a spot light, whose cone's silhouette runs along the slices and
 * so can pass between a camera sample and its lines, the unshadowed weight), their
 * weights do not break, and their radiances agree; then value is the straight line
 * between them, else 0. Otherwise (an edge lies between them, the camera sample is off
 * both lines' surfaces, a shadow's edge crosses the line, the light's own radiance jumps:
 * its cone, the epipole) the fix-up walks the row for the camera sample. Taking the one
 * sample on its side of an edge instead was tried: it ignores the change in β between
 * them, and failed the opaque-fog closed form of tests/methods/test_stability.py (0.83 %
 * against its 0.1 %).
 *
 * In scalars, every load unconditional and every test a select: so PoCL runs gather's
 * work-items eight at a time (inline_math.h). */
ALWAYS_INLINE int slice_interpolates(global const float* ranges, global const float* line,
                                     global const float* radiance, int n, float threshold, int i, float q,
                                     float scale, float own_distance, float own_weight, float* value_x,
                                     float* value_y, float* value_z)
{
    float lo = ranges[2 * i], hi = ranges[2 * i + 1];
    float f = hi > lo ? inline_clamp((q - lo) / (hi - lo), 0.0f, 1.0f) * (float)(n - 1) : 0.0f;
    int j = inline_min((int)f, n - 2);
    float s = f - (float)j;
    global const float* a = line + 2 * (i * n + j); /* a[2], b[3]: distance, weight */
    global const float* va = radiance + 4 * (i * n + j); /* va[4], vb[5], vb[6] */
    float a_distance = a[0], a_weight = a[1], b_distance = a[2], b_weight = a[3];
    float ra = va[0], ga = va[1], ba = va[2], rb = va[4], gb = va[5], bb = va[6];
    float between_distance = inline_mix(a_distance, b_distance, s);
    /* not a spot light (own_weight < 0): the weight is not compared */
    float between_weight = own_weight < 0.0f ? own_weight : inline_mix(a_weight, b_weight, s);
    float luminance_a = inline_dot_xyz(ra, ga, ba, 0.2126f, 0.7152f, 0.0722f);
    float luminance_b = inline_dot_xyz(rb, gb, bb, 0.2126f, 0.7152f, 0.0722f);
    int interpolates =
        !(a_distance < 0.0f) /* the slice misses the screen */
        & !(inline_fabs(a_weight - b_weight) > threshold * inline_fmax(inline_fabs(a_weight), inline_fabs(b_weight)))
        & (inline_fabs(between_distance - own_distance) <= threshold * own_distance)
        & (inline_fabs(between_weight - own_weight)
           <= threshold * inline_fmax(inline_fabs(between_weight), inline_fabs(own_weight)))
        & !(inline_fabs(luminance_a - luminance_b) > threshold * inline_fmax(luminance_a, luminance_b));
    *value_x = interpolates ? inline_mix(ra, rb, s) / scale : 0.0f;
    *value_y = interpolates ? inline_mix(ga, gb, s) / scale : 0.0f;
    *value_z = interpolates ? inline_mix(ba, bb, s) / scale : 0.0f;
    return interpolates;
}

/* A camera sample's direction, distance, two nearest slices and their weight, as fix_up
 * takes them (gather has them in scalars). */
inline float3 gather_ray(global const frame_t* frame, global const view_t* views, global const float2* offsets,
                         global const uint* camera_depth, global const epipolar_t* ep, int sample, float* distance,
                         int* i0, int* i1, float* t)
{
    float3 dir = camera_ray(frame, views, offsets, sample);
    *distance = inline_fmin(as_float(camera_depth[sample]), frame->far);
    slices_around(ep, atan2_approx(inline_dot(dir, ep->w.xyz), inline_dot(dir, ep->u.xyz)), i0, i1, t);
    return dir;
}

/* Per camera sample: add each of its two slices' interpolated radiance, weighted as
 * traverse blends them; flag the sample in `fixup_flags` (a bit per slice) for fix_up
 * where a slice cannot interpolate. No walk and no atomic here, and all in scalars, so
 * that the work-items run as one vector loop: gather_ray's and slice_interpolates' float3
 * arithmetic spelled out on the components, in the same order (inline_math.h). */
kernel void gather(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                   global const epipolar_t* ep, global const uint* camera_depth, global const float2* offsets,
                   global const float2* ranges, global const float2* line, global const float4* radiance, int n,
                   float threshold, global float4* scatter, global uchar* fixup_flags)
{
    /* One work-item per camera sample, none beyond: no early return, so that the loads
     * of the frame's constants are unconditional and move out of the work-item loop. */
    int sample = get_global_id(0);
    /* camera_ray (walk.h), a perspective and an orthographic view alike */
    int pixel = sample / frame->spp;
    global const float* offset = (global const float*)(offsets + sample % frame->spp);
    float sx = 2.0f * ((float)(pixel % frame->width) + offset[0]) / (float)views->width - 1.0f;
    float sy = 1.0f - 2.0f * ((float)(pixel / frame->width) + offset[1]) / (float)views->height;
    float3 forward = views->forward.xyz, right = views->right.xyz, up = views->up.xyz;
    int perspective = views->projection == PROJECTION_PERSPECTIVE;
    float along_right = sx * views->scale_x, along_up = sy * views->scale_y;
    float rx = right.x * along_right, ry = right.y * along_right, rz = right.z * along_right;
    float ux = up.x * along_up, uy = up.y * along_up, uz = up.z * along_up;
    float px = forward.x + rx + ux, py = forward.y + ry + uy, pz = forward.z + rz + uz;
    float inverse = inline_inverse_length_xyz(px, py, pz);
    float dx = perspective ? px * inverse : forward.x;
    float dy = perspective ? py * inverse : forward.y;
    float dz = perspective ? pz * inverse : forward.z;
    float distance = inline_fmin(as_float(camera_depth[sample]), frame->far);
    float ax = ep->axis.x, ay = ep->axis.y, az = ep->axis.z;
    float alpha = atan2_approx(inline_dot_xyz(dx, dy, dz, ep->w.x, ep->w.y, ep->w.z),
                               inline_dot_xyz(dx, dy, dz, ep->u.x, ep->u.y, ep->u.z));
    int i0, i1;
    float t;
    slices_around(ep, alpha, &i0, &i1, &t);
    float cos_beta = inline_dot_xyz(dx, dy, dz, ax, ay, az), sin_beta = inline_cross_length_xyz(dx, dy, dz, ax, ay, az);
    float q = pseudo_beta(cos_beta, sin_beta);
    global const light_t* light = lights + ep->light_index;
    float own_weight = -1.0f;
#if SAMPLING_LIGHT == LIGHT_SPOT
    own_weight = unshadowed_weight(ep, light, (float3)(dx, dy, dz), distance);
#endif
    float scale = radiance_scale(light, sin_beta);
    float r0, g0, b0, r1, g1, b1;
    int from0 = slice_interpolates((global const float*)ranges, (global const float*)line,
                                   (global const float*)radiance, n, threshold, i0, q, scale, distance, own_weight,
                                   &r0, &g0, &b0);
    int from1 = slice_interpolates((global const float*)ranges, (global const float*)line,
                                   (global const float*)radiance, n, threshold, i1, q, scale, distance, own_weight,
                                   &r1, &g1, &b1);
    global float* out = (global float*)(scatter + sample);
    out[0] += (1.0f - t) * r0 + t * r1;
    out[1] += (1.0f - t) * g0 + t * g1;
    out[2] += (1.0f - t) * b0 + t * b1;
    out[3] += 0.0f;
    fixup_flags[sample] = (uchar)(!from0 | !from1 << 1);
}

/* Per block of FIXUP_BLOCK camera samples: how many gather flagged for fix_up. */
kernel void fixup_count(int samples, global const uchar* fixup_flags, global uint* block_counts)
{
    int block = get_global_id(0);
    int begin = block * FIXUP_BLOCK, end = inline_min(begin + FIXUP_BLOCK, samples);
    uint count = 0;
    for (int sample = begin; sample < end; ++sample) count += fixup_flags[sample] != 0;
    block_counts[block] = count;
}

/* Per block: list its flagged camera samples (index·4 + a bit per slice) from its offset
 * in `fixups` on (the block counts' prefix sums, taken on the host). */
kernel void fixup_list(int samples, global const uchar* fixup_flags, global const uint* block_offsets,
                       global uint* fixups)
{
    int block = get_global_id(0);
    int begin = block * FIXUP_BLOCK, end = inline_min(begin + FIXUP_BLOCK, samples);
    uint at = block_offsets[block];
    for (int sample = begin; sample < end; ++sample)
        if (fixup_flags[sample]) fixups[at++] = (uint)sample << 2 | fixup_flags[sample];
}

/* Per listed camera sample: walk the rows of the slices it could not interpolate, as
 * traverse does, and add them with their weights. */
kernel void fix_up(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                   global const epipolar_t* ep, global const float2* tree, global const integrand_t* integrand,
                   global const float* tables, global const uint* camera_depth, global const float2* offsets,
                   global const textured_integrand_t* textured, global const float* texture_basis,
                   global const float* texture_prefix, global const uint* fixups, int count, global float4* scatter RECTIFIED_LAYER_ARGS)
{
    int k = get_global_id(0);
    if (k >= count) return;
    row_texture_t texture = {textured, texture_basis, texture_prefix};
    ATTACH_RECTIFIED_LAYERS(texture) /* translucent objects only (translucent_walk.h) */
    uint entry = fixups[k];
    int sample = entry >> 2;
    float distance, t;
    int i0, i1;
    float3 dir = gather_ray(frame, views, offsets, camera_depth, ep, sample, &distance, &i0, &i1, &t);
    ray_span_t span;
    if (!ray_span(ep, lights + ep->light_index, frame, integrand, dir, distance, &span)) return;
    float3 walked = (float3)(0.0f);
    if (entry & 1) walked += (1.0f - t) * row_radiance(ep, tree, i0, &span, integrand, tables, frame, &texture);
    if (entry & 2) walked += t * row_radiance(ep, tree, i1, &span, integrand, tables, frame, &texture);
    scatter[sample] += (float4)(walked, 0.0f);
}
