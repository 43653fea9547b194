/* atan2_approx.h — a fast arc tangent for the kernels whose cost PoCL's atan2 dominates. */
#ifndef CLRAYS_ATAN2_APPROX_H
#define CLRAYS_ATAN2_APPROX_H

#include "inline_math.h"

/* atan2 within 3 ulp (a minimax polynomial after reducing to [0, tan π/8]): PoCL's
 * atan2 costs as much as the rest of a camera sample's interpolation (sampling.cl) or
 * of a rectified texel (rectify.cl). rectify's S, which the walk compares with a β from
 * atan2, moves by at most 3 ulp (≈ 1e-6 rad; tests/stages/test_rectify.py holds it to the
 * float64 angle within BETA_TOLERANCE). */
/* The reduction (t above tan π/8 becomes (t − 1)/(t + 1), and π/4 is added back) and the
 * minimax polynomial on the reduced r (z = r²), shared with atan2_approx_lanes (lanes.h). */
#define ATAN_REDUCE_ABOVE 0.41421356f
#define ATAN_OF_REDUCED(r, z) \
    ((((8.05374449538e-2f * (z) - 1.38776856032e-1f) * (z) + 1.99777106478e-1f) * (z) - 3.33329491539e-1f) * (z) * (r) \
     + (r))

ALWAYS_INLINE float atan2_approx(float y, float x)
{
    float ax = inline_fabs(x), ay = inline_fabs(y);
    float big = inline_fmax(ax, ay), small = inline_fmin(ax, ay);
    float t = big > 0.0f ? small / big : 0.0f;
    int reduced = t > ATAN_REDUCE_ABOVE;
    float r = reduced ? (t - 1.0f) / (t + 1.0f) : t;
    float z = r * r;
    float a = ATAN_OF_REDUCED(r, z);
    a = reduced ? a + M_PI_4_F : a;
    a = ay > ax ? M_PI_2_F - a : a;
    a = x < 0.0f ? M_PI_F - a : a;
    return inline_copysign(a, y);
}

#endif
