/* visible_ranges — the β and γ ranges of the visible rays, from the bounds rectify_bounds
 * reduces (cl/rectify.cl): read by rectify_ranges and integrand_rows on the device, so the
 * host never waits for them (docs/design.md §4.2). Reads bounds[3] (pseudo-angles).
 *
 * In double where the device has it: the host computed these in float64 before they
 * moved here, and the float32 values the kernels store from them are the same bits. */
#ifndef VISIBLE_RANGES_H
#define VISIBLE_RANGES_H

#ifdef cl_khr_fp64
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double wide_t;
#define WIDE_PI M_PI
#else
typedef float wide_t;
#define WIDE_PI M_PI_F
#endif

#pragma OPENCL FP_CONTRACT OFF /* the host's float64 arithmetic, operation for operation */

/* The angle θ ∈ [0, π] of rectify.cl's pseudo_angle_lanes q: 2·atan(q) up to q = 1,
 * π - 2·atan(2 - q) above; +inf (no camera sample) stays +inf. */
inline wide_t angle_of_pseudo(float q)
{
    wide_t w = (wide_t)q;
    if (isinf(q)) return w;
    return w <= 1.0 ? 2.0 * atan(w) : WIDE_PI - 2.0 * atan(2.0 - w);
}

/* β_min, β_max (rad) and γ_max (rad, or length for a directional light) of the visible
 * rays. float32(π) is 9e-8 above π: a ray pointing straight away from the light (the
 * anti-epipole on a pixel centre) would put β past the integrand's [0, π]. γ_max ≤ 0 (no
 * visible ray has extent in γ) is left to the caller. */
inline void visible_ranges(global const uint* bounds, int directional, wide_t* beta_min, wide_t* beta_max,
                           wide_t* gamma_max)
{
    *beta_min = fmin(angle_of_pseudo(as_float(bounds[0])), WIDE_PI);
    *beta_max = fmin(angle_of_pseudo(as_float(bounds[1])), WIDE_PI);
    float gamma = as_float(bounds[2]);
    *gamma_max = directional ? (wide_t)gamma : angle_of_pseudo(gamma);
}

#pragma OPENCL FP_CONTRACT ON

#endif
