/* integrand_build — the `table` integrand's prefix rows F(β_j, x_k), built on the device in
 * float32 (docs/design.md §4.4; docs/integrand.md has the integrand and its error).
 *
 * The table is float[3][n_beta][n_gamma]: F of each channel at β row j and column
 * x_k = k/(n_gamma - 1), F(·, 0) = 0; for a grey medium (`grey`: every channel the same
 * σt) float[1][n_beta][n_gamma], the host passing an amplitude of 1 (integrand.h
 * multiplies each channel's by its own). integrand_cells integrates K over each cell with
 * QUAD_NODES-point Gauss–Legendre (the host builder's rule), LANES cells per work-item;
 * integrand_prefix replaces a point row's last cell by panels halving towards the ray's point
 * at infinity and sums the cells in compensated (Kahan) float32.
 *
 * Rows are float4 (δ = π - β, β, ρ(cos β), 0), which integrand_rows computes in double
 * (the host's float64 rule, clrays/stages/integrand.py table_rows) from the visible β range
 * that rectify reduced: a point row's K needs sin((1+x)δ/2), which it takes as
 * sin(β + (1-x)δ/2) past π/2, so β ≈ 0 keeps its relative precision; a directional row's
 * phase does not depend on x. K is written in u = 1 - x, exact near x = 1, where the far
 * half-ray is squeezed. */
#include "common.h"
#include "lanes.h"
#include "visible_ranges.h"

#if QUAD_NODES != 3
#error "integrand_build.cl spells out 3-point Gauss-Legendre"
#endif
#define GL_NODE 0.7745966692414834f  /* sqrt(3/5): nodes -GL_NODE, 0, +GL_NODE */
#define GL_OUTER 0.5555555555555556f /* 5/9 */
#define GL_INNER 0.8888888888888888f /* 8/9 */
/* Panels of a point row's last cell: the last h·2^-LAST_CELL_PANELS of the ray is left out (K is bounded). */
#define LAST_CELL_PANELS 40

typedef struct {
    float_lanes r, g, b;
} rgb_lanes;

/* K of a point (or spot) light's row at u = 1 - x, per channel: amplitude·ρ(cos(β+γ))·
 * exp(-σt·d_el·(sinβ + sinγ)/sin(β+γ)) / d_el with the half-angle forms of
 * clrays/stages/integrand.py _row_integrand; a grey medium's one plane (`grey`) takes the
 * first channel's alone. */
ALWAYS_INLINE rgb_lanes point_integrand(float_lanes u, float4 row, float4 amplitude, float4 sigma_t, float d_el, float g,
                                        int grey)
{
    float delta = row.x, beta = row.y;
    float_lanes far_angle = u * (0.5f * delta);
    float_lanes near_angle = (2.0f - u) * (0.5f * delta);
    near_angle = near_angle <= M_PI_2_F ? near_angle : beta + far_angle;
    float_lanes far = sin(far_angle);
    float_lanes ratio = sin(near_angle) / far;
    float_lanes d = (1.0f + g) * (1.0f + g) - 4.0f * g * (far * far);
    float_lanes falloff = d * sqrt_lanes(d);
    float scale = (1.0f - g * g) / (4.0f * M_PI_F * d_el);
    float_lanes red = exp(-(sigma_t.x * d_el) * ratio) / falloff * scale;
    rgb_lanes k;
    if (grey) {
        k.r = k.g = k.b = red * amplitude.x; /* g and b not stored */
    } else {
        k.r = red * amplitude.x;
        k.g = exp(-(sigma_t.y * d_el) * ratio) / falloff * (scale * amplitude.y);
        k.b = exp(-(sigma_t.z * d_el) * ratio) / falloff * (scale * amplitude.z);
    }
    return k;
}

/* K of a directional row at x: amplitude·ρ(cos β)·exp(-σt·x·s_end); a grey medium's one
 * plane (`grey`) takes the first channel's alone. */
ALWAYS_INLINE rgb_lanes directional_integrand(float_lanes x, float4 row, float4 amplitude, float4 sigma_t, float4 s_end,
                                              int grey)
{
    rgb_lanes k;
    k.r = amplitude.x * row.z * exp(-sigma_t.x * (x * s_end.x));
    if (grey) {
        k.g = k.b = k.r; /* not stored */
        return k;
    }
    k.g = amplitude.y * row.z * exp(-sigma_t.y * (x * s_end.y));
    k.b = amplitude.z * row.z * exp(-sigma_t.z * (x * s_end.z));
    return k;
}

#pragma OPENCL FP_CONTRACT OFF /* the host's float64 rule, operation for operation */
/* One work-item per β row: the row's nodes β_j = β_min + (β_max - β_min)·sin²(π/2·t_j),
 * t_j = j/(n_beta - 1) as numpy's linspace, over the visible rays' β range (the bounds
 * rectify_bounds reduced), and the float4 (δ, β, ρ(cos β), 0) integrand_cells reads; work-item
 * 0 writes the range into the integrand's params, where integrand.h reads it, and whether no
 * visible ray has extent in γ (walk.h's spans are then empty). `g`: the
 * Henyey–Greenstein g, one wide_t (double where the device has it). */
kernel void integrand_rows(global const uint* bounds, int directional, global const wide_t* g, int n_beta,
                           global float4* rows, global integrand_t* params)
{
    int j = get_global_id(0);
    wide_t beta_min, beta_max, gamma_max;
    visible_ranges(bounds, directional, &beta_min, &beta_max, &gamma_max);
    if (j == 0) {
        params->beta_min = (float)beta_min;
        params->beta_max = (float)beta_max;
        params->no_extent = !(gamma_max > 0.0);
    }
    if (!rows || j >= n_beta) return;
    wide_t t = j == n_beta - 1 ? 1.0 : (wide_t)j * (1.0 / (wide_t)(n_beta - 1));
    wide_t s = sin((WIDE_PI * 0.5) * t);
    wide_t beta = beta_min + (beta_max - beta_min) * (s * s);
    wide_t c = clamp(cos(beta), (wide_t)-1.0, (wide_t)1.0);
    wide_t gg = *g;
    wide_t d = (1.0 + gg * gg) - (2.0 * gg) * c;
    wide_t rho = (1.0 - gg * gg) / ((4.0 * WIDE_PI) * (d * sqrt(d)));
    rows[j] = (float4)((float)fmax(WIDE_PI - beta, (wide_t)1e-20), (float)beta, (float)rho, 0.0f);
}
#pragma OPENCL FP_CONTRACT ON

/* One work-item per LANES cells of a row: ∫ K over cell k, written at column k + 1. */
kernel void integrand_cells(global const float4* rows, int point, float4 amplitude, float4 sigma_t, float4 s_end,
                            float d_el, float g, int grey, int n_gamma, global float* table)
{
    int first = get_global_id(0) * LANES, j = get_global_id(1), cells = n_gamma - 1;
    if (first >= cells) return;
    float4 row = rows[j];
    float h = 1.0f / (float)cells;
    int_lanes k = min_lanes(first + (int_lanes)(0, 1, 2, 3, 4, 5, 6, 7), (int_lanes)(cells - 1));
    float_lanes centre = float_of_lanes(k) + 0.5f;
    const float nodes[3] = {-GL_NODE, 0.0f, GL_NODE}, weights[3] = {GL_OUTER, GL_INNER, GL_OUTER};
    rgb_lanes sum = {0.0f, 0.0f, 0.0f};
    for (int n = 0; n < 3; ++n) {
        rgb_lanes value;
        if (point) {
            float_lanes u = ((float)cells - centre - 0.5f * nodes[n]) * h;
            value = point_integrand(u, row, amplitude, sigma_t, d_el, g, grey);
        } else {
            value = directional_integrand((centre + 0.5f * nodes[n]) * h, row, amplitude, sigma_t, s_end, grey);
        }
        sum.r += value.r * weights[n], sum.g += value.g * weights[n], sum.b += value.b * weights[n];
    }
    size_t plane = (size_t)get_global_size(1) * n_gamma;
    global float* out = table + (size_t)j * n_gamma + 1;
    for (int lane = 0; lane < LANES && first + lane < cells; ++lane) {
        out[first + lane] = sum.r[lane] * (0.5f * h);
        if (grey) continue; /* one plane */
        out[plane + first + lane] = sum.g[lane] * (0.5f * h);
        out[2 * plane + first + lane] = sum.b[lane] * (0.5f * h);
    }
}

/* One work-item per row: a point row's last cell on LAST_CELL_PANELS panels halving towards
 * x = 1 (K falls to 0 there in a layer ~σt·d_el·β wide, narrower than a cell for β → 0),
 * then each channel's running sum over the cells, compensated. */
kernel void integrand_prefix(global const float4* rows, int point, float4 amplitude, float4 sigma_t, float d_el,
                             float g, int grey, int n_gamma, global float* table)
{
    int j = get_global_id(0), cells = n_gamma - 1, channels = grey ? 1 : 3;
    size_t plane = (size_t)get_global_size(0) * n_gamma;
    global float* row_table = table + (size_t)j * n_gamma;
    if (point) {
        float4 row = rows[j];
        float h = 1.0f / (float)cells;
        const float nodes[3] = {-GL_NODE, 0.0f, GL_NODE}, weights[3] = {GL_OUTER, GL_INNER, GL_OUTER};
        float last[3] = {0.0f, 0.0f, 0.0f};
        for (int p0 = 0; p0 < LAST_CELL_PANELS; p0 += LANES) {
            /* panel p spans u ∈ [h·2^-(p+1), h·2^-p]: mid 0.75·h·2^-p, half-width 0.25·h·2^-p */
            int_lanes p = p0 + (int_lanes)(0, 1, 2, 3, 4, 5, 6, 7);
            float_lanes width = as_float8((127 - p) << 23) * h; /* h·2^-p */
            float_lanes half_width = 0.25f * width, mid = 0.75f * width;
            rgb_lanes sum = {0.0f, 0.0f, 0.0f};
            for (int n = 0; n < 3; ++n) {
                rgb_lanes value = point_integrand(mid - half_width * nodes[n], row, amplitude, sigma_t, d_el, g, grey);
                sum.r += value.r * weights[n], sum.g += value.g * weights[n], sum.b += value.b * weights[n];
            }
            for (int lane = 0; lane < LANES && p0 + lane < LAST_CELL_PANELS; ++lane) {
                last[0] += sum.r[lane] * half_width[lane], last[1] += sum.g[lane] * half_width[lane], last[2] += sum.b[lane] * half_width[lane];
            }
        }
        for (int c = 0; c < channels; ++c) row_table[c * plane + cells] = last[c];
    }
    for (int c = 0; c < channels; ++c) {
        global float* f = row_table + c * plane;
        float total = 0.0f, carry = 0.0f;
        f[0] = 0.0f;
        for (int k = 1; k <= cells; ++k) {
            float term = f[k] - carry;
            float next = total + term;
            carry = (next - total) - term;
            total = next;
            f[k] = total;
        }
    }
}
