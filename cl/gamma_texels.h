/* gamma_texels.h — where the γ texels of a rectified row lie (docs/design.md §4.2): even in
 * the texel coordinate u ∈ [0, N], with γ = γ_max·t·(1 − W + W·t), t = u/N, W =
 * epipolar_t.gamma_warp (0: even in γ, a directional light's), γ_max = N·gamma_step.
 * Texel i covers [γ(i), γ(i + 1)); with W > 0 those near γ = 0, the eye's light ray, are
 * the finest (1 − W of the even width; the last 1 + W). A quadratic rather than an
 * exponential γ0·(e^{K·u/N} − 1): its inverse is a square root, where log1p and expm1,
 * evaluated at both ends of every lit run, took traverse 1.2–1.4× its time on PoCL
 * (bench/RESULTS.md, "γ texels finer near the eye's light ray, kept"). Every reader of the
 * texture goes through these two functions; clrays.structs.texel_gamma and
 * texel_coordinate are the host's copies. */
#ifndef CLRAYS_GAMMA_TEXELS_H
#define CLRAYS_GAMMA_TEXELS_H
#include "common.h"

typedef struct {
    float step; /* epipolar_t.gamma_step, γ_max / N */
    float even; /* 1 − W, the first texel's share of the even width; W = epipolar_t.gamma_warp */
    float rate; /* W / N */
    int warped; /* W > 0 */
} gamma_texels_t;

inline gamma_texels_t gamma_texels_of(global const epipolar_t* ep)
{
    float warp = ep->gamma_warp;
    gamma_texels_t texels = {ep->gamma_step, 1.0f - warp, warp / (float)ep->gamma_samples, warp > 0.0f};
    return texels;
}

/* The texel coordinate u of γ (not clamped): texel floor(u) holds γ. The root of
 * W·t² + (1 − W)·t = g (t = u/N, g = γ/γ_max) in the form that keeps its digits as W → 0. */
inline float gamma_texel_coord(gamma_texels_t texels, float gamma)
{
    float x = gamma / texels.step; /* N·g, the even texels' coordinate */
    if (!texels.warped) return x;
    return 2.0f * x / (texels.even + sqrt(texels.even * texels.even + 4.0f * texels.rate * x));
}

/* γ at texel coordinate u: the start of texel u for an integer u, 0 at u = 0. */
inline float gamma_at_texel(gamma_texels_t texels, float u)
{
    if (!texels.warped) return u * texels.step;
    return u * texels.step * (texels.even + texels.rate * u);
}

/* Texel i's extent in γ. */
inline float gamma_texel_width(gamma_texels_t texels, int i)
{
    return gamma_at_texel(texels, (float)(i + 1)) - gamma_at_texel(texels, (float)i);
}

#endif
