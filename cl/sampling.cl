/* sampling — epipolar sampling, `render.sampling: epipolar` (docs/design.md §4.5
 * "Epipolar sampling"). In-scattered light varies slowly along a slice's line on the
 * screen and fast across lines, so it is computed at samples on each slice's line and
 * interpolated to the camera samples:
 *
 *   line_samples  per line sample: the camera distance where it lands, and for a spot
 *                 light what its ray would gather unshadowed (the "line value")
 *   line_scatter  per run of line samples: walk its own row where it is needed (every
 *                 `step`-th sample, the ends, both sides of a break: an edge, a spot
 *                 light's cone); the others are left for line_refine_fill
 *   line_refine_fill  per run between two `step`-th line samples: compute too the
 *                 samples whose computed neighbours differ in radiance (a shadow's edge
 *                 between them), then interpolate the rest between the computed samples
 *                 either side (no break lies between them)
 *   gather        per camera sample: interpolate each of its two slices at its β when
 *                 the samples there match its distance (or, both slices standing, the
 *                 blend of their distances does) and unshadowed weight and each other's
 *                 radiance, blending the two slices as traverse does; flag it for fix_up
 *                 where a slice cannot
 *   fixup_count   per block of camera samples: count the flagged ones
 *   fixup_offsets one work-group: the counts' prefix sums (each block's offset), the
 *                 list's length, and the walks' sum (SampleCounts), in `counts`
 *   fixup_list    per block of camera samples: list the flagged ones from its offset
 *   fix_up        per run of the list: walk those rows for each listed sample itself
 *
 * No count crosses to the host inside a frame: fix_up reads the list's length from
 * `counts`, and the host reads `counts` only when asked for the frame's SampleCounts.
 *
 * line_samples and gather take LANES samples per work-item as float8 vectors (lanes.h):
 * PoCL would run them one at a time (docs/design.md §4.5, "Cost on PoCL").
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
#include "lanes.h"
#include "spot_wedge.h"

/* The light's type (LIGHT_*): gather computes a camera sample's unshadowed weight for a
 * spot light only, and its work-items run as one vector loop for the others. */
#ifndef SAMPLING_LIGHT
#define SAMPLING_LIGHT LIGHT_POINT
#endif

/* Camera samples per block of the fix-up list (fixup_count, fixup_list); from
 * clrays/stages/sampling.py (-D). */
#ifndef FIXUP_BLOCK
#define FIXUP_BLOCK 1024
#endif

/* What clrays.stages.sampling.SampleCounts counts of the line samples, those that walked
 * their row, each run of them keeps in its own entry of `walked` (line_scatter stores it,
 * line_refine_fill adds its refined ones), and fixup_offsets sums them. A global atomic per
 * walked sample cost line_scatter a fifth of its time on two cores (the counter's cache line
 * goes back and forth); gather flags its fix-ups instead (fixup_count, fixup_list). */

/* Line samples are spaced evenly in q = tan(β/2) for β ≤ π/2 and 2 - cot(β/2) above
 * (pseudo_beta: sin β / (1 + cos β), or 2 - sin β / (1 - cos β)): q rises with β at
 * between 1/2 and 1 times its rate, and needs no arc tangent from cos β and sin β, nor any
 * trigonometry back (clrays/stages/sampling.py pseudo_beta). */

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

/* The factor radiance is stored and interpolated under: sin β for a point or spot light,
 * whose in-scattering grows as 1/sin β near the epipole, faster than a straight line
 * between samples follows; 1 for a directional light. */
ALWAYS_INLINE float radiance_scale(global const light_t* light, float sin_beta)
{
    return light->type == LIGHT_DIRECTIONAL ? 1.0f : inline_fmax(sin_beta, SIN_BETA_MIN);
}

/* Per LANES line samples of a slice: (distance, unshadowed weight): where each lands (the
 * depth of the pixel it points into, its first camera sample, clamped to the screen and
 * to far), and for a spot light what it would gather unshadowed (0 for other lights: no
 * kernel reads it); distance -1 where the slice has no camera sample beside it. Each lane does the operations of the scalar line_q, line_direction
 * and view_project (lighting.h), in the same order (lanes.h). */
kernel void line_samples(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                         global const epipolar_t* ep, global const uint* camera_depth, global const float2* ranges,
                         global const float4* sides, int n, global const int* lengths, global float2* line,
                         global float2* wedges)
{
    int first = get_global_id(0) * LANES, i = get_global_id(1);
    if (i >= ep->slices) return;
#if SAMPLING_LIGHT == LIGHT_SPOT
    /* every sample of the slice lies in its half-plane: one wedge for them all, kept for
     * line_scatter's and line_refine_fill's walks (written for every slice, read or not) */
    float2 wedge = slice_wedge(ep, lights + ep->light_index, sides[i].xyz);
    if (first == 0) wedges[i] = wedge;
#endif
    int samples = lengths[i];
    if (first >= samples) return;
    int count = min(LANES, samples - first); /* the lanes that store */
    global float2* out = line + i * n + first;
    float2 range = ranges[i];
    if (!(range.x <= range.y)) { /* the slice does not cross the screen */
        for (int k = 0; k < count; ++k) out[k] = (float2)(-1.0f, 0.0f);
        return;
    }
    /* line_q */
    int_lanes j = first + (int_lanes)(0, 1, 2, 3, 4, 5, 6, 7);
    float_lanes q = mix_lanes((float_lanes)(range.x), (float_lanes)(range.y), float_of_lanes(j) / (float)(samples - 1));
    /* line_direction */
    float_lanes k = q <= 1.0f ? q : 2.0f - q; /* tan(β/2), or cot(β/2) */
    float_lanes across = 2.0f * k / (1.0f + k * k), along = (1.0f - k * k) / (1.0f + k * k);
    along = q <= 1.0f ? along : -along;
    float3 axis = ep->axis.xyz, side = sides[i].xyz;
    float_lanes dx = along * axis.x + across * side.x, dy = along * axis.y + across * side.y;
    float_lanes dz = along * axis.z + across * side.z;
    float_lanes inverse = 1.0f / sqrt_lanes(squared_length_lanes(dx, dy, dz));
    dx *= inverse;
    dy *= inverse;
    dz *= inverse;
    /* where it lands: view_project of origin + dir, then the pixel it points into */
    float3 origin = views->origin.xyz;
    float_lanes px = (origin.x + dx) - origin.x, py = (origin.y + dy) - origin.y, pz = (origin.z + dz) - origin.z;
    float3 right = views->right.xyz, up = views->up.xyz, forward = views->forward.xyz;
    float_lanes x = dot_lanes(px, py, pz, right.x, right.y, right.z), y = dot_lanes(px, py, pz, up.x, up.y, up.z);
    float_lanes z = dot_lanes(px, py, pz, forward.x, forward.y, forward.z);
    float_lanes sx, sy;
    int_lanes in_front = z > 0.0f;
    if (views->projection == PROJECTION_PERSPECTIVE) {
        sx = x / (z * views->scale_x);
        sy = y / (z * views->scale_y);
    } else {
        in_front = (int_lanes)(-1);
        sx = x / views->scale_x;
        sy = y / views->scale_y;
    }
    float_lanes texel_x = (sx + 1.0f) * 0.5f * (float)views->width, texel_y = (1.0f - sy) * 0.5f * (float)views->height;
    int_lanes column = clamp_int_lanes(int_of_lanes(floor_lanes(texel_x)), 0, frame->width - 1);
    int_lanes row = clamp_int_lanes(int_of_lanes(floor_lanes(texel_y)), 0, frame->height - 1);
    float_lanes depth = LOAD_LANES((global const float*)camera_depth, (row * frame->width + column) * frame->spp);
    float_lanes distance = in_front ? fmin_lanes(depth, (float_lanes)(frame->far)) : (float_lanes)(frame->far);
#if SAMPLING_LIGHT == LIGHT_SPOT
    float_lanes weight = weight_in_wedge_lanes(ep, (float_lanes)(wedge.x), (float_lanes)(wedge.y), along * inverse,
                                               across * inverse, distance);
#else
    float_lanes weight = 0.0f; /* read for a spot light only (line_sample_needed, slice_line) */
#endif
    if (count == LANES) { /* two stores of four (distance, weight) pairs each */
        store_pairs_run((global float*)out, 0, distance, weight);
        return;
    }
    for (int lane = 0; lane < count; ++lane) out[lane] = (float2)(distance[lane], weight[lane]);
}

/* Two neighbouring line samples are not interpolated across when their distances differ
 * by more than `threshold` relatively (an edge), or a spot light's unshadowed weights (its
 * cone). A point or directional light's weights differ where the distances do, and beside
 * the epipole the camera samples walk their own rays (gather's epipole_sin). */
ALWAYS_INLINE int distance_breaks(float2 a, float2 b, float threshold)
{
    return inline_fabs(a.x - b.x) > threshold * inline_fmin(a.x, b.x);
}

ALWAYS_INLINE int weight_breaks(float2 a, float2 b, float threshold)
{
    return inline_fabs(a.y - b.y) > threshold * inline_fmax(inline_fabs(a.y), inline_fabs(b.y));
}

/* Every `step`-th sample, the ends, and both sides of a break. */
ALWAYS_INLINE int line_sample_needed(global const float2* line, int j, int n, int step, float threshold)
{
    if (j % step == 0 || j == n - 1) return 1;
    float2 before = line[j - 1], here = line[j], after = line[j + 1];
#if SAMPLING_LIGHT == LIGHT_SPOT
    return distance_breaks(before, here, threshold) || weight_breaks(before, here, threshold)
           || distance_breaks(here, after, threshold) || weight_breaks(here, after, threshold);
#else
    return distance_breaks(before, here, threshold) || distance_breaks(here, after, threshold);
#endif
}

/* The lit wedge of slice i's half-plane, which line_samples kept for a spot light: every
 * line sample of the slice lies in it (spot_wedge.h). Unread for the other lights. */
ALWAYS_INLINE float2 line_wedge(global const float2* wedges, int i)
{
#if SAMPLING_LIGHT == LIGHT_SPOT
    return wedges[i];
#else
    return (float2)(0.0f);
#endif
}

/* The radiance of line sample j of slice i, times radiance_scale: its own walk along
 * row i (0 where its ray has no extent); `walked` counts the walks. A spot light's cone
 * is the slice's wedge (line_wedge). */
inline float3 line_sample_radiance(global const frame_t* frame, global const light_t* lights,
                                   global const epipolar_t* ep, global const float2* tree,
                                   global const integrand_t* integrand, global const float* tables,
                                   const walk_features_t* features, global const float2* ranges,
                                   global const float4* sides, float2 wedge, float distance, int i, int j, int n,
                                   uint* walked)
{
    float q, sin_beta;
    line_q(ranges, i, j, n, &q);
    float3 dir = line_direction(ep, sides, i, q, &sin_beta);
    ray_span_t span;
    global const light_t* light = lights + ep->light_index;
#if SAMPLING_LIGHT == LIGHT_SPOT
    if (!ray_span_in_wedge(ep, frame, integrand, dir, distance, wedge, &span)) return (float3)(0.0f);
#else
    if (!ray_span(ep, light, frame, integrand, dir, distance, &span)) return (float3)(0.0f);
#endif
    ++*walked;
    return radiance_scale(light, sin_beta) * row_radiance(ep, tree, i, &span, integrand, tables, frame, features);
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

#ifdef MEDIUM_VARYING
/* medium_faces of line sample j of slice i's ray up to its distance. */
inline int line_sample_faces(global const epipolar_t* ep, global const float2* ranges, global const float4* sides,
                             global const medium_t* m, global const float2* samples, int i, int j, int n)
{
    float q, sin_beta;
    line_q(ranges, i, j, n, &q);
    return medium_faces(m, line_direction(ep, sides, i, q, &sin_beta), samples[j].x);
}
#endif

/* What line_scatter and line_refine_fill know of a line sample (`state`, a byte each). */
#define LINE_LEFT 0     /* not computed (yet): interpolated by the fill */
#define LINE_COMPUTED 1 /* computed by line_scatter, or on a slice that misses the screen */
#define LINE_REFINED 2  /* computed by the refine */

/* Per run of line samples from a `step`-th one to the next (the last run: to the line's
 * last sample too): each sample's radiance times radiance_scale where it is needed (state
 * LINE_COMPUTED), else 0 (LINE_LEFT); w holds the sample's distance, where gather reads it
 * with the radiance (line's distances are then not read there but for a spot light's
 * weights). A work-item per run, not per sample: most samples are not needed, and the
 * run's ends bound line_refine_fill's work-item too. */
NOT_ACROSS_WORK_ITEMS
kernel void line_scatter(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                         global const epipolar_t* ep, global const float2* tree,
                         global const integrand_t* integrand, global const float* tables, global const float2* ranges,
                         global const float4* sides, global const float2* wedges, global const float2* line, int n,
                         global const int* lengths, int step, float threshold, global float4* radiance,
                         global uchar* state, global ushort* walked WALK_FEATURE_ARGS)
{
    walk_features_t features;
    ATTACH_WALK_FEATURES(features) /* a light texture, translucent layers (walk_features.h) */
    int run = get_global_id(0), i = get_global_id(1);
    if (i >= ep->slices) return;
    int first = run * step, length = lengths[i];
    uint walks = 0;
    int end = first >= length - 1 ? first : (first + step >= length - 1 ? length : first + step);
    float2 wedge = line_wedge(wedges, i);
    global const float2* samples = line + i * n;
    for (int j = first; j < end; ++j) {
        float4 result = (float4)(0.0f, 0.0f, 0.0f, samples[j].x);
        uchar known = LINE_LEFT;
        if (samples[j].x < 0.0f) {
            known = LINE_COMPUTED; /* the slice does not cross the screen: nothing reads it */
        } else if (line_sample_needed(samples, j, length, step, threshold)) {
            result.xyz = line_sample_radiance(frame, lights, ep, tree, integrand, tables, &features, ranges, sides,
                                              wedge, samples[j].x, i, j, length, &walks);
            known = LINE_COMPUTED;
        }
        radiance[i * n + j] = result;
        state[i * n + j] = known;
    }
    walked[i * get_global_size(0) + run] = (ushort)walks; /* every run's entry, 0 past the line */
}

/* Per run of line samples between two `step`-th ones (which line_scatter computed, as it
 * did the line's last): first refine, then fill, in place in `radiance` (its w, the
 * distance, kept).
 * - Refine: a sample line_scatter left is computed too where the samples line_scatter
 *   computed either side differ by more than 4 × the threshold (a shadow edge crosses the
 *   line between them), so that the fill draws no straight line across it. Not 1 ×: over
 *   `step` samples the light's own falloff often changes radiance by a few percent, and
 *   refining on it walked many more samples for no error gained on the bench scenes. In a
 *   medium with a box or a grid (MEDIUM_VARYING), also where the two rays cross its faces
 *   differently: a kink of the in-scattering that the threshold does not see. A
 *   refined sample is marked LINE_REFINED, so that every decision sees line_scatter's
 *   samples (LINE_COMPUTED) only.
 * - Fill: each sample still LINE_LEFT is linear in j between the computed samples either
 *   side; it stays LINE_LEFT, so the next fill skips it.
 * The run's ends are computed and stay as they are: the work-items of the runs on either
 * side read them, and write only inside their own runs. */
NOT_ACROSS_WORK_ITEMS
kernel void line_refine_fill(global const frame_t* frame, global const light_t* lights, global const epipolar_t* ep,
                             global const float2* tree, global const integrand_t* integrand,
                             global const float* tables, global const float2* ranges, global const float4* sides,
                             global const float2* wedges,
                             global const float2* line, int n, global const int* lengths, int step, float threshold,
                             global float4* radiance, global uchar* state, global ushort* walked WALK_FEATURE_ARGS)
{
    walk_features_t features;
    ATTACH_WALK_FEATURES(features) /* a light texture, translucent layers (walk_features.h) */
    int run = get_global_id(0), i = get_global_id(1);
    if (i >= ep->slices) return;
    int length = lengths[i], first = run * step;
    int last = inline_min(first + step, length - 1); /* the run's computed ends */
    if (first >= length - 1) return;
    global float4* samples = radiance + i * n;
    global uchar* known = state + i * n;
    uint walks = 0;
    float2 wedge = line_wedge(wedges, i);
    for (int j = first + 1; j < last; ++j) {
        if (known[j] != LINE_LEFT) continue;
        int left = j - 1, right = j + 1;
        while (known[left] != LINE_COMPUTED) --left;
        while (known[right] != LINE_COMPUTED) ++right;
        int breaks = radiance_breaks(samples[left].xyz, samples[right].xyz, 4.0f * threshold);
#ifdef MEDIUM_VARYING /* or an edge of the medium's box or grid crosses the line between them (medium_walk.h) */
        breaks = breaks || line_sample_faces(ep, ranges, sides, features.medium.medium, line + i * n, i, left, length)
                               != line_sample_faces(ep, ranges, sides, features.medium.medium, line + i * n, i, right,
                                                    length);
#endif
        if (breaks) {
            float3 computed = line_sample_radiance(frame, lights, ep, tree, integrand, tables, &features, ranges, sides,
                                                   wedge, line[i * n + j].x, i, j, length, &walks);
            samples[j].xyz = computed;
            known[j] = LINE_REFINED;
        }
    }
    if (walks) walked[i * get_global_size(0) + run] += (ushort)walks; /* line_scatter's work-item, done */
    for (int j = first + 1; j < last; ++j) {
        if (known[j] != LINE_LEFT) continue;
        int left = j - 1, right = j + 1;
        while (known[left] == LINE_LEFT) --left;
        while (known[right] == LINE_LEFT) ++right;
        float t = (float)(j - left) / (float)(right - left);
        samples[j].xyz = inline_mix3(samples[left].xyz, samples[right].xyz, t);
    }
}

#pragma OPENCL FP_CONTRACT OFF /* as luminance's dot (inline_math.h) */
ALWAYS_INLINE float_lanes luminance_lanes(float_lanes r, float_lanes g, float_lanes b)
{
    float_lanes x = r * 0.2126f, y = g * 0.7152f, z = b * 0.0722f;
    return z + (x + y);
}
#pragma OPENCL FP_CONTRACT ON

/* slices_around (walk.h) on each lane. */
ALWAYS_INLINE void slices_around_lanes(global const epipolar_t* ep, float_lanes alpha, int_lanes* i0,
                                       int_lanes* i1, float_lanes* t)
{
    float_lanes offset = alpha - ep->alpha_min;
    offset -= 2.0f * M_PI_F * floor_lanes(offset / (2.0f * M_PI_F));
    float gap = M_PI_F + 0.5f * ep->alpha_step * (float)ep->slices;
    if (!ep->full_circle) offset = offset > gap ? offset - 2.0f * M_PI_F : offset;
    float_lanes f = offset / ep->alpha_step - 0.5f;
    *i0 = int_of_lanes(floor_lanes(f));
    *t = f - float_of_lanes(*i0);
    *i1 = *i0 + 1;
    if (ep->full_circle) {
        *i0 = *i0 < 0 ? *i0 + ep->slices : *i0;
        *i1 = *i1 >= ep->slices ? *i1 - ep->slices : *i1;
    } else {
        *i0 = clamp_int_lanes(*i0, 0, ep->slices - 1);
        *i1 = clamp_int_lanes(*i1, 0, ep->slices - 1);
    }
}

/* What slice i offers a camera sample (its unshadowed weight own_weight, its pseudo-angle
 * q), per lane: the straight line between the two line samples either side
 * of its q, in (r, g, b) (still times radiance_scale); the distance on that line in
 * `between`; and whether the line may stand for the sample (-1), from the line alone: the
 * slice is on the screen, its two samples' radiances agree, and for a spot light, whose
 * cone's silhouette runs along the slices and so can pass between a camera sample and its
 * lines, their weights do not break and the weight between them matches the sample's. (A
 * point or directional light's weights differ where the distances do, which gather
 * weighs; docs/design.md §4.5, "Back to camera samples".)
 * Whether the sample lies on the surface the line sees is gather's test (the distances).
 * Where the line cannot stand for it (an edge lies between them, a shadow's edge crosses
 * the line, the light's own radiance jumps: its cone, the epipole), or where `walk` says
 * so, the fix-up walks the row for the camera sample. Taking the one sample on its side
 * of an edge instead was tried: it ignores the change in β between them, and failed the
 * opaque-fog closed form of tests/methods/test_stability.py (0.83 % against its 0.1 %). */
ALWAYS_INLINE int_lanes slice_line(global const float* ranges, global const float* line,
                                   global const float* radiance, int n, global const int* lengths, float threshold,
                                   int_lanes i, float_lanes q, float_lanes own_weight,
                                   int_lanes walk, float_lanes* between, float_lanes* r, float_lanes* g,
                                   float_lanes* b)
{
    float_lanes lo, hi;
    int_lanes length;
    if (all_lanes(i == i.s0)) { /* the lanes on one slice: its range and length read once (the same values) */
        lo = ranges[2 * i.s0], hi = ranges[2 * i.s0 + 1], length = lengths[i.s0];
    } else {
        lo = LOAD_LANES(ranges, 2 * i), hi = LOAD_LANES(ranges, 2 * i + 1), length = LOAD_INT_LANES(lengths, i);
    }
    float_lanes clamped = fmin_lanes(fmax_lanes((q - lo) / (hi - lo), (float_lanes)(0.0f)), (float_lanes)(1.0f));
    float_lanes f = hi > lo ? clamped * float_of_lanes(length - 1) : 0.0f;
    int_lanes j = min_lanes(int_of_lanes(f), length - 2);
    float_lanes s = f - float_of_lanes(j);
    int_lanes at = i * n + j; /* radiance (r, g, b, distance): 4·at, the next 4·at + 4; line's weight: 2·at + 1 */
    /* the distances from radiance's w, beside the colour; line's weights for a spot light only */
    float_lanes run[8]; /* (r, g, b, distance) of samples j and j + 1 */
    load_runs_of_8(radiance, at, run);
    float_lanes a_distance = run[3], b_distance = run[7];
#if SAMPLING_LIGHT == LIGHT_SPOT
    float_lanes a_weight = LOAD_LANES(line, 2 * at + 1), b_weight = LOAD_LANES(line, 2 * at + 3);
#else
    float_lanes a_weight = 0.0f, b_weight = 0.0f; /* not compared: own_weight < 0 below */
#endif
    float_lanes ra = run[0], ga = run[1], ba = run[2], rb = run[4], gb = run[5], bb = run[6];
    *between = mix_lanes(a_distance, b_distance, s);
    /* not a spot light (own_weight < 0): the weight is not compared */
    float_lanes between_weight = own_weight < 0.0f ? own_weight : mix_lanes(a_weight, b_weight, s);
    float_lanes luminance_a = luminance_lanes(ra, ga, ba), luminance_b = luminance_lanes(rb, gb, bb);
    int_lanes stands =
        ~walk & !(a_distance < 0.0f) /* the slice misses the screen */
        & !((own_weight >= 0.0f)
            & (fabs_lanes(a_weight - b_weight) > threshold * fmax_lanes(fabs_lanes(a_weight), fabs_lanes(b_weight))))
        & (fabs_lanes(between_weight - own_weight)
           <= threshold * fmax_lanes(fabs_lanes(between_weight), fabs_lanes(own_weight)))
        & !(fabs_lanes(luminance_a - luminance_b) > threshold * fmax_lanes(luminance_a, luminance_b));
    *r = mix_lanes(ra, rb, s);
    *g = mix_lanes(ga, gb, s);
    *b = mix_lanes(ba, bb, s);
    return stands;
}

/* Whether a distance on a line is the camera sample's own, within `threshold` of it. */
ALWAYS_INLINE int_lanes same_distance(float_lanes between, float_lanes own, float threshold)
{
    return fabs_lanes(between - own) <= threshold * own;
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

#ifdef MEDIUM_VARYING
/* A slice's line cannot stand for a camera sample whose ray crosses the medium's box or grid
 * by other faces (medium_faces) than either of the two line samples it would be interpolated
 * from: an edge of the box lies between them, where the in-scattering has a kink. Near the
 * epipole a box's edge can run along the lines, between two that the refine computed. */
#define GATHER_MEDIUM_ARGS , global const float4* sides MEDIUM_ARGS
ALWAYS_INLINE int_lanes medium_breaks_lanes(global const epipolar_t* ep, global const float2* ranges,
                                            global const int* lengths, global const float4* sides,
                                            global const medium_t* medium, int_lanes i, float_lanes q,
                                            float_lanes dx, float_lanes dy, float_lanes dz, float_lanes distance)
{
    int breaks[LANES];
    for (int k = 0; k < LANES; ++k) {
        int slice = i[k], length = lengths[slice];
        float2 range = ranges[slice];
        breaks[k] = 0;
        if (!(range.x < range.y) || length < 2) continue;
        float f = clamp((q[k] - range.x) / (range.y - range.x), 0.0f, 1.0f) * (float)(length - 1);
        int j = min((int)f, length - 2);
        int own = medium_faces(medium, (float3)(dx[k], dy[k], dz[k]), distance[k]);
        for (int end = j; end <= j + 1; ++end) {
            float q_end, sin_beta;
            line_q(ranges, slice, end, length, &q_end);
            if (medium_faces(medium, line_direction(ep, sides, slice, q_end, &sin_beta), distance[k]) != own)
                breaks[k] = -1;
        }
    }
    return vload8(0, breaks);
}
#else
#define GATHER_MEDIUM_ARGS
#endif

/* Per LANES camera samples: add each of its two slices' interpolated radiance,
 * weighted as traverse blends them, to `scatter` (with `overwrite`, write it there: the
 * first light's, into a buffer not cleared); flag the sample in `fixup_flags` (a bit per slice)
 * for fix_up where a slice cannot interpolate. No walk and no atomic here: vector
 * arithmetic, a load per lane where the lanes read different slices. */
NOT_ACROSS_WORK_ITEMS
kernel void gather(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                   global const epipolar_t* ep, global const uint* camera_depth, global const float2* offsets,
                   global const float2* ranges, global const float2* line, global const float4* radiance, int n,
                   global const int* lengths, float threshold, float epipole_sin, int samples, int overwrite,
                   global float4* scatter, global uchar* fixup_flags GATHER_MEDIUM_ARGS)
{
    int first = get_global_id(0) * LANES;
    /* lanes past the last sample compute the last one again, and store nothing */
    int_lanes sample = min_lanes(first + (int_lanes)(0, 1, 2, 3, 4, 5, 6, 7), (int_lanes)(samples - 1));
    float_lanes dx, dy, dz; /* camera_ray (walk.h), a perspective and an orthographic view alike */
    camera_ray_lanes(frame, views, offsets, sample, &dx, &dy, &dz);
    int run = first + LANES <= samples; /* samples first, first + 1, ...: their buffers read and written as runs */
    float_lanes depth = run ? load_run((global const float*)camera_depth, first)
                            : LOAD_LANES((global const float*)camera_depth, sample);
    float_lanes distance = fmin_lanes(depth, (float_lanes)(frame->far));
    float3 axis = ep->axis.xyz, u = ep->u.xyz, w = ep->w.xyz;
    float_lanes alpha = atan2_approx_lanes(dot_lanes(dx, dy, dz, w.x, w.y, w.z), dot_lanes(dx, dy, dz, u.x, u.y, u.z));
    int_lanes i0, i1;
    float_lanes t;
    slices_around_lanes(ep, alpha, &i0, &i1, &t);
    float_lanes cos_beta = dot_lanes(dx, dy, dz, axis.x, axis.y, axis.z);
    float_lanes sin_beta = cross_length_lanes(dx, dy, dz, axis.x, axis.y, axis.z);
    /* pseudo_beta */
    float_lanes q = cos_beta >= 0.0f ? sin_beta / (1.0f + cos_beta) : 2.0f - sin_beta / (1.0f - cos_beta);
    global const light_t* light = lights + ep->light_index;
    float_lanes own_weight = -1.0f;
#if SAMPLING_LIGHT == LIGHT_SPOT
    own_weight = spot_weight_lanes(ep, light, dx, dy, dz, cos_beta, sin_beta, distance);
#endif
    float_lanes scale = /* radiance_scale */
        light->type == LIGHT_DIRECTIONAL ? (float_lanes)(1.0f) : fmax_lanes(sin_beta, (float_lanes)(SIN_BETA_MIN));
    /* Within epipole_sin of the epipole the radiance grows as 1/sin β faster than a line's
     * samples follow, and the pixels there are the frame's brightest: they walk their rays. */
    int_lanes beside_epipole = (cos_beta > 0.0f) & (sin_beta < epipole_sin);
    float_lanes r0, g0, b0, r1, g1, b1, between0, between1;
    int_lanes stands0 = slice_line((global const float*)ranges, (global const float*)line,
                                   (global const float*)radiance, n, lengths, threshold, i0, q, own_weight,
                                   beside_epipole, &between0, &r0, &g0, &b0);
    int_lanes stands1 = slice_line((global const float*)ranges, (global const float*)line,
                                   (global const float*)radiance, n, lengths, threshold, i1, q, own_weight,
                                   beside_epipole, &between1, &r1, &g1, &b1);
    /* A slice interpolates where its line sees the sample's own surface there; or where
     * both lines stand, see one surface (their distances within 4 × the threshold) and the
     * sample's distance is theirs blended as their radiances are: a surface seen at a
     * grazing angle changes its distance across the slices, and the blend follows it where
     * each line alone is a few percent off (docs/design.md §4.5, "A surface at a grazing
     * angle"). */
    int_lanes blended = stands0 & stands1 & same_distance((1.0f - t) * between0 + t * between1, distance, threshold)
                        & same_distance(between0, between1, 4.0f * threshold);
    int_lanes from0 = stands0 & (same_distance(between0, distance, threshold) | blended);
    int_lanes from1 = stands1 & (same_distance(between1, distance, threshold) | blended);
#ifdef MEDIUM_VARYING
    from0 &= ~medium_breaks_lanes(ep, ranges, lengths, sides, medium, i0, q, dx, dy, dz, distance);
    from1 &= ~medium_breaks_lanes(ep, ranges, lengths, sides, medium, i1, q, dx, dy, dz, distance);
#endif
    float_lanes w0 = from0 ? 1.0f - t : 0.0f, w1 = from1 ? t : 0.0f; /* the slices' weights, as traverse's */
    float_lanes red = (w0 * r0 + w1 * r1) / scale, green = (w0 * g0 + w1 * g1) / scale;
    float_lanes blue = (w0 * b0 + w1 * b1) / scale;
    int_lanes flags = (from0 ? 0 : 1) | (from1 ? 0 : 2);
    if (run) { /* four stores of two samples' (r, g, b, 0) each, one of the 8 flags */
        global float8_at_float* out = (global float8_at_float*)(scatter + first);
        float_lanes pairs[4];
        records_of_lanes(red, green, blue, 0.0f, pairs);
        for (int k = 0; k < 4; ++k) out[k] = overwrite ? pairs[k] : out[k] + pairs[k];
        *(global uchar8_at_uchar*)(fixup_flags + first) = __builtin_convertvector(flags, uchar8);
        return;
    }
    /* Through private arrays, not red[k]: NVIDIA's compiler emits invalid PTX (a `selp` of
     * mismatched operands) for a lane picked by a loop index and narrowed to uchar. */
    float reds[LANES], greens[LANES], blues[LANES];
    int flag[LANES];
    vstore8(red, 0, reds);
    vstore8(green, 0, greens);
    vstore8(blue, 0, blues);
    vstore8(flags, 0, flag);
    for (int k = 0; k < LANES && first + k < samples; ++k) {
        float4 interpolated = (float4)(reds[k], greens[k], blues[k], 0.0f);
        scatter[first + k] = overwrite ? interpolated : scatter[first + k] + interpolated;
        fixup_flags[first + k] = (uchar)flag[k];
    }
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

/* `counts` of a light's epipolar sampling, as fixup_offsets writes them. */
#define COUNT_COMPUTED 0 /* line samples that walked their row */
#define COUNT_FIXED_UP 1 /* camera samples listed for fix_up: the list's length */

/* Work-items of fixup_offsets' one work-group, each summing a run of the block counts;
 * from clrays/stages/sampling.py (-D). */
#ifndef FIXUP_SCAN_ITEMS
#define FIXUP_SCAN_ITEMS 256
#endif

/* One work-group: each block's offset in the fix-up list (the exclusive prefix sums of
 * `block_counts`), the list's length, and the sum of the `walk_entries` entries of
 * `walked`, into `counts` (COUNT_*). A frame has about a thousand blocks at 1280×720:
 * each work-item sums a run of them, and the first adds up the runs' sums. */
__attribute__((reqd_work_group_size(FIXUP_SCAN_ITEMS, 1, 1)))
kernel void fixup_offsets(int blocks, global const uint* block_counts, int walk_entries,
                          global const ushort* walked, global uint* block_offsets, global uint* counts)
{
    local uint run_sums[FIXUP_SCAN_ITEMS], walk_sums[FIXUP_SCAN_ITEMS];
    int item = get_local_id(0);
    int per_item = (blocks + FIXUP_SCAN_ITEMS - 1) / FIXUP_SCAN_ITEMS;
    int begin = inline_min(item * per_item, blocks), end = inline_min(begin + per_item, blocks);
    uint sum = 0;
    for (int block = begin; block < end; ++block) sum += block_counts[block];
    uint walks = 0;
    for (int k = item; k < walk_entries; k += FIXUP_SCAN_ITEMS) walks += walked[k];
    run_sums[item] = sum;
    walk_sums[item] = walks;
    barrier(CLK_LOCAL_MEM_FENCE);
    if (item == 0) {
        uint listed = 0, computed = 0;
        for (int k = 0; k < FIXUP_SCAN_ITEMS; ++k) {
            uint run = run_sums[k];
            run_sums[k] = listed;
            listed += run;
            computed += walk_sums[k];
        }
        counts[COUNT_COMPUTED] = computed;
        counts[COUNT_FIXED_UP] = listed;
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    uint at = run_sums[item];
    for (int block = begin; block < end; ++block) {
        block_offsets[block] = at;
        at += block_counts[block];
    }
}

/* Per block: list its flagged camera samples (index·4 + a bit per slice) from its offset
 * in `fixups` on (the block counts' prefix sums, from fixup_offsets). */
kernel void fixup_list(int samples, global const uchar* fixup_flags, global const uint* block_offsets,
                       global uint* fixups)
{
    int block = get_global_id(0);
    int begin = block * FIXUP_BLOCK, end = inline_min(begin + FIXUP_BLOCK, samples);
    uint at = block_offsets[block];
    for (int sample = begin; sample < end; ++sample)
        if (fixup_flags[sample]) fixups[at++] = (uint)sample << 2 | fixup_flags[sample];
}

/* Per run of the fix-up list (its length read from `counts`, so the host sizes the launch
 * without it: clrays.device.Device.list_launch): for each listed camera sample, walk the
 * rows of the slices it could not interpolate, as traverse does, and add them with their
 * weights. The runs are the list split evenly over the launch's work-items, one sample
 * each on a GPU (whose launch has a work-item per camera sample), a few dozen each on a
 * CPU (a few work-groups per core, each a stretch of the list, as before). */
NOT_ACROSS_WORK_ITEMS
kernel void fix_up(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                   global const epipolar_t* ep, global const float2* tree, global const integrand_t* integrand,
                   global const float* tables, global const uint* camera_depth, global const float2* offsets,
                   global const uint* fixups, global const uint* counts, global float4* scatter WALK_FEATURE_ARGS)
{
    uint count = counts[COUNT_FIXED_UP], items = get_global_size(0);
    uint per_item = count / items + (count % items != 0);
    uint begin = get_global_id(0) * per_item, end = min(begin + per_item, count);
    if (begin >= end) return;
    walk_features_t features;
    ATTACH_WALK_FEATURES(features) /* a light texture, translucent layers (walk_features.h) */
    for (uint k = begin; k < end; ++k) {
        uint entry = fixups[k];
        int sample = entry >> 2;
        float distance, t;
        int i0, i1;
        float3 dir = gather_ray(frame, views, offsets, camera_depth, ep, sample, &distance, &i0, &i1, &t);
        ray_span_t span;
        if (!ray_span(ep, lights + ep->light_index, frame, integrand, dir, distance, &span)) continue;
        float3 walked = (float3)(0.0f);
        if (entry & 1) walked += (1.0f - t) * row_radiance(ep, tree, i0, &span, integrand, tables, frame, &features);
        if (entry & 2) walked += t * row_radiance(ep, tree, i1, &span, integrand, tables, frame, &features);
        scatter[sample] += (float4)(walked, 0.0f);
    }
}
