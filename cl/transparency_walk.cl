/* transparency_walk — MBOIT's fog in front of the opaque depth in one walk per camera sample
 * that meets translucent films (docs/design.md, translucent surfaces: the camera side):
 * ∫_0^D (T(s) − T(D)) dL(0, s) for one light, T MBOIT's transmittance from the sample's
 * moments (mboit.h), along the lit runs of the two min-max rows nearest the sample
 * (traverse.cl's walk), each run split at WALK_PIECES + 1 pieces of the ray and each piece
 * weighted by T − T(D) at its middle (walk.h's weighted run_radiance).
 * Reads frame, views, lights, epipolar, tree, integrand, tables, offsets, walk_samples (the
 * samples with films), film_depth, film_tri (transparency.cl's gather), tri_opacity, and the
 * walk's features (walk_features.h); adds into walked_fog (float4 per camera sample).
 *
 *   along the ray:  eye |— piece 0: 1 − T(D) —| nearest film |— 1 … WALK_PIECES —| farthest film
 *   the pieces between the films even in warped depth; behind the farthest the weight is 0. */
#ifndef TRANSPARENCY_WEIGHTED_WALK
#define TRANSPARENCY_WEIGHTED_WALK 1
#endif
#ifndef WALK_PIECES
#define WALK_PIECES 4 /* measured on scenes/glass_row.yaml (bench/RESULTS.md, the camera side) */
#endif
#include "mboit.h"
#include "walk.h"

/* The depth a fraction f of the way from near to far, even in MBOIT's warp. */
inline float depth_between(float near, float far, float f)
{
#if TRANSPARENCY_LOG_WARP
    return near * pow(far / near, f);
#else
    return mix(near, far, f);
#endif
}

/* γ of depth s along the ray of angle β to the eye–light axis (walk.h's ray_span). */
inline float depth_gamma(global const epipolar_t* ep, int directional, float sin_beta, float cos_beta, float s)
{
    return directional ? s * sin_beta : atan2(s * sin_beta, ep->d_el - s * cos_beta);
}

/* The bounds of the pieces between the nearest and the farthest film into bounds[0 … WALK_PIECES]:
 * with the gathered films' exact transmittance and at most WALK_PIECES + 1 films, the films'
 * own depths in order (the last repeated: empty pieces), so that T is constant over each piece
 * and its weight at the middle is exact; otherwise even steps in the warp. */
inline void piece_bounds(const film_moments_t* films, float* bounds)
{
#if TRANSPARENCY_GATHERED
    if (films->count <= WALK_PIECES + 1) {
        int n = 0;
        for (int k = 0; k < films->count; ++k) { /* insertion sort of a handful of depths */
            float z = as_float(films->film_depth[k * films->samples + films->sample]);
            int at = n++;
            for (; at > 0 && bounds[at - 1] > z; --at) bounds[at] = bounds[at - 1];
            bounds[at] = z;
        }
        for (int j = n; j <= WALK_PIECES; ++j) bounds[j] = bounds[n - 1];
        return;
    }
#endif
    for (int j = 0; j <= WALK_PIECES; ++j)
        bounds[j] = depth_between(films->nearest, films->farthest, (float)j / (float)WALK_PIECES);
}

/* The pieces of the ray and the fog's weight over each, into the walk's features. */
inline void fog_pieces(global const epipolar_t* ep, global const light_t* light, float3 dir,
                       const film_moments_t* films, float2 depth_range, float moment_bias, walk_features_t* features)
{
    float sin_beta, cos_beta;
    ray_beta(ep, dir, &sin_beta, &cos_beta);
    int directional = light->type == LIGHT_DIRECTIONAL;
    float bounds[WALK_PIECES + 1];
    piece_bounds(films, bounds);
    features->piece_gamma[0] = -INFINITY;
    features->piece_weight[0] = (float4)(1.0f - films->behind, 0.0f);
    for (int j = 0; j <= WALK_PIECES; ++j)
        features->piece_gamma[j + 1] = depth_gamma(ep, directional, sin_beta, cos_beta, bounds[j]);
    for (int j = 1; j <= WALK_PIECES; ++j) {
        float middle = TRANSPARENCY_GATHERED ? 0.5f * (bounds[j - 1] + bounds[j])
                                             : depth_between(films->nearest, films->farthest,
                                                             ((float)j - 0.5f) / (float)WALK_PIECES);
        features->piece_weight[j] = (float4)(fog_weight(films, middle, depth_range, moment_bias), 0.0f);
    }
}

NOT_ACROSS_WORK_ITEMS
kernel void transparency_walk(global const frame_t* frame, global const view_t* views, global const light_t* lights,
                              global const epipolar_t* epipolar, global const float2* tree,
                              global const integrand_t* integrand, global const float* tables,
                              global const float2* offsets, global const int* walk_samples, int walk_count, int slots,
                              global const uint* film_depth, global const int* film_tri,
                              global const float4* tri_opacity, float2 depth_range, float moment_bias,
                              global float4* walked_fog WALK_FEATURE_ARGS)
{
    int index = get_global_id(0);
    if (index >= walk_count) return;
    int sample = walk_samples[index];
    int samples = frame->width * frame->height * frame->spp;
    global const epipolar_t* ep = epipolar;
    global const light_t* light = lights + ep->light_index;
    float3 dir = camera_ray(frame, views, offsets, sample);
    film_moments_t films = film_moments(slots, samples, sample, film_depth, film_tri, tri_opacity, depth_range);
    ray_span_t span;
    /* Behind the farthest film the fog's weight is 0: the walk ends there. */
    if (!(films.farthest > 0.0f) || !ray_span(ep, light, frame, integrand, dir, films.farthest, &span)) return;
    int i0, i1;
    float t;
    nearest_slices(ep, dir, &i0, &i1, &t);
    walk_features_t features;
    ATTACH_WALK_FEATURES(features) /* a light texture, translucent layers (walk_features.h) */
    fog_pieces(ep, light, dir, &films, depth_range, moment_bias, &features);
    float3 near0 = row_radiance(ep, tree, i0, &span, integrand, tables, frame, &features);
    float3 near1 = row_radiance(ep, tree, i1, &span, integrand, tables, frame, &features);
    walked_fog[sample] += (float4)(mix(near0, near1, t), 0.0f);
}
