/* integrand.h — radiance of a lit interval [γ0, γ1) of camera ray β, from the tables
 * clrays/stages/integrand.py builds per frame; a line-by-line port of its segment_radiance
 * (docs/integrand.md has the derivation and the measured errors). Every mode is
 *
 *     L = row_scale(β) · [F(β, x(β, γ1)) - F(β, x(β, γ0))]
 *
 * with x ∈ [0, 1] a per-row coordinate and F the prefix integral of a smooth integrand:
 *   point/spot:  x = γ/(π-β)  (rows run to the ray's point at infinity), row_scale = (π-β)/sinβ
 *   directional: x = s/s_end with s = γ/sinβ,                          row_scale = s_end
 * Rows sit at β = beta_min + (beta_max - beta_min)·sin²(πt/2), t uniform in [0, 1].
 *
 *   table:  tables = F[channel][n_beta][n_gamma]                          (bilinear)
 *           grey (every channel the same σt): F[1][n_beta][n_gamma] of unit amplitude,
 *           each channel's segment that times its amplitude
 *   svd:    tables = B[channel][rank][n_beta], then P[channel][rank][n_gamma]
 *           F ≈ Σ B_i(β)·P_i(x)                                            (linear)
 *   analytic: closed forms (directional light; isotropic point light with σt = 0). */
#ifndef CLRAYS_INTEGRAND_H
#define CLRAYS_INTEGRAND_H
#include "lighting.h"
#include "atan2_approx.h"
#include "medium.h"
#ifdef MEDIUM_VARYING
#include "medium_walk.h"
#endif

/* SIN_BETA_MIN, the clamp of sinβ in every 1/sinβ, comes from clrays/structs.py (-D): the
 * host's tables use the same one. */

/* Cell index in [0, n-2] and the fraction within it. */
inline int grid_split(float coordinate, int n, float* fraction)
{
    int i = inline_clamp_int((int)inline_floor(coordinate), 0, n - 2);
    *fraction = coordinate - (float)i;
    return i;
}

/* Fractional row index of β: the inverse of the sin² node spacing, precise at both ends. */
inline float beta_coordinate(global const integrand_t* in, float beta)
{
    float span = in->beta_max - in->beta_min;
    if (!(span > 0.0f)) return 0.0f;
    float lo = inline_sqrt(inline_clamp(beta - in->beta_min, 0.0f, span));
    float hi = inline_sqrt(inline_clamp(in->beta_max - beta, 0.0f, span));
    return M_2_PI_F * atan2_approx(lo, hi) * (float)(in->n_beta - 1);
}

/* x(β, γ) per channel (only directional rows differ per channel, through s_end).
 * delta = π - β, taken from the geometry rather than from β: within float32's spacing of π
 * (2.4e-7) the difference M_PI_F - β is all rounding, and x = γ/(π-β) with it. */
inline float3 row_coordinate(global const integrand_t* in, float delta, float sin_beta, float gamma)
{
    if (in->light_type == LIGHT_DIRECTIONAL)
        return inline_clamp3((gamma / sin_beta) / in->s_end.xyz, 0.0f, 1.0f);
    float x = delta > 0.0f ? gamma / delta : (gamma > 0.0f ? 1.0f : 0.0f);
    return (float3)(inline_clamp(x, 0.0f, 1.0f));
}

inline float3 row_scale(global const integrand_t* in, float delta, float sin_beta)
{
    if (in->light_type == LIGHT_DIRECTIONAL) return in->s_end.xyz;
    return (float3)(delta > SIN_BETA_MIN ? delta / sin_beta : 1.0f); /* (π-β)/sinβ → 1 as β → π */
}

/* Bilinear F of one channel at row j + fj, column x·(n_gamma - 1). */
inline float table_lookup(global const float* table, int n_beta, int n_gamma, int j, float fj, float x)
{
    float fk;
    int k = grid_split(x * (float)(n_gamma - 1), n_gamma, &fk);
    global const float* a = table + (size_t)j * n_gamma + k;
    global const float* b = a + n_gamma;
    return (1.0f - fj) * ((1.0f - fk) * a[0] + fk * a[1]) + fj * ((1.0f - fk) * b[0] + fk * b[1]);
}

inline float svd_difference(global const integrand_t* in, global const float* tables, int channel, int j,
                            float fj, float x0, float x1)
{
    global const float* basis = tables + (size_t)channel * in->rank * in->n_beta;
    global const float* prefix = tables + (size_t)3 * in->rank * in->n_beta + (size_t)channel * in->rank * in->n_gamma;
    float f0, f1;
    int k0 = grid_split(x0 * (float)(in->n_gamma - 1), in->n_gamma, &f0);
    int k1 = grid_split(x1 * (float)(in->n_gamma - 1), in->n_gamma, &f1);
    float sum = 0.0f;
    for (int i = 0; i < in->rank; ++i) {
        global const float* b = basis + i * in->n_beta;
        global const float* p = prefix + i * in->n_gamma;
        float b_i = (1.0f - fj) * b[j] + fj * b[j + 1];
        sum += b_i * (((1.0f - f1) * p[k1] + f1 * p[k1 + 1]) - ((1.0f - f0) * p[k0] + f0 * p[k0 + 1]));
    }
    return sum;
}

/* What a segment lookup needs that depends only on the ray's β: computed once per
 * pixel, used for every lit run of both slices. */
typedef struct {
    float beta;
    float delta;     /* π - β, precise as β → π */
    float sin_beta;
    float3 scale;    /* row_scale(β) */
    int row;         /* table row j ... */
    float row_t;     /* ... and the fraction towards row j + 1 */
    float cos_beta;
#ifdef MEDIUM_VARYING
    medium_ray_t* medium; /* the ray's own prefix (medium_walk.h), which replaces the tables */
#endif
} integrand_row_t;

inline integrand_row_t integrand_row(global const integrand_t* in, float beta, float sin_beta, float cos_beta)
{
    integrand_row_t r;
    r.beta = beta;
    r.sin_beta = inline_fmax(sin_beta, SIN_BETA_MIN);
    r.cos_beta = cos_beta;
    r.delta = atan2_approx(r.sin_beta, -cos_beta);
    r.scale = row_scale(in, r.delta, r.sin_beta);
    r.row = in->mode == INTEGRAND_ANALYTIC ? 0 : grid_split(beta_coordinate(in, beta), in->n_beta, &r.row_t);
    return r;
}

inline float3 segment_radiance(global const integrand_t* in, global const float* tables,
                               global const frame_t* frame, const integrand_row_t* r, float gamma0, float gamma1)
{
#ifdef MEDIUM_VARYING /* a bounded or heterogeneous medium: the tables (homogeneous) are not read */
    return medium_ray_segment(r->medium, gamma0, gamma1);
#endif
    if (in->mode == INTEGRAND_ANALYTIC) {
        if (in->light_type == LIGHT_DIRECTIONAL) {
            /* σs·E·ρ(cos β)·e^{-σt·s0}·(1 - e^{-σt·Δs})/σt, → Δs as σt → 0 (s = γ/sin β). */
            float3 sigma_t = in->sigma_t.xyz;
            float s0 = inline_fmax(gamma0, 0.0f) / r->sin_beta;
            float ds = inline_fmax(gamma1, 0.0f) / r->sin_beta - s0;
            float3 tail = select((float3)(ds), -expm1(-sigma_t * ds) / sigma_t, isgreater(sigma_t, (float3)(0.0f)));
            return in->amplitude.xyz * phase_function(frame, r->cos_beta) * exp(-sigma_t * s0) * tail;
        }
        float span = inline_clamp(gamma1, 0.0f, r->delta) - inline_clamp(gamma0, 0.0f, r->delta);
        return in->amplitude.xyz * (span / (4.0f * M_PI_F * in->d_el * r->sin_beta));
    }
    int j = r->row;
    float fj = r->row_t;
    float3 x0 = row_coordinate(in, r->delta, r->sin_beta, gamma0);
    float3 x1 = row_coordinate(in, r->delta, r->sin_beta, gamma1);
    float3 difference;
    if (in->mode == INTEGRAND_TABLE && in->grey) { /* the channels differ by their amplitude alone */
        float unit = table_lookup(tables, in->n_beta, in->n_gamma, j, fj, x1.x)
                   - table_lookup(tables, in->n_beta, in->n_gamma, j, fj, x0.x);
        difference = in->amplitude.xyz * unit;
    } else if (in->mode == INTEGRAND_TABLE) {
        size_t plane = (size_t)in->n_beta * in->n_gamma;
        difference.x = table_lookup(tables, in->n_beta, in->n_gamma, j, fj, x1.x)
                     - table_lookup(tables, in->n_beta, in->n_gamma, j, fj, x0.x);
        difference.y = table_lookup(tables + plane, in->n_beta, in->n_gamma, j, fj, x1.y)
                     - table_lookup(tables + plane, in->n_beta, in->n_gamma, j, fj, x0.y);
        difference.z = table_lookup(tables + 2 * plane, in->n_beta, in->n_gamma, j, fj, x1.z)
                     - table_lookup(tables + 2 * plane, in->n_beta, in->n_gamma, j, fj, x0.z);
    } else {
        difference = (float3)(svd_difference(in, tables, 0, j, fj, x0.x, x1.x),
                              svd_difference(in, tables, 1, j, fj, x0.y, x1.y),
                              svd_difference(in, tables, 2, j, fj, x0.z, x1.z));
    }
    return r->scale * difference;
}

#endif
