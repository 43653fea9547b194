/* mboit.h — the transmittance along a camera ray from the translucent films it meets, gathered
 * in no order (docs/design.md, translucent surfaces: the camera side). `gathered`
 * (TRANSPARENCY_GATHERED): the exact product of the (1 − α) of the films in front of a depth,
 * read from the sample's gathered list. `mboit`: the films' absorbance b0 per channel, four
 * power moments of the mean absorbance over warped depth, and the Hamburger reconstruction
 * (moments.h) of the fraction in front of any depth. Shared by the composite (transparency.cl)
 * and the weighted walk of the fog (transparency_walk.cl, and raymarch.cl built with
 * TRANSPARENCY_WEIGHTED_WALK). */
#ifndef CLRAYS_MBOIT_H
#define CLRAYS_MBOIT_H

#include "moments.h"

#ifndef TRANSPARENCY_GATHERED
#define TRANSPARENCY_GATHERED 0 /* 1: the exact product over the gathered films, not MBOIT's estimate */
#endif
#ifndef TRANSPARENCY_LOG_WARP
#define TRANSPARENCY_LOG_WARP 0 /* MBOIT: moments of log depth instead of depth */
#endif

/* Absorbance −ln(1 − α) is taken with α at most this: a channel with opacity 1 absorbs all but
 * e^{-13.8} ≈ 1e-6 (MBOIT needs a finite absorbance; the peeled product uses α itself). */
#define OPACITY_MAX 0.999999f

/* MBOIT's depth coordinate in [0, 1] (docs/design.md, translucent surfaces: the camera side):
 * depth, or log depth, between the nearest and farthest distance of the translucent triangles
 * from the eye. */
inline float warped_depth(float z, float2 range)
{
#if TRANSPARENCY_LOG_WARP
    return clamp(log(z / range.x) / log(range.y / range.x), 0.0f, 1.0f);
#else
    return clamp((z - range.x) / (range.y - range.x), 0.0f, 1.0f);
#endif
}

/* MBOIT's overestimation (Münstermann et al. 2018): on scenes/glass_row.yaml 0.25 cuts the error of the
 * lower bound alone from 1.45 % to 1.1 % (relative RMSE against 8-layer peeling; 0.5: 1.05 %, 0.1: 1.3 %). */
#define OVERESTIMATION 0.25f
/* The fraction of the absorbance in front of w: between the Hamburger lower bound (cl/moments.h,
 * the mass of the three-point support strictly in front) and the upper bound (with the mass at w
 * too), OVERESTIMATION of the way up, as MBOIT does. */
inline float absorbance_in_front(float4 moments, float w, float moment_bias)
{
    float4 b = biased_moments(moments, moment_bias);
    float w1, w2;
    three_point_support(b, w, &w1, &w2);
    float lower = clamp(three_point_shadow(b, w, w1, w2), 0.0f, 1.0f);
    float at_w = clamp(three_point_weight(b, w, w1, w2), 0.0f, 1.0f);
    return clamp(lower + OVERESTIMATION * at_w, 0.0f, 1.0f);
}

inline float3 absorbance(float3 alpha)
{
    return -log(1.0f - fmin(alpha, (float3)(OPACITY_MAX)));
}

/* One camera sample's films: their moments for MBOIT, and where the gathered list lies. */
typedef struct {
    float3 b0;      /* the total absorbance per channel */
    float3 behind;  /* T(D), the transmittance of all the films: exp(−b0), or the exact product */
    float4 b;       /* moments (w, w², w³, w⁴) of the mean absorbance, normalised by its total */
    float nearest;  /* the nearest and farthest film's depth (+inf and 0 without films) */
    float farthest;
    int count;      /* films in the list */
    int samples, sample;
    global const uint* film_depth;
    global const int* film_tri;
    global const float4* tri_opacity;
} film_moments_t;

/* The moments of sample's films, slot-major film_depth and film_tri (transparency.cl), the
 * slots after the first empty one unread. */
inline film_moments_t film_moments(int slots, int samples, int sample, global const uint* film_depth,
                                   global const int* film_tri, global const float4* tri_opacity, float2 depth_range)
{
    film_moments_t m = {(float3)(0.0f), (float3)(1.0f), (float4)(0.0f), INFINITY, 0.0f, 0,
                        samples, sample, film_depth, film_tri, tri_opacity};
    float total = 0.0f;
    for (int k = 0; k < slots; ++k) {
        int tri = film_tri[k * samples + sample];
        if (tri < 0) break;
        ++m.count;
        m.behind *= 1.0f - tri_opacity[tri].xyz;
        float3 a = absorbance(tri_opacity[tri].xyz);
        float z = as_float(film_depth[k * samples + sample]);
        float w = warped_depth(z, depth_range);
        float mean = (a.x + a.y + a.z) / 3.0f;
        m.b0 += a;
        total += mean;
        m.b += mean * (float4)(w, w * w, w * w * w, w * w * w * w);
        m.nearest = fmin(m.nearest, z);
        m.farthest = fmax(m.farthest, z);
    }
    if (total > 0.0f) m.b /= total;
#if !TRANSPARENCY_GATHERED
    m.behind = exp(-m.b0);
#endif
    return m;
}

/* T(z⁻), the transmittance of the films in front of depth z: the product of their (1 − α) over
 * the gathered list (`gathered`; the list holds each surface once, so a film at z itself is not
 * in front of z), or MBOIT's estimate from the moments. */
inline float3 estimated_transmittance(const film_moments_t* m, float z, float2 depth_range, float moment_bias)
{
#if TRANSPARENCY_GATHERED
    float3 through = (float3)(1.0f);
    for (int k = 0; k < m->count; ++k)
        if (as_float(m->film_depth[k * m->samples + m->sample]) < z)
            through *= 1.0f - m->tri_opacity[m->film_tri[k * m->samples + m->sample]].xyz;
    return through;
#else
    return exp(-m->b0 * absorbance_in_front(m->b, warped_depth(z, depth_range), moment_bias));
#endif
}

/* The weight of the fog at depth s in the films' composite, T(s) − T(D) (docs/design.md, the
 * camera side: ∫_0^D T dL = T(D)·L(0, D) + ∫_0^D (T(s) − T(D)) dL(0, s), and the first term is
 * the frame's own in-scattering that shade attenuates). In front of the nearest film it is
 * exactly 1 − T(D); from there the product of the films in front (`gathered`) or MBOIT's
 * estimate, kept in [0, 1 − T(D)]; behind the farthest 0. */
inline float3 fog_weight(const film_moments_t* m, float s, float2 depth_range, float moment_bias)
{
    float3 behind_all = m->behind;
    if (s <= m->nearest) return 1.0f - behind_all;
    if (s >= m->farthest) return (float3)(0.0f);
    return clamp(estimated_transmittance(m, s, depth_range, moment_bias) - behind_all, 0.0f, 1.0f - behind_all);
}

#endif
