/* spot_wedge.h — a spot light's unshadowed weight of camera rays, 8 at a time (lanes.h),
 * from the wedge its cone cuts in each ray's half-plane (lighting.h's lit_wedge;
 * docs/design.md §4.5, "A spot light's cone as a wedge").
 *
 * The unshadowed weight of a ray up to its end is what it would gather if nothing cast a
 * shadow, without the medium's attenuation and phase, and without the factor 1/sin β that
 * `radiance_scale` (sampling.cl) takes out of the radiance exactly: the γ it sweeps inside
 * the cone, divided by d_el. It breaks where the in-scattering breaks: at the ray's end (an
 * edge) and at the cone. The sampling kernels compute it for a spot light only: a point or
 * directional light's weights differ where the distances do, which they compare already. */
#ifndef CLRAYS_SPOT_WEDGE_H
#define CLRAYS_SPOT_WEDGE_H

#include "common.h"
#include "lighting.h"
#include "lanes.h"

/* lit_wedge on each lane. */
ALWAYS_INLINE void lit_wedge_lanes(float_lanes x, float_lanes y, float_lanes c, float_lanes* lo, float_lanes* hi)
{
    c = fmax_lanes(c, (float_lanes)(0.0f));
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
 * wedge [lo, hi]: the part of [0, γ_end] within it (lit_sweep on each lane), over d_el.
 * Where the ray misses the cone it is 0 exactly. */
ALWAYS_INLINE float_lanes weight_in_wedge_lanes(global const epipolar_t* ep, float_lanes lo, float_lanes hi,
                                                float_lanes cos_beta, float_lanes sin_beta, float_lanes distance)
{
    float_lanes gamma_end = atan2_approx_lanes(distance * sin_beta, ep->d_el - distance * cos_beta);
    float_lanes zero = 0.0f;
    int_lanes next_turn = !(fmin_lanes(gamma_end, hi) > fmax_lanes(lo, zero));
    lo = next_turn ? lo + 2.0f * M_PI_F : lo;
    hi = next_turn ? hi + 2.0f * M_PI_F : hi;
    return fmax_lanes(fmin_lanes(gamma_end, hi) - fmax_lanes(lo, zero), zero) / ep->d_el;
}

/* The weight of each lane's ray d (unit; cos β = d·a, sin β = |d × a|) up to distance, in
 * its own half-plane: ray_wedge (lighting.h) on each lane. */
ALWAYS_INLINE float_lanes spot_weight_lanes(global const epipolar_t* ep, global const light_t* light,
                                            float_lanes dx, float_lanes dy, float_lanes dz, float_lanes cos_beta,
                                            float_lanes sin_beta, float_lanes distance)
{
    float3 k = light->direction.xyz;
    float axis_along = inline_dot(ep->axis.xyz, k);
    float3 k_normal = k - axis_along * ep->axis.xyz;
    int_lanes own_side = sin_beta > WEDGE_SIN_BETA_MIN; /* else on the axis: u's half-plane */
    float_lanes scale = own_side ? sin_beta : 1.0f;
    float_lanes y = own_side ? dot_lanes(dx, dy, dz, k_normal.x, k_normal.y, k_normal.z)
                             : (float_lanes)(inline_dot(ep->u.xyz, k_normal));
    float_lanes lo, hi;
    lit_wedge_lanes(-axis_along * scale, y, light->cos_cone * scale, &lo, &hi);
    return weight_in_wedge_lanes(ep, lo, hi, cos_beta, sin_beta, distance);
}

#endif
