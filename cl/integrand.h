/* integrand.h — radiance of a lit interval [γ0, γ1) of camera ray β, from the tables
 * that clrays/integrand.py builds per frame (DESIGN §4 "integrand"). The tables hold
 * G = sinβ·I(β, γ) (smooth as β → 0); the 1/sinβ factor is applied here exactly.
 *
 *   table:    tables = F[channel][n_beta][n_gamma], F(β, γ) = ∫0^γ G dγ'  (bilinear)
 *   svd:      tables = B[channel][rank][n_beta] then P[channel][rank][n_gamma],
 *             G ≈ Σ B_i(β)·Γ_i(γ), P_i(γ) = ∫0^γ Γ_i                       (linear)
 *   analytic: closed forms from constant0/constant1 (directional light; σt = 0). */
#ifndef CLRAYS_INTEGRAND_H
#define CLRAYS_INTEGRAND_H
#include "lighting.h"

/* Linear interpolation position on a sample grid: index i and weight t, clamped. */
inline int grid_position(float coordinate, int count, float* t)
{
    float c = clamp(coordinate, 0.0f, (float)(count - 1));
    int i = min((int)c, count - 2);
    *t = c - (float)i;
    return i;
}

inline float table_prefix(global const float* tables, int channel, int n_beta, int n_gamma,
                          int row, float row_t, float column)
{
    float column_t;
    int col = grid_position(column, n_gamma, &column_t);
    global const float* a = tables + ((size_t)channel * n_beta + row) * n_gamma + col;
    global const float* b = a + n_gamma;
    float top = mix(a[0], a[1], column_t), bottom = mix(b[0], b[1], column_t);
    return mix(top, bottom, row_t);
}

inline float svd_segment(global const integrand_t* in, global const float* tables, int channel,
                         int row, float row_t, float column0, float column1)
{
    global const float* basis = tables + (size_t)channel * in->rank * in->n_beta;
    global const float* prefix = tables + (size_t)3 * in->rank * in->n_beta + (size_t)channel * in->rank * in->n_gamma;
    float t0, t1;
    int c0 = grid_position(column0, in->n_gamma, &t0), c1 = grid_position(column1, in->n_gamma, &t1);
    float sum = 0.0f;
    for (int i = 0; i < in->rank; ++i) {
        global const float* b = basis + i * in->n_beta + row;
        global const float* p = prefix + i * in->n_gamma;
        sum += mix(b[0], b[1], row_t) * (mix(p[c1], p[c1 + 1], t1) - mix(p[c0], p[c0 + 1], t0));
    }
    return sum;
}

inline float3 segment_radiance(global const integrand_t* in, global const float* tables,
                               global const frame_t* frame, float beta, float gamma0, float gamma1)
{
    float sin_beta = sin(beta);
    if (in->mode == INTEGRAND_ANALYTIC) {
        if (in->light_type == LIGHT_DIRECTIONAL) {
            /* σs·E·ρ(cos β)·(e^{-σt s0} - e^{-σt s1})/σt with s = γ/sin β (§3). */
            float3 sigma_t = in->constant1.xyz;
            float s0 = gamma0 / sin_beta, s1 = gamma1 / sin_beta;
            float3 span = (float3)(s1 - s0);
            float3 decay = sigma_t * span;
            /* (1 - e^{-x})/x → 1 as x → 0: keep the σt = 0 limit exact. */
            float3 factor = select(-expm1(-decay) / decay, (float3)(1.0f), isless(fabs(decay), (float3)(1e-6f)));
            return in->constant0.xyz * phase_function(frame, cos(beta)) * exp(-sigma_t * s0) * span * factor;
        }
        /* σt = 0, isotropic point light: σs·I/(4π·d_el·sin β)·(γ1 - γ0). */
        return in->constant0.xyz * ((gamma1 - gamma0) / sin_beta);
    }
    float row_t;
    int row = grid_position((beta - in->beta_min) * in->beta_scale, in->n_beta, &row_t);
    float column0 = gamma0 * in->gamma_scale, column1 = gamma1 * in->gamma_scale;
    float3 out;
    if (in->mode == INTEGRAND_TABLE) {
        out.x = table_prefix(tables, 0, in->n_beta, in->n_gamma, row, row_t, column1)
              - table_prefix(tables, 0, in->n_beta, in->n_gamma, row, row_t, column0);
        out.y = table_prefix(tables, 1, in->n_beta, in->n_gamma, row, row_t, column1)
              - table_prefix(tables, 1, in->n_beta, in->n_gamma, row, row_t, column0);
        out.z = table_prefix(tables, 2, in->n_beta, in->n_gamma, row, row_t, column1)
              - table_prefix(tables, 2, in->n_beta, in->n_gamma, row, row_t, column0);
    } else {
        out = (float3)(svd_segment(in, tables, 0, row, row_t, column0, column1),
                       svd_segment(in, tables, 1, row, row_t, column0, column1),
                       svd_segment(in, tables, 2, row, row_t, column0, column1));
    }
    return fmax(out, (float3)(0.0f)) / sin_beta;
}

#endif
