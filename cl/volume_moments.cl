/* volume_moments — in-scattered radiance per camera sample from prefix sums of moments
 * along each rectified row (method `moments`, docs/design.md §9, the volume).
 * Both read ranges (rectify_ranges: β_min, β_max, γ_max, 1/max(β_max - β_min, 1e-6)), on
 * the device, so the host never waits for them.
 * volume_moments_prefix reads tree (level 0: the rectified S[α, γ]); writes prefix
 *   ((gamma_samples + 1) moment sums per row, the first 0).
 * volume_moments_scatter reads frame, views, lights, epipolar, prefix, integrand, tables,
 *   camera_depth, offsets, and a textured light's tables (walk_features.h, LIGHT_TEXTURE);
 *   adds into scatter (float4 per camera sample).
 *
 *   row α:   S[0]   S[1]   S[2]  ...  S[n-1]          z = beta_depth(S): [β_min, β_max] → [0.05, 0.95]
 *   prefix:  P[0]=0 P[1]   P[2]  ...  P[n]            P[i+1] = P[i] + (z, z², z³, z⁴) of S[i]
 *   a ray's [γa, γb): texels [ia, ib): mean moments (P[ib] − P[ia]) / (ib − ia)
 *
 * A ray (β, γ) is lit where β < S, so its lit fraction over [γa, γb) is the mass of the
 * texels' S at or beyond β (β_min, β_max: the frame's visible rays, so clamping S to
 * them changes no ray's answer but narrows the distribution the bound works with): one reconstruction from the mean moments, whatever the
 * number of shadow edges in between, times the unshadowed radiance of the interval.
 * MOMENT_CHUNKS splits the ray's γ range in equal parts, each with its own fraction. */
#include "moments.h"
#include "walk.h"

#ifndef MOMENT_CHUNKS
#define MOMENT_CHUNKS 8
#endif

/* Prefix sums in double where the device has it: a difference of two sums of up to
 * 16384 terms keeps the float32 precision of the mean it gives (docs/design.md §9). */
#if defined(cl_khr_fp64) && PREFIX_DOUBLE
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double4 prefix_t;
typedef double prefix_scalar_t;
#define TO_PREFIX(v) convert_double4(v)
#define FROM_PREFIX(v) convert_float4(v)
#else
typedef float4 prefix_t;
typedef float prefix_scalar_t;
#define TO_PREFIX(v) (v)
#define FROM_PREFIX(v) (v)
#endif

/* β as the depth the moments are taken of: the visible rays' [β_min, β_max] onto
 * [0.05, 0.95], clamped. Clamped values sit 0.05 inside [0, 1]: distributions on {0, 1}
 * alone have the moments that the moment bias pulls towards, so it could not keep their
 * Hankel matrix invertible. */
inline float beta_depth(float beta, float beta_min, float inverse_beta_range)
{
    return 0.05f + 0.9f * clamp((beta - beta_min) * inverse_beta_range, 0.0f, 1.0f);
}

kernel void volume_moments_prefix(global const epipolar_t* ep, global const float2* tree,
                                  global const float4* ranges, global prefix_t* prefix)
{
    int slice = get_global_id(0);
    if (slice >= ep->slices) return;
    float beta_min = ranges->x, inverse_beta_range = ranges->w;
    int n = ep->gamma_samples;
    global const float2* row = tree + (size_t)slice * 2 * n; /* level 0 of the row's min-max tree */
    global prefix_t* out = prefix + (size_t)slice * (n + 1);
    prefix_t sum = (prefix_t)(0);
    out[0] = sum;
    for (int i = 0; i < n; ++i) {
        float z = beta_depth(row[i].x, beta_min, inverse_beta_range);
        float z2 = z * z;
        sum += TO_PREFIX(((float4)(z, z2, z2 * z, z2 * z2)));
        out[i + 1] = sum;
    }
}

/* The unshadowed radiance of [g0, g1) of the ray: the integrand's segment, times the light's
 * texture along each of the two rows (blended as their moments) when the light has one,
 * as traverse's lit runs (walk.h, docs/light-textures.md). */
inline float3 chunk_radiance(global const integrand_t* in, global const float* tables, global const frame_t* frame,
                             const integrand_row_t* ray, const walk_features_t* features,
                             global const float* texture0, global const float* texture1, float t,
                             gamma_texels_t texels, float g0, float g1)
{
#ifdef LIGHT_TEXTURE
    if (features->textured->textured && g1 > g0)
        return mix(unweighted_run_radiance(in, tables, frame, ray, features, texture0, texels, g0, g1),
                   unweighted_run_radiance(in, tables, frame, ray, features, texture1, texels, g0, g1), t);
#endif
    return segment_radiance(in, tables, frame, ray, g0, g1);
}

/* Radiance of [gamma_begin, gamma_end) of ray beta between two rows (weights 1 − t, t):
 * per chunk, the two rows' mean moments blended as traverse blends their radiance, one
 * reconstruction of the lit fraction, times the chunk's unshadowed radiance, which is the
 * same ray's in both rows. */
inline float3 moments_rows(global const epipolar_t* ep, global const prefix_t* row0, global const prefix_t* row1,
                           float t, const integrand_row_t* ray, float gamma_begin, float gamma_end,
                           global const integrand_t* in, global const float* tables, global const frame_t* frame,
                           float receiver, float moment_bias, const walk_features_t* features,
                           global const float* texture0, global const float* texture1)
{
    int n = ep->gamma_samples;
    gamma_texels_t texels = gamma_texels_of(ep);
    float3 radiance = (float3)(0.0f);
    float chunk = (gamma_end - gamma_begin) / (float)MOMENT_CHUNKS;
    float run_start = -1.0f; /* γ ≥ 0 where a run of wholly lit parts began */
    for (int c = 0; c < MOMENT_CHUNKS; ++c) {
        float g0 = gamma_begin + c * chunk, g1 = c + 1 == MOMENT_CHUNKS ? gamma_end : g0 + chunk;
        int i0 = clamp((int)floor(gamma_texel_coord(texels, g0)), 0, n);
        int i1 = clamp((int)ceil(gamma_texel_coord(texels, g1)), i0, n);
        float lit = 1.0f;
        if (i1 > i0) {
            prefix_scalar_t count = (prefix_scalar_t)(i1 - i0);
            float4 mean = mix(FROM_PREFIX((row0[i1] - row0[i0]) / count), FROM_PREFIX((row1[i1] - row1[i0]) / count),
                              t);
            lit = msm_hamburger_visibility(mean, receiver, moment_bias);
        }
        if (lit >= 1.0f) { /* wholly lit parts in a row are one lit run, integrated once */
            if (run_start < 0.0f) run_start = g0;
            continue;
        }
        if (run_start >= 0.0f) {
            radiance += chunk_radiance(in, tables, frame, ray, features, texture0, texture1, t, texels,
                                       run_start, g0);
            run_start = -1.0f;
        }
        if (lit > 0.0f)
            radiance += lit * chunk_radiance(in, tables, frame, ray, features, texture0, texture1, t, texels,
                                             g0, g1);
    }
    if (run_start >= 0.0f)
        radiance += chunk_radiance(in, tables, frame, ray, features, texture0, texture1, t, texels, run_start,
                                   gamma_end);
    return radiance;
}

NOT_ACROSS_WORK_ITEMS
kernel void volume_moments_scatter(global const frame_t* frame, global const view_t* views,
                                   global const light_t* lights, global const epipolar_t* epipolar,
                                   global const prefix_t* prefix, global const integrand_t* integrand,
                                   global const float* tables, global const uint* camera_depth,
                                   global const float2* offsets, global const float4* ranges,
                                   float moment_bias, global float4* scatter WALK_FEATURE_ARGS)
{
    int sample = get_global_id(0);
    if (sample >= frame->width * frame->height * frame->spp) return;
    global const epipolar_t* ep = epipolar;
    float3 dir = camera_ray(frame, views, offsets, sample);
    float distance = fmin(as_float(camera_depth[sample]), frame->far);
    /* The ray's β, γ range, lamp chord and slices, as traverse.cl takes them (walk.h). */
    ray_span_t span;
    if (!ray_span(ep, lights + ep->light_index, frame, integrand, dir, distance, &span)) return;
    int i0, i1;
    float t;
    nearest_slices(ep, dir, &i0, &i1, &t);
    size_t stride = (size_t)ep->gamma_samples + 1;
    global const prefix_t* row0 = prefix + i0 * stride;
    global const prefix_t* row1 = prefix + i1 * stride;
    float receiver = beta_depth(span.ray.beta, ranges->x, ranges->w);
    walk_features_t features;
    ATTACH_WALK_FEATURES(features) /* a light texture (walk_features.h) */
#ifdef LIGHT_TEXTURE
    size_t texture_stride = features.textured->textured
                                ? (size_t)3 * (features.textured->rank + 1) * (ep->gamma_samples + 1) : 0;
    global const float* texture0 = features.prefix + i0 * texture_stride;
    global const float* texture1 = features.prefix + i1 * texture_stride;
#else
    global const float* texture0 = 0; /* (read only for a textured light) */
    global const float* texture1 = 0;
#endif
    float3 radiance = moments_rows(ep, row0, row1, t, &span.ray, span.gamma_begin, span.gamma_lamp0, integrand, tables,
                                   frame, receiver, moment_bias, &features, texture0, texture1);
    if (span.gamma_lamp1 < span.gamma_end)
        radiance += moments_rows(ep, row0, row1, t, &span.ray, span.gamma_lamp1, span.gamma_end, integrand, tables,
                                 frame, receiver, moment_bias, &features, texture0, texture1);
    scatter[sample] += (float4)(radiance, 0.0f);
}
