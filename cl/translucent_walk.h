/* translucent_walk.h — the walk of a row that translucent layers cross (docs/design.md,
 * "Translucent occluders: the light side"): walk.h's row_radiance takes it for a slice
 * whose rectified layers (translucency_rectify) are not all empty, and keeps the min-max
 * tree walk for every other. Texel by texel: a texel is lit where level 0 of the tree
 * says so (binary, the opaque occluders), and its light is then scaled by the
 * transmittance of the last layer whose β is at most the ray's (the layers the ray's
 * point there lies behind). Neighbouring texels of equal transmittance merge into one run,
 * so the integrand is evaluated once per run, as on an opaque row.
 * Only built with TRANSLUCENT_LAYERS (a scene with translucent objects). */
#ifndef CLRAYS_TRANSLUCENT_WALK_H
#define CLRAYS_TRANSLUCENT_WALK_H
#ifdef TRANSLUCENT_LAYERS

#include "translucency.h"

/* (Its kernel arguments, RECTIFIED_LAYER_ARGS, are declared in walk_features.h.) */

/* The transmittance of ray β at rectified texel `position` of a row's layers. */
inline float3 texel_transmittance(global const float* beta_row, global const uint2* clear_row, int position, float beta)
{
    float3 through = (float3)(1.0f);
    for (int k = 0; k < TRANSLUCENT_LAYERS; ++k) {
        if (!(beta_row[position * TRANSLUCENT_LAYERS + k] <= beta)) break;
        through = unpack_clear(clear_row[position * TRANSLUCENT_LAYERS + k]);
    }
    return through;
}

inline float3 walk_row_translucent(global const epipolar_t* ep, global const float2* row,
                                   global const float* beta_row, global const uint2* clear_row,
                                   const integrand_row_t* ray, float gamma_begin, float gamma_end,
                                   global const integrand_t* in, global const float* tables,
                                   global const frame_t* frame, const walk_features_t* features,
                                   global const float* row_prefix)
{
    float beta = ray->beta;
    int n = ep->gamma_samples;
    gamma_texels_t texels = gamma_texels_of(ep);
    int end = min(n, (int)ceil(gamma_texel_coord(texels, gamma_end)));
    float3 radiance = (float3)(0.0f), run_through = (float3)(0.0f);
    int run_start = -1, run_end = 0;
    for (int position = clamp((int)floor(gamma_texel_coord(texels, gamma_begin)), 0, n); position < end; ++position) {
        float3 through = row[position].x > beta ? texel_transmittance(beta_row, clear_row, position, beta)
                                                : (float3)(0.0f);
        int lit = through.x + through.y + through.z > 0.0f;
        if (lit && run_start >= 0 && all(through == run_through)) {
            run_end = position + 1;
            continue;
        }
        if (run_start >= 0)
            radiance += run_through * run_radiance(in, tables, frame, ray, features, row_prefix, texels,
                                                   fmax(gamma_at_texel(texels, (float)run_start), gamma_begin),
                                                   fmin(gamma_at_texel(texels, (float)run_end), gamma_end));
        run_start = lit ? position : -1;
        run_end = position + 1;
        run_through = through;
    }
    if (run_start >= 0)
        radiance += run_through * run_radiance(in, tables, frame, ray, features, row_prefix, texels,
                                               fmax(gamma_at_texel(texels, (float)run_start), gamma_begin),
                                               fmin(gamma_at_texel(texels, (float)run_end), gamma_end));
    return radiance;
}

#endif
#endif
