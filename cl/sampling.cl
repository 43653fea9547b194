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

/* The counters of clrays.stages.sampling.SampleCounts: line samples that walked their
 * row, camera samples that walked at least one row themselves (the fix-ups). Both are
 * rare next to the camera samples, so plain global atomics do. */
#define COUNT_COMPUTED 0
#define COUNT_FIXED_UP 1

/* Line samples are spaced evenly in q = tan(β/2) for β ≤ π/2 and 2 - cot(β/2) above: q
 * rises with β at between 1/2 and 1 times its rate, and needs no arc tangent from cos β
 * and sin β, nor any trigonometry back (clrays/stages/sampling.py pseudo_beta). */
inline float pseudo_beta(float cos_beta, float sin_beta)
{
    return cos_beta >= 0.0f ? sin_beta / (1.0f + cos_beta) : 2.0f - sin_beta / (1.0f - cos_beta);
}

/* q of line sample j of slice i; 0 when the slice does not cross the screen. */
inline int line_q(global const float2* ranges, int i, int j, int n, float* q)
{
    float2 range = ranges[i];
    if (!(range.x <= range.y)) return 0;
    *q = mix(range.x, range.y, (float)j / (float)(n - 1));
    return 1;
}

/* The direction at pseudo-angle q in the half-plane of slice i's centre (sides[i]). */
inline float3 line_direction(global const epipolar_t* ep, global const float4* sides, int i, float q,
                             float* sin_beta)
{
    float k = q <= 1.0f ? q : 2.0f - q; /* tan(β/2), or cot(β/2) */
    float across = 2.0f * k / (1.0f + k * k), along = (1.0f - k * k) / (1.0f + k * k);
    along = q <= 1.0f ? along : -along;
    *sin_beta = across;
    return normalize(along * ep->axis.xyz + across * sides[i].xyz);
}

/* The camera distance where a direction lands: the depth of the pixel it points into
 * (its first camera sample), clamped to the screen and to far. */
inline float landing_distance(global const frame_t* frame, global const view_t* views,
                              global const uint* camera_depth, float3 dir)
{
    float2 texel;
    float unused;
    if (!view_project(views, views->origin.xyz + dir, &texel, &unused)) return frame->far;
    int x = clamp((int)floor(texel.x), 0, frame->width - 1), y = clamp((int)floor(texel.y), 0, frame->height - 1);
    return fmin(as_float(camera_depth[(y * frame->width + x) * frame->spp]), frame->far);
}

/* What the ray along dir up to distance would gather if nothing cast a shadow, without
 * the medium's attenuation and phase, and without the factor 1/sin β of a point or spot
 * light (which `radiance_scale` takes out of the radiance exactly): the γ it sweeps,
 * divided by d_el, for a point or spot light (only the part inside a spot light's cone),
 * the lit length for a directional light. It breaks where the in-scattering breaks: at
 * the ray's end (an edge) and at a spot light's cone. */
inline float unshadowed_weight(global const epipolar_t* ep, global const light_t* light, float3 dir,
                               float distance)
{
    float begin = 0.0f, end = distance;
    if (light->type == LIGHT_SPOT && !spot_interval(light, dir, distance, &begin, &end)) return 0.0f;
    if (light->type == LIGHT_DIRECTIONAL) return end - begin;
    float cos_beta = dot(dir, ep->axis.xyz);
    float sin_beta = fmax(length(cross(dir, ep->axis.xyz)), SIN_BETA_MIN);
    float gamma_begin = begin > 0.0f ? atan2_approx(begin * sin_beta, ep->d_el - begin * cos_beta) : 0.0f;
    float gamma_end = atan2_approx(end * sin_beta, ep->d_el - end * cos_beta);
    return (gamma_end - gamma_begin) / ep->d_el;
}

/* The factor radiance is stored and interpolated under: sin β for a point or spot light,
 * whose in-scattering grows as 1/sin β near the epipole, faster than a straight line
 * between samples follows; 1 for a directional light. */
inline float radiance_scale(global const light_t* light, float sin_beta)
{
    return light->type == LIGHT_DIRECTIONAL ? 1.0f : fmax(sin_beta, SIN_BETA_MIN);
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
inline int distance_breaks(float2 a, float2 b, float threshold)
{
    return fabs(a.x - b.x) > threshold * fmin(a.x, b.x);
}

inline int weight_breaks(float2 a, float2 b, float threshold)
{
    return fabs(a.y - b.y) > threshold * fmax(fabs(a.y), fabs(b.y));
}

/* A line value (interpolated or not) stands for a camera sample's own when both are
 * within `threshold` of it, relatively. */
inline int line_matches(float2 value, float2 own, float threshold)
{
    return fabs(value.x - own.x) <= threshold * own.x
           && fabs(value.y - own.y) <= threshold * fmax(fabs(value.y), fabs(own.y));
}

/* Every `step`-th sample, the ends, and both sides of a break. */
inline int line_sample_needed(global const float2* line, int j, int n, int step, float threshold)
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

inline float luminance(float3 c) { return dot(c, (float3)(0.2126f, 0.7152f, 0.0722f)); }

/* Two radiances differ by more than `threshold` of the larger (in luminance): a shadow's
 * edge lies between them, which neither their distances nor their unshadowed weights
 * show. */
inline int radiance_breaks(float3 a, float3 b, float threshold)
{
    float la = luminance(a), lb = luminance(b);
    return fabs(la - lb) > threshold * fmax(la, lb);
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

/* Whether slice i interpolates at a camera sample (own line value `own`, pseudo-angle q,
 * sin β): the two line samples either side of its q match it (distance, and for a spot
 * light, whose cone's silhouette runs along the slices and so can pass between a camera
 * sample and its lines, the unshadowed weight), their weights do not break, and their
 * radiances agree; then *value is the straight line between them. Otherwise (an edge lies
 * between them, the camera sample is off both lines' surfaces, a shadow's edge crosses
 * the line, the light's own radiance jumps: its cone, the epipole) the fix-up walks the
 * row for the camera sample. Taking the one sample on its side of an edge instead was
 * tried: it ignores the change in β between them, and failed the opaque-fog closed form
 * of tests/methods/test_stability.py (0.83 % against its 0.1 %). */
inline int slice_interpolates(global const light_t* light, global const float2* ranges, global const float2* line,
                              global const float4* radiance, int n, float threshold, int i, float q,
                              float sin_beta, float2 own, float3* value)
{
    float lo = ranges[i].x, hi = ranges[i].y;
    float f = hi > lo ? clamp((q - lo) / (hi - lo), 0.0f, 1.0f) * (float)(n - 1) : 0.0f;
    int j = min((int)f, n - 2);
    float s = f - (float)j;
    float2 a = line[i * n + j], b = line[i * n + j + 1];
    if (a.x < 0.0f || weight_breaks(a, b, threshold)) return 0; /* a.x < 0: the slice misses the screen */
    float2 between = mix(a, b, s);
    if (own.y < 0.0f) between.y = own.y; /* not a spot light: the weight is not compared */
    float4 va = radiance[i * n + j], vb = radiance[i * n + j + 1];
    if (!line_matches(between, own, threshold) || radiance_breaks(va.xyz, vb.xyz, threshold)) return 0;
    *value = mix(va.xyz, vb.xyz, s) / radiance_scale(light, sin_beta);
    return 1;
}

/* A camera sample's direction, distance, two nearest slices and their weight, as gather
 * and fix_up both take them. */
inline float3 gather_ray(global const frame_t* frame, global const view_t* views, global const float2* offsets,
                         global const uint* camera_depth, global const epipolar_t* ep, int sample, float* distance,
                         int* i0, int* i1, float* t)
{
    float3 dir = camera_ray(frame, views, offsets, sample);
    *distance = fmin(as_float(camera_depth[sample]), frame->far);
    slices_around(ep, atan2_approx(dot(dir, ep->w.xyz), dot(dir, ep->u.xyz)), i0, i1, t);
    return dir;
}

/* Per camera sample: add each of its two slices' interpolated radiance, weighted as
 * traverse blends them; list the sample in `fixups` (index·4 + a bit per slice) for
 * fix_up when a slice cannot interpolate. No walk here, so the kernel stays branch-light. */
kernel void gather(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                   global const epipolar_t* ep, global const uint* camera_depth, global const float2* offsets,
                   global const float2* ranges, global const float2* line, global const float4* radiance, int n,
                   float threshold, global float4* scatter, global uint* fixups, global uint* counts)
{
    int sample = get_global_id(0);
    if (sample >= frame->width * frame->height * frame->spp) return;
    float distance, t;
    int i0, i1;
    float3 dir = gather_ray(frame, views, offsets, camera_depth, ep, sample, &distance, &i0, &i1, &t);
    float cos_beta = dot(dir, ep->axis.xyz), sin_beta = length(cross(dir, ep->axis.xyz));
    float q = pseudo_beta(cos_beta, sin_beta);
    global const light_t* light = lights + ep->light_index;
    float2 own = (float2)(distance, light->type == LIGHT_SPOT ? unshadowed_weight(ep, light, dir, distance) : -1.0f);
    float3 near0 = (float3)(0.0f), near1 = (float3)(0.0f);
    int from0 = slice_interpolates(light, ranges, line, radiance, n, threshold, i0, q, sin_beta, own, &near0);
    int from1 = slice_interpolates(light, ranges, line, radiance, n, threshold, i1, q, sin_beta, own, &near1);
    scatter[sample] += (float4)((1.0f - t) * near0 + t * near1, 0.0f);
    if (!(from0 && from1)) fixups[atomic_inc(counts + COUNT_FIXED_UP)] = (uint)sample << 2 | !from0 | !from1 << 1;
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
