"""Float64 numpy references of the filtered shadow tests of `render.shadow_filter`
(docs/design.md §9): the moment vector of a depth, and the visibility that VSM and the
two four-moment reconstructions (Hamburger, Hausdorff) take from filtered moments.

Depths here are normalised: 0 at the light's near end, 1 at its far end (the device
stage maps each light's depths so). Every function takes arrays and broadcasts.

The moment reconstructions return the *visibility* 1 − G, G being the sharpest lower
bound of the shadow intensity P(depth < z) over all distributions with those moments:
so they never darken a receiver more than the true distribution does, and their errors
are light leaks (docs/design.md §9).
"""
from __future__ import annotations

import numpy as np

#: The moments are pulled this far towards those of (0.5, 0.5, 0.5, 0.5) before a
#: reconstruction (docs/design.md §9, the moment bias): keeps the Hankel matrix
#: invertible where a filter saw a single depth.
MOMENT_BIAS_CENTRE = 0.5


def moment_vector(depth) -> np.ndarray:
    """(..., 4): (z, z², z³, z⁴) of normalised depths z."""
    z = np.asarray(depth, dtype=np.float64)
    return np.stack([z, z * z, z ** 3, z ** 4], axis=-1)


def vsm_visibility(moments, depth, min_variance: float) -> np.ndarray:
    """Chebyshev's one-sided bound from (z, z²) (the first two of `moments`): 1 where the
    receiver is nearer than the mean, else σ² / (σ² + (z − μ)²), σ² at least `min_variance`."""
    b = np.asarray(moments, dtype=np.float64)
    z = np.asarray(depth, dtype=np.float64)
    mean = b[..., 0]
    variance = np.maximum(b[..., 1] - mean * mean, min_variance)
    excess = z - mean
    return np.where(excess <= 0.0, 1.0, variance / (variance + excess * excess))


def _biased(moments, moment_bias: float) -> np.ndarray:
    b = np.asarray(moments, dtype=np.float64)
    return (1.0 - moment_bias) * b + moment_bias * MOMENT_BIAS_CENTRE


def _three_point_support(b: np.ndarray, z: np.ndarray):
    """The two other support points z1 ≤ z2 of the distribution with moments (1, b1..b4)
    that has a point at z: the roots of c0 + c1·x + c2·x² where B·c = (1, z, z²), B the
    Hankel matrix of (1, b1, b2 | b1, b2, b3 | b2, b3, b4), solved through its Cholesky
    factors (docs/design.md §9, steps 2–3)."""
    b1, b2, b3, b4 = (b[..., k] for k in range(4))
    d11 = b2 - b1 * b1  # B = L·D·Lᵀ with unit lower-triangular L
    l21 = (b3 - b1 * b2) / d11
    d22 = (b4 - b2 * b2) - l21 * l21 * d11
    # Forward: L·y = (1, z, z²), first column of L is (1, b1, b2).
    y1 = z - b1
    y2 = z * z - b2 - l21 * y1
    # Scale by D, then back-substitute Lᵀ·c = D⁻¹·y.
    c2 = y2 / d22
    c1 = y1 / d11 - l21 * c2
    c0 = 1.0 - b1 * c1 - b2 * c2
    half_p, q = c1 / (2.0 * c2), c0 / c2
    root = np.sqrt(np.maximum(half_p * half_p - q, 0.0))
    return -half_p - root, -half_p + root


def _lagrange_weight(b: np.ndarray, point, others) -> np.ndarray:
    """Weight at `point` of the distribution on {point} ∪ `others` with moments
    (1, b1, ...): E[ℓ(X)] for the Lagrange polynomial ℓ of `point` (1 there, 0 at the others)."""
    coefficients = np.ones_like(point)[..., None] * np.array([1.0])  # polynomial, lowest power first
    denominator = np.ones_like(point)
    for other in others:
        # multiply by (x − other)
        shifted = np.concatenate([np.zeros_like(coefficients[..., :1]), coefficients], axis=-1)
        scaled = np.concatenate([coefficients * -other[..., None], np.zeros_like(coefficients[..., :1])], axis=-1)
        coefficients = shifted + scaled
        denominator = denominator * (point - other)
    powers = np.concatenate([np.ones_like(b[..., :1]), b], axis=-1)[..., :coefficients.shape[-1]]
    return (coefficients * powers).sum(axis=-1) / denominator


def _three_point_shadow(b: np.ndarray, z: np.ndarray, z1: np.ndarray, z2: np.ndarray) -> np.ndarray:
    """Weight of the support points nearer than z in the distribution on {z, z1, z2}."""
    in_front_one = _lagrange_weight(b, z1, (z, z2))
    in_front_none = np.zeros_like(z)
    behind_both = 1.0 - _lagrange_weight(b, z, (z1, z2))
    return np.where(z <= z1, in_front_none, np.where(z <= z2, in_front_one, behind_both))


def msm_hamburger_visibility(moments, depth, moment_bias: float) -> np.ndarray:
    """Four moments on ℝ (Hamburger): 1 − the sharpest lower bound of P(depth < z)."""
    b = _biased(moments, moment_bias)
    z = np.asarray(depth, dtype=np.float64) * np.ones(b.shape[:-1])
    z1, z2 = _three_point_support(b, z)
    return 1.0 - np.clip(_three_point_shadow(b, z, z1, z2), 0.0, 1.0)


def msm_hausdorff_visibility(moments, depth, moment_bias: float) -> np.ndarray:
    """Four moments on [0, 1] (Hausdorff): as Hamburger where the three-point support
    lies in [0, 1]; otherwise the four-point support {0, z, z_free, 1}, z_free the point
    that makes its moments match (docs/design.md §9)."""
    b = _biased(moments, moment_bias)
    z = np.asarray(depth, dtype=np.float64) * np.ones(b.shape[:-1])
    z1, z2 = _three_point_support(b, z)
    three = _three_point_shadow(b, z, z1, z2)
    b1, b2, b3, b4 = (b[..., k] for k in range(4))
    # E[X (X − 1)(X − z)(X − z_free)] = 0, solved for z_free.
    with np.errstate(divide="ignore", invalid="ignore"):
        z_free = (b4 - b3 - z * (b3 - b2)) / (b3 - b2 - z * (b2 - b1))
        zero = np.zeros_like(z)
        one = np.ones_like(z)
        at_zero = _lagrange_weight(b, zero, (z, z_free, one))
        at_free = _lagrange_weight(b, z_free, (zero, z, one))
        four = at_zero + np.where(z_free < z, at_free, 0.0)
    shadow = np.where((z1 < 0.0) | (z2 > 1.0), four, three)
    return 1.0 - np.clip(shadow, 0.0, 1.0)


def box_blur(image: np.ndarray, radius: int) -> np.ndarray:
    """Mean over the (2·radius + 1)² texels around each texel of a (H, W, ...) array,
    edges clamped (repeated), as PCF reads a map."""
    padded = np.pad(np.asarray(image, dtype=np.float64), [(radius, radius), (radius, radius)]
                    + [(0, 0)] * (image.ndim - 2), mode="edge")
    height, width = image.shape[:2]
    total = np.zeros(image.shape, dtype=np.float64)
    for dy in range(2 * radius + 1):
        for dx in range(2 * radius + 1):
            total += padded[dy:dy + height, dx:dx + width]
    return total / (2 * radius + 1) ** 2
