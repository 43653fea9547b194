/* spot_wedge.h — a spot light's unshadowed weight of a camera ray, from the wedge its cone
 * cuts in the ray's half-plane (docs/design.md §4.5, "A spot light's weight by its wedge").
 *
 * The unshadowed weight of a ray up to its end is what it would gather if nothing cast a
 * shadow, without the medium's attenuation and phase, and without the factor 1/sin β that
 * `radiance_scale` (sampling.cl) takes out of the radiance exactly: the γ it sweeps inside
 * the cone, divided by d_el. It breaks where the in-scattering breaks: at the ray's end (an
 * edge) and at the cone. The sampling kernels compute it for a spot light only: a point or
 * directional light's weights differ where the distances do, which they compare already.
 *
 * The cone's apex is the light, which lies in every half-plane through the eye and the
 * light. In such a half-plane, with side s (unit, normal to the axis a from the eye to the
 * light), the light's ray at angle γ from the ray back to the eye, turned towards s, lies
 * inside the cone where cos γ·x + sin γ·y ≥ c: (x, y) = (-a·k, s·k) is the cone's axis k seen
 * in the half-plane and c its cos_cone. Those are the γ within δ of φ = atan2(y, x), with
 * cos δ = c/r and r = |(x, y)|: one wedge, empty (δ = 0) where r < c. */
#ifndef CLRAYS_SPOT_WEDGE_H
#define CLRAYS_SPOT_WEDGE_H

#include "common.h"
#include "lanes.h"

/* The wedge (φ - δ, φ + δ) of the cone axis (x, y) in a half-plane and cos_cone c; x, y and
 * c scaled by one positive factor give the same wedge. sin δ from r² - c² (0 where r < |c|:
 * δ = 0, or π for a cone wider than a half-turn's c < 0, which the loader's 90° at most
 * leaves only as rounding). */
ALWAYS_INLINE float2 lit_wedge(float x, float y, float c)
{
    float phi = atan2_approx(y, x), delta = atan2_approx(inline_sqrt(inline_fmax(x * x + y * y - c * c, 0.0f)), c);
    return (float2)(phi - delta, phi + delta);
}

/* lit_wedge on each lane. */
ALWAYS_INLINE void lit_wedge_lanes(float_lanes x, float_lanes y, float_lanes c, float_lanes* lo, float_lanes* hi)
{
    float_lanes phi = atan2_approx_lanes(y, x);
    float_lanes delta = atan2_approx_lanes(sqrt_lanes(fmax_lanes(x * x + y * y - c * c, (float_lanes)(0.0f))), c);
    *lo = phi - delta;
    *hi = phi + delta;
}

/* The wedge of a slice's half-plane, side s: every line sample of the slice lies in it. */
ALWAYS_INLINE float2 slice_wedge(global const epipolar_t* ep, global const light_t* light, float3 side)
{
    float3 k = light->direction.xyz;
    return lit_wedge(-inline_dot(ep->axis.xyz, k), inline_dot(side, k), light->cos_cone);
}

/* The weight of each lane's ray (cos β, sin β with the axis) up to distance, its half-plane's
 * wedge [lo, hi]: the γ of [0, γ_end] inside the wedge or the wedge a turn later, over
 * d_el. A wedge has φ in (-π, π] and is at most a half-turn wide (up to rounding), so no
 * other turn of it meets [0, π). Where the ray misses the cone it is 0 exactly. */
ALWAYS_INLINE float_lanes weight_in_wedge_lanes(global const epipolar_t* ep, float_lanes lo, float_lanes hi,
                                                float_lanes cos_beta, float_lanes sin_beta, float_lanes distance)
{
    float_lanes gamma_end = atan2_approx_lanes(distance * sin_beta, ep->d_el - distance * cos_beta);
    float_lanes zero = 0.0f;
    float_lanes first = fmin_lanes(gamma_end, hi) - fmax_lanes(lo, zero);
    float_lanes second = fmin_lanes(gamma_end, hi + 2.0f * M_PI_F) - fmax_lanes(lo + 2.0f * M_PI_F, zero);
    return (fmax_lanes(first, zero) + fmax_lanes(second, zero)) / ep->d_el;
}

/* The weight of each lane's ray d (unit; cos β = d·a, sin β = |d × a|) up to distance, in
 * its own half-plane, whose side is (d - cos β·a)/sin β: x, y and c are taken times sin β,
 * which needs no division and gives the same wedge. */
ALWAYS_INLINE float_lanes spot_weight_lanes(global const epipolar_t* ep, global const light_t* light,
                                            float_lanes dx, float_lanes dy, float_lanes dz, float_lanes cos_beta,
                                            float_lanes sin_beta, float_lanes distance)
{
    float3 k = light->direction.xyz;
    float axis_along = inline_dot(ep->axis.xyz, k);
    float_lanes lo, hi;
    lit_wedge_lanes(-axis_along * sin_beta, dot_lanes(dx, dy, dz, k.x, k.y, k.z) - cos_beta * axis_along,
                    light->cos_cone * sin_beta, &lo, &hi);
    return weight_in_wedge_lanes(ep, lo, hi, cos_beta, sin_beta, distance);
}

#endif
