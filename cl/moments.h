/* moments.h — reconstructions of a lit fraction from the moments b = (z, z², z³, z⁴) of a
 * depth distribution (docs/design.md §9): VSM's Chebyshev bound and the four-moment bounds
 * on ℝ (Hamburger) and on [0, 1] (Hausdorff). Shared by shadow_filter.cl (surface shadows)
 * and volume_moments.cl (the `moments` method). */
#ifndef CLRAYS_MOMENTS_H
#define CLRAYS_MOMENTS_H

/* Chebyshev's one-sided bound (VSM): the lit fraction is at most σ² / (σ² + (z − μ)²). */
inline float vsm_visibility(float4 b, float z, float min_variance)
{
    float variance = fmax(b.y - b.x * b.x, min_variance);
    float excess = z - b.x;
    return excess <= 0.0f ? 1.0f : variance / (variance + excess * excess);
}

/* Weight at z of the three-point distribution on {z, other1, other2} with moments (1, b.x, b.y):
 * E[ℓ(X)], ℓ the Lagrange polynomial that is 1 at z and 0 at the others. */
inline float three_point_weight(float4 b, float z, float other1, float other2)
{
    return (b.y - (other1 + other2) * b.x + other1 * other2) / ((z - other1) * (z - other2));
}

/* The other two support points z1 ≤ z2 of the distribution with moments (1, b) that has a
 * point at z: the roots of c0 + c1·x + c2·x², B·c = (1, z, z²), B the Hankel matrix of
 * (1, b1, b2 | b1, b2, b3 | b2, b3, b4) through its L·D·Lᵀ factors (docs/design.md §9). */
inline void three_point_support(float4 b, float z, float* z1, float* z2)
{
    float d11 = b.y - b.x * b.x;
    float l21 = (b.z - b.x * b.y) / d11;
    float d22 = (b.w - b.y * b.y) - l21 * l21 * d11;
    float y1 = z - b.x;
    float y2 = z * z - b.y - l21 * y1;
    float c2 = y2 / d22;
    float c1 = y1 / d11 - l21 * c2;
    float c0 = 1.0f - b.x * c1 - b.y * c2;
    float half_p = c1 / (2.0f * c2), q = c0 / c2;
    float root = sqrt(fmax(half_p * half_p - q, 0.0f));
    *z1 = -half_p - root;
    *z2 = -half_p + root;
}

/* Shadow of the three-point support: the weight of its points nearer than z. */
inline float three_point_shadow(float4 b, float z, float z1, float z2)
{
    if (z <= z1) return 0.0f;
    if (z <= z2) return three_point_weight(b, z1, z, z2);
    return 1.0f - three_point_weight(b, z, z1, z2);
}

/* The moments pulled towards those of depth 0.5 (the moment bias, docs/design.md §9). */
inline float4 biased_moments(float4 b, float moment_bias)
{
    return mix(b, (float4)(0.5f), moment_bias);
}

/* 4MSM on ℝ: 1 − the sharpest lower bound of the shadow P(depth < z). */
inline float msm_hamburger_visibility(float4 moments, float z, float moment_bias)
{
    float4 b = biased_moments(moments, moment_bias);
    float z1, z2;
    three_point_support(b, z, &z1, &z2);
    return 1.0f - clamp(three_point_shadow(b, z, z1, z2), 0.0f, 1.0f);
}

/* 4MSM on [0, 1]: as on ℝ while the support stays in [0, 1], else the four-point support
 * {0, z, z_free, 1} whose moments match (E[X(X − 1)(X − z)(X − z_free)] = 0). */
inline float msm_hausdorff_visibility(float4 moments, float z, float moment_bias)
{
    float4 b = biased_moments(moments, moment_bias);
    float z1, z2;
    three_point_support(b, z, &z1, &z2);
    float shadow;
    if (z1 >= 0.0f && z2 <= 1.0f) {
        shadow = three_point_shadow(b, z, z1, z2);
    } else {
        float z_free = (b.w - b.z - z * (b.z - b.y)) / (b.z - b.y - z * (b.y - b.x));
        /* Weights at 0 and at z_free of the distribution on {0, z, z_free, 1}: E[ℓ(X)]. */
        float at_zero = (b.z - (1.0f + z + z_free) * b.y + (z + z_free + z * z_free) * b.x - z * z_free)
                        / (-z * z_free);
        float at_free = (b.z - (1.0f + z) * b.y + z * b.x) / (z_free * (z_free - 1.0f) * (z_free - z));
        shadow = at_zero + (z_free < z ? at_free : 0.0f);
    }
    return 1.0f - clamp(shadow, 0.0f, 1.0f);
}

#endif
