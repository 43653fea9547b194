/* inline_math.h — OpenCL built-ins written out, for the kernels whose work-items PoCL should
 * run several at a time (docs/design.md §4.5, "Cost on PoCL").
 *
 * PoCL's CPU driver links its built-ins from a library built for a generic x86-64, and
 * LLVM does not inline a function across different target features: every dot, fmax or
 * floor stays a call, and a call in the work-item loop stops PoCL's loop vectorizer (the
 * loop runs one work-item at a time). These are the library's own operations in the
 * library's order, always inlined: the results are the same bit for bit, on the paths
 * each function states. FP_CONTRACT is off here so that no a·b + c becomes a fused one
 * the library does not do. */
#ifndef CLRAYS_INLINE_MATH_H
#define CLRAYS_INLINE_MATH_H

#pragma OPENCL FP_CONTRACT OFF

#define ALWAYS_INLINE inline __attribute__((always_inline))

ALWAYS_INLINE float inline_fabs(float x) { return as_float(as_uint(x) & 0x7fffffffu); }

ALWAYS_INLINE float inline_copysign(float x, float sign)
{
    return as_float((as_uint(x) & 0x7fffffffu) | (as_uint(sign) & 0x80000000u));
}

/* fmax/fmin: the other operand where one is NaN, as the built-ins. */
ALWAYS_INLINE float inline_fmax(float a, float b) { return (b != b || a > b) ? a : b; }
ALWAYS_INLINE float inline_fmin(float a, float b) { return (b != b || a < b) ? a : b; }
ALWAYS_INLINE float inline_clamp(float x, float lo, float hi) { return inline_fmin(inline_fmax(x, lo), hi); }
ALWAYS_INLINE float3 inline_clamp3(float3 v, float lo, float hi)
{
    return (float3)(inline_clamp(v.x, lo, hi), inline_clamp(v.y, lo, hi), inline_clamp(v.z, lo, hi));
}
ALWAYS_INLINE int inline_min(int a, int b) { return a > b ? b : a; }
ALWAYS_INLINE int inline_max(int a, int b) { return a < b ? b : a; }
ALWAYS_INLINE int inline_clamp_int(int x, int lo, int hi) { return inline_min(inline_max(x, lo), hi); }

/* floor as the library's (SLEEF's): exact, and x itself for |x| ≥ 2^23, ±inf and NaN. */
ALWAYS_INLINE float inline_floor(float x)
{
    float fraction = x - (float)(int)x;
    fraction = fraction < 0.0f ? fraction + 1.0f : fraction;
    float floored = inline_copysign(x - fraction, x);
    return inline_fabs(x) < 8388608.0f ? floored : x;
}

/* ceil as -floor(-x): exact, -0 for x in (-1, 0], x itself for |x| ≥ 2^23, ±inf and NaN. */
ALWAYS_INLINE float inline_ceil(float x) { return -inline_floor(-x); }

ALWAYS_INLINE float inline_dot(float3 a, float3 b)
{
    float x = a.x * b.x, y = a.y * b.y, z = a.z * b.z;
    return z + (x + y);
}

ALWAYS_INLINE float3 inline_cross(float3 a, float3 b)
{
    return (float3)(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}

ALWAYS_INLINE float3 inline_mix3(float3 a, float3 b, float t) { return (b - a) * t + a; }
ALWAYS_INLINE float2 inline_mix2(float2 a, float2 b, float t) { return (b - a) * t + a; }
ALWAYS_INLINE float inline_mix(float a, float b, float t) { return (b - a) * t + a; }

/* sqrt is exact (correctly rounded) in the library too. */
ALWAYS_INLINE float inline_sqrt(float x) { return __builtin_sqrtf(x); }

/* length of a vector whose squared length is a normal float (≥ 2^-126, finite), as the
 * library's; the library rescales shorter ones, which here are only cross products of
 * two unit vectors within 1e-19 of parallel: those get 0, where the library gets their
 * length below 1e-19, and every caller clamps sin β to SIN_BETA_MIN (1e-9) anyway. */
ALWAYS_INLINE float inline_length(float3 v)
{
    float squared = inline_dot(v, v);
    return squared >= 1.17549435e-38f ? inline_sqrt(squared) : 0.0f;
}

/* length(v) as the built-in, bit for bit, for any v: inline_length where |v|² is a normal
 * float, the library's call (which rescales) for the rare rest, shorter than 1e-19 or longer
 * than 1e19. */
ALWAYS_INLINE float exact_length(float3 v)
{
    float squared = inline_dot(v, v);
    return squared >= 1.17549435e-38f && squared <= 3.40282347e38f ? inline_sqrt(squared) : length(v);
}

/* normalize of a vector whose squared length is a normal float: v · (1 / |v|), the
 * library's path for it (ray directions: their squared length is near 1 or above). */
ALWAYS_INLINE float3 inline_normalize(float3 v) { return v * (1.0f / inline_sqrt(inline_dot(v, v))); }

/* The same on float3's components, for kernels written in scalars: LLVM's loop vectorizer
 * takes no vector-typed instruction, so a float3 in the work-item loop stops it as a call
 * does. */
ALWAYS_INLINE float inline_dot_xyz(float ax, float ay, float az, float bx, float by, float bz)
{
    float x = ax * bx, y = ay * by, z = az * bz;
    return z + (x + y);
}

/* |a × b| of two vectors, as length(cross(a, b)) on inline_length's path. */
ALWAYS_INLINE float inline_cross_length_xyz(float ax, float ay, float az, float bx, float by, float bz)
{
    float cx = ay * bz - az * by, cy = az * bx - ax * bz, cz = ax * by - ay * bx;
    float squared = inline_dot_xyz(cx, cy, cz, cx, cy, cz);
    return squared >= 1.17549435e-38f ? inline_sqrt(squared) : 0.0f;
}

/* 1 / |v|, the factor of inline_normalize. */
ALWAYS_INLINE float inline_inverse_length_xyz(float x, float y, float z)
{
    return 1.0f / inline_sqrt(inline_dot_xyz(x, y, z, x, y, z));
}

ALWAYS_INLINE float inline_product(float a, float b) { return a * b; }

/* Back to OpenCL's default for the code that includes this. */
#pragma OPENCL FP_CONTRACT ON

#endif
