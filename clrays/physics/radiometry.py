"""Radiometry, in numpy float64 (vectorised): what the stages set up for the device (the lamp,
the effective far, light positions and cones) and the references integrate.

Every method in clrays computes the same single-scattering model (docs/design.md §1), per
RGB channel, with σt = σs + σa:

    L = L_surf·e^{-σt·D} + ∫_0^D e^{-σt·s} · σs · ρ(cosθ) · V(x_s) · Lin(x_s) ds

    point / spot light (intensity I):  Lin(x) = I·e^{-σt·d} / d²,  d = |x - l|
                                       (a spot light is 0 outside its hard-edged cone)
    directional light (irradiance E):  Lin(x) = E

θ is the angle between the light's propagation direction at x (x - l normalised, or the
directional light's `direction`) and the direction from x towards the eye, so for a
camera ray x_s = o + s·v the cosine is cosθ = -ω_prop·v.

This module knows nothing about occluders: the helpers here integrate over segments the
caller has already found to be lit (V = 1).

The lamp. Along a ray through a point light the integral diverges like ∫ds/d², and with the
eye at the light every ray goes through it. So a point or spot light is a lamp: a ball of
radius `lamp_radius(scene)` = LAMP_RADIUS_REL × the scene's size around it holds no medium. A ray
that passes the light at a distance h > lamp radius never meets the ball, so the ball
changes nothing but those two cases: they become finite (about σs·I·ρ·2/radius per ray).
The scene's size is the diagonal of the bounds of its triangles, the camera and the lights'
positions (`scene_size`), never camera.far: far bounds only the rays that hit nothing, so
a closed room renders the same whatever its far (docs/design.md §1, the lamp).

Far. camera.far only ends the rays that hit nothing. Past the optical depth
FAR_OPTICAL_DEPTH of the least attenuating channel the medium adds nothing a float32 can
hold, so every method ends rays at `effective_far(scene)`: far, but no further than that
depth past twice the distance of the farthest vertex or light from the eye, and never past
FAR_DEVICE_MAX (which keeps squares of distances finite in float32). A far of 1e300 thus
renders like a far of a few hundred scene units instead of overflowing.
"""
from __future__ import annotations

import math

import numpy as np

from ..scene.model import DirectionalLight, Light, Medium, Phase, SpotLight
from ..structs import FAR_DEVICE_MAX, FAR_OPTICAL_DEPTH, LAMP_RADIUS_REL

# Gauss–Legendre rule on [-1, 1] used for every panel of the point-light quadrature.
GL_NODES = 16
_GL_X, _GL_W = np.polynomial.legendre.leggauss(GL_NODES)

# Bound on the float64 elements of one quadrature batch (segments × nodes × 3 channels),
# so a call on many segments stays around 100 MB of temporaries.
_QUAD_BATCH_ELEMENTS = 1_500_000


def rgb(value) -> np.ndarray:
    """A colour or coefficient as a float64 array of shape (3,) (a scalar is broadcast)."""
    return np.broadcast_to(np.asarray(value, dtype=np.float64), (3,)).copy()


def phase(cos_theta, phase: Phase) -> np.ndarray:
    """Phase function value ρ(cosθ), same shape as `cos_theta`.

    isotropic:         ρ = 1 / (4π)
    Henyey–Greenstein: ρ(c) = (1 - g²) / (4π (1 + g² - 2g·c)^{3/2})

    Both integrate to 1 over the sphere; g > 0 scatters forward (cosθ = 1 means the light
    keeps its direction and goes on towards the eye).
    """
    c = np.asarray(cos_theta, dtype=np.float64)
    if phase.type == "isotropic":
        return np.full(c.shape, 1.0 / (4.0 * math.pi))
    if phase.type == "hg":
        g = float(phase.g)
        # Rounding can push |c| a hair past 1; clipping keeps the base ≥ (1 - |g|)² > 0.
        c = np.clip(c, -1.0, 1.0)
        return (1.0 - g * g) / (4.0 * math.pi * (1.0 + g * g - 2.0 * g * c) ** 1.5)
    raise ValueError(f"unknown phase function {phase.type!r}")


def light_position(light: Light) -> np.ndarray | None:
    """The light's position (3,), or None for a directional light."""
    if isinstance(light, DirectionalLight):
        return None
    return np.asarray(light.position, dtype=np.float64)


def scene_size(scene) -> float:
    """The diagonal of the bounds of the scene's triangles, the camera position and every
    point or spot light's position, in scene units (0 only for a scene with no triangles
    whose camera sits at its only light)."""
    points = [np.reshape(scene.camera.position, (1, 3))]
    points += [np.reshape(light.position, (1, 3)) for light in scene.lights if not isinstance(light, DirectionalLight)]
    if scene.geometry.count:  # the triangles' bounds: a relief's from its texels (Geometry.bounds)
        points += [np.stack(scene.geometry.bounds())]
    points = np.concatenate(points).astype(np.float64)
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


def effective_far(scene) -> float:
    """Where every method ends the rays that hit nothing (module docstring, Far): camera.far,
    clamped where going further changes no float32 radiance."""
    eye = np.asarray(scene.camera.position, dtype=np.float64)
    points = [eye.reshape(1, 3)]
    points += [np.reshape(light.position, (1, 3)) for light in scene.lights if not isinstance(light, DirectionalLight)]
    reach = max(float(np.sqrt(((np.concatenate(points) - eye) ** 2).sum(axis=1).max())),
                scene.geometry.farthest_from(eye))  # a relief's part from its texels
    sigma_t = np.asarray(scene.medium.sigma_t, dtype=np.float64)
    optical = FAR_OPTICAL_DEPTH / float(sigma_t[sigma_t > 0].min()) if (sigma_t > 0).any() else 0.0
    # A light of any power sits within `reach`, so what lies a further `optical` away is
    # e^-FAR_OPTICAL_DEPTH of the light the ray gathers nearer (the light's path and the
    # ray's together are at least as long). The margin of 2 keeps far surfaces from float32
    # rounding against the clamped far.
    return min(float(scene.camera.far), 2.0 * reach + optical, FAR_DEVICE_MAX)


def lamp_radius(scene) -> float:
    """Radius of every point and spot light's medium-free ball (module docstring), in the
    scene's length unit: LAMP_RADIUS_REL × `scene_size`, or × the effective far for a
    scene of size 0."""
    return LAMP_RADIUS_REL * (scene_size(scene) or effective_far(scene))


def lamp_interval(light: Light, origins: np.ndarray, dirs: np.ndarray, radius: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The part (a, b) of each ray x(s) = o + s·v (v unit) inside the lamp |x - l| < radius,
    each (N,); a ray that misses it (or a directional light) gets a = b = 0.

    With s0 = (l - o)·v and h = |(l - o) - s0·v| the ray's distance from the light, the
    chord is s0 ± sqrt(radius² - h²)."""
    dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    n = len(dirs)
    position = light_position(light)
    if position is None or radius <= 0:
        return np.zeros(n), np.zeros(n)
    to_light = position - np.broadcast_to(np.asarray(origins, dtype=np.float64), (n, 3))
    s0 = np.einsum("ij,ij->i", to_light, dirs)
    across = to_light - s0[:, None] * dirs
    h2 = np.einsum("ij,ij->i", across, across)
    half = np.sqrt(np.maximum(radius * radius - h2, 0.0))
    inside = h2 < radius * radius
    return np.where(inside, s0 - half, 0.0), np.where(inside, s0 + half, 0.0)


def spot_axis(light: SpotLight) -> np.ndarray:
    """Unit cone axis of a spot light (the scene model promises unit, this makes sure)."""
    a = np.asarray(light.direction, dtype=np.float64)
    return a / np.linalg.norm(a)


def in_spot_cone(light: SpotLight, points: np.ndarray) -> np.ndarray:
    """Boolean (N,): x is inside the cone, (x - l)·a ≥ cos(cone)·|x - l| (edge included)."""
    w = np.asarray(points, dtype=np.float64).reshape(-1, 3) - light.position
    cos_cone = math.cos(math.radians(light.cone_deg))
    return w @ spot_axis(light) >= cos_cone * np.linalg.norm(w, axis=1)


def propagation_direction(light: Light, points: np.ndarray) -> np.ndarray:
    """Unit direction (N, 3) in which the light travels at each point: (x - l)/|x - l|,
    or the directional light's `direction`."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if isinstance(light, DirectionalLight):
        w = np.asarray(light.direction, dtype=np.float64)
        return np.broadcast_to(w / np.linalg.norm(w), points.shape).copy()
    w = points - light.position
    with np.errstate(invalid="ignore", divide="ignore"):
        return w / np.linalg.norm(w, axis=1, keepdims=True)


def light_incident(light: Light, points: np.ndarray, sigma_t) -> np.ndarray:
    """Unshadowed incident radiance Lin(x) (N, 3) at each point, per RGB channel.

    point:       Lin = I·e^{-σt·d} / d²,  d = |x - l|
    spot:        the same inside the cone, 0 outside (hard edge)
    directional: Lin = E (not attenuated inside the scene)

    A point exactly at a point light gets +inf.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    sigma_t = rgb(sigma_t)
    if isinstance(light, DirectionalLight):
        return np.broadcast_to(rgb(light.irradiance), points.shape).copy()
    d = np.linalg.norm(points - light.position, axis=1)
    with np.errstate(divide="ignore"):
        lin = rgb(light.intensity) * np.exp(-sigma_t * d[:, None]) / (d * d)[:, None]
    if isinstance(light, SpotLight):
        lin = np.where(in_spot_cone(light, points)[:, None], lin, 0.0)
    return lin


def cone_interval(light: SpotLight, origins: np.ndarray, dirs: np.ndarray, t0, t1) -> tuple[np.ndarray, np.ndarray]:
    """The part [a, b] of each ray x(s) = o + s·v, s ∈ [t0, t1], inside a spot light's cone.

    With q = o - l, a the axis and c = cos(cone), the double cone is
    ((q + s·v)·a)² - c²·|q + s·v|² ≥ 0, a quadratic A s² + 2B s + C ≥ 0 with
    A = (v·a)² - c², B = (q·a)(v·a) - c²(q·v), C = (q·a)² - c²|q|²; the light's cone is
    the nappe with (q + s·v)·a ≥ 0. For a half-angle ≤ 90° that nappe is convex, so a
    ray meets it in one interval: the breakpoints (roots, the apex plane crossing, t0, t1)
    cut [t0, t1] into pieces, and the interval spans the pieces whose midpoint is inside.
    Returns (a, b), each (N,); a ray that misses the cone gets a = b.
    """
    dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    n = len(dirs)
    q = np.broadcast_to(np.asarray(origins, dtype=np.float64), (n, 3)) - light.position
    t0 = np.broadcast_to(np.asarray(t0, dtype=np.float64), (n,))
    t1 = np.broadcast_to(np.asarray(t1, dtype=np.float64), (n,))
    axis = spot_axis(light)
    c2 = math.cos(math.radians(light.cone_deg)) ** 2
    qa, va = q @ axis, dirs @ axis
    qv, qq = np.einsum("ij,ij->i", q, dirs), np.einsum("ij,ij->i", q, q)
    vv = np.einsum("ij,ij->i", dirs, dirs)
    qa_, b_, c_ = va * va - c2 * vv, qa * va - c2 * qv, qa * qa - c2 * qq
    with np.errstate(invalid="ignore", divide="ignore"):
        disc = b_ * b_ - qa_ * c_
        # Numerically stable roots: r1 = k/A, r2 = C/k with k = -(B + sign(B)·√disc);
        # A = 0 (ray parallel to a generator) leaves the single linear root C/k.
        k = -(b_ + np.copysign(np.sqrt(np.maximum(disc, 0.0)), b_))
        r1 = np.where(disc >= 0, k / qa_, np.nan)
        r2 = np.where(disc >= 0, c_ / k, np.nan)
        r_apex = -qa / va
    cuts = np.stack([t0, t1, r1, r2, r_apex], axis=1)
    cuts = np.where(np.isfinite(cuts), cuts, t0[:, None])
    cuts = np.sort(np.clip(cuts, t0[:, None], t1[:, None]), axis=1)
    mid = 0.5 * (cuts[:, :-1] + cuts[:, 1:])
    w = q[:, None, :] + mid[..., None] * dirs[:, None, :]
    inside = (w @ axis) >= math.sqrt(c2) * np.linalg.norm(w, axis=2)
    inside &= cuts[:, 1:] > cuts[:, :-1]
    lo = np.min(np.where(inside, cuts[:, :-1], np.inf), axis=1)
    hi = np.max(np.where(inside, cuts[:, 1:], -np.inf), axis=1)
    empty = ~inside.any(axis=1)
    lo = np.where(empty, t0, lo)
    hi = np.where(empty, t0, hi)
    return lo, hi


def _point_segments_panels(s0, h, ua, ub, coeff, sigma_t, ph: Phase, panels: int) -> np.ndarray:
    """Composite Gauss–Legendre estimate (M, 3) of ∫_{s0+ua}^{s0+ub} coeff·ρ·e^{-σt(s+d)}/d² ds.

    See `in_scatter_segments` for the change of variables. Both sides of the closest
    approach go in one array: side 0 is u = s - s0 ∈ [ua, min(ub, 0)] (before it), side 1
    is u ∈ [max(ua, 0), ub] (after it); an empty side gets zero width.
    """
    m = len(s0)
    u_lo = np.stack([ua, np.maximum(ua, 0.0)], axis=1)
    u_hi = np.stack([np.minimum(ub, 0.0), ub], axis=1)
    hh = h[:, None]
    # ψ = π/2 - |φ| = atan2(h, |u|) at both ends of each side; atan2 stays exact for tiny h.
    psi_small = np.arctan2(hh, np.stack([-u_lo[:, 0], u_hi[:, 1]], axis=1))  # end far from the light
    psi_large = np.arctan2(hh, np.stack([-u_hi[:, 0], u_lo[:, 1]], axis=1))  # end close to it
    valid = u_hi > u_lo
    lo = np.log(np.where(valid, psi_small, 1.0))
    hi = np.log(np.where(valid, psi_large, 1.0))
    # Panels uniform in τ = ln ψ: geometric grading towards ψ → 0, where the φ-integrand
    # changes on a scale ~ h/|s - s0| (the exponentials and the phase are smooth in s).
    width = (hi - lo) / panels  # (M, 2)
    k = np.arange(panels)[:, None]
    tau_unit = (k + 0.5 * (_GL_X[None, :] + 1.0)).reshape(-1)  # (P·G,) in [0, panels]
    weights = np.tile(_GL_W, panels) * 0.5  # Gauss weights for a panel of unit width
    psi = np.exp(lo[..., None] + width[..., None] * tau_unit)  # (M, 2, P·G)
    # Before the closest approach s + d = s0 + h·tan(ψ/2) and cosθ = +cosψ; after it
    # s + d = s0 + h·cot(ψ/2) and cosθ = -cosψ (no cancellation between s and d).
    half = np.tan(0.5 * psi)
    path = s0[:, None, None] + hh[..., None] * np.stack([half[:, 0], 1.0 / half[:, 1]], axis=1)
    # An empty side has zero weight, but its dummy nodes may sit at s < 0, where e^{-σt·path}
    # could overflow and turn 0·inf into NaN: park them at the ray's origin.
    path = np.where(valid[..., None], path, 0.0)
    cos_theta = np.cos(psi) * np.array([1.0, -1.0])[None, :, None]
    # dψ = ψ·dτ, and ds/d² = dψ/h: the 1/h is applied once at the end.
    g = (phase(cos_theta, ph) * psi * (weights * width[..., None])).reshape(m, -1)
    path = path.reshape(m, -1)
    out = np.empty((m, 3))
    for ch in range(3):
        out[:, ch] = np.einsum("ij,ij->i", g, np.exp(-sigma_t[ch] * path))
    return out * coeff / h[:, None]


def in_scatter_segments(light: Light, medium: Medium, origins: np.ndarray, dirs: np.ndarray, a, b, *,
                        panels: int = 8, tol: float | None = 1e-10, max_panels: int = 4096) -> np.ndarray:
    """In-scattered radiance (M, 3) from lit segments s ∈ [a, b] of rays x(s) = o + s·v (v unit):

        ∫_a^b e^{-σt·s} · σs · ρ(cosθ) · Lin(x_s) ds      (V = 1 assumed; a spot cone is NOT
                                                          applied here, clip with `cone_interval`)

    Directional light (closed form, cosθ = -w·v constant):

        σs·E·ρ·(e^{-σt·a} - e^{-σt·b})/σt = σs·E·ρ·e^{-σt·a}·(-expm1(-σt(b - a)))/σt  (→ b - a as σt → 0)

    Point / spot light: with s0 = (l - o)·v the closest approach and h = |(l - o) - s0·v| the
    distance of the ray's line from the light, s = s0 + h·tanφ gives d = h/cosφ and
    ds/d² = dφ/h, so

        ∫ σs·I·ρ(-sinφ)·e^{-σt(s + d)} dφ / h,     φ ∈ (-π/2, π/2)

    whose 1/d² peak is gone. Each side of the closest approach is integrated in
    ψ = π/2 - |φ| (then s + d = s0 + h·tan(ψ/2) before it, s0 + h·cot(ψ/2) after it, and
    cosθ = ±cosψ) with composite Gauss–Legendre (`panels` × 16 nodes) on panels uniform in
    ln ψ. With `tol`, segments are re-integrated with twice the panels until two successive
    estimates agree to `tol` relative (or `max_panels` is reached); with tol=None one pass.
    h is clamped to 1e-12 of the segment's scale so a ray through the light stays finite
    (the true integral there diverges like π/h).
    """
    dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    m = len(dirs)
    origins = np.broadcast_to(np.asarray(origins, dtype=np.float64), (m, 3))
    a = np.broadcast_to(np.asarray(a, dtype=np.float64), (m,))
    b = np.broadcast_to(np.asarray(b, dtype=np.float64), (m,))
    sigma_s, sigma_t = rgb(medium.sigma_s), rgb(medium.sigma_s) + rgb(medium.sigma_a)
    out = np.zeros((m, 3))
    if m == 0:
        return out
    if isinstance(light, DirectionalLight):
        w = np.asarray(light.direction, dtype=np.float64)
        w = w / np.linalg.norm(w)
        rho = phase(-(dirs @ w), medium.phase)
        length = np.maximum(b - a, 0.0)[:, None]
        st = sigma_t[None, :]
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            factor = np.where(st > 0, -np.exp(-st * a[:, None]) * np.expm1(-st * length) / st, length)
        return sigma_s * rgb(light.irradiance) * rho[:, None] * factor
    to_light = light.position - origins
    s0 = np.einsum("ij,ij->i", to_light, dirs)
    h = np.linalg.norm(to_light - s0[:, None] * dirs, axis=1)
    scale = np.linalg.norm(to_light, axis=1) + np.abs(a) + np.abs(b)
    h = np.maximum(h, 1e-12 * np.maximum(scale, np.finfo(float).tiny))
    ua, ub = a - s0, b - s0
    coeff = sigma_s * rgb(light.intensity)

    def estimate(idx: np.ndarray, p: int) -> np.ndarray:
        # Batches keep each temporary (segments × 2 sides × p·16 nodes) near 12 MB.
        res = np.empty((len(idx), 3))
        batch = max(1, _QUAD_BATCH_ELEMENTS // (2 * GL_NODES * p))
        for k in range(0, len(idx), batch):
            j = idx[k:k + batch]
            res[k:k + batch] = _point_segments_panels(s0[j], h[j], ua[j], ub[j], coeff, sigma_t, medium.phase, p)
        return res

    live = np.flatnonzero(b > a)
    out[live] = refined(estimate, live, panels, tol, max_panels)
    return out


def refined(estimate, items: np.ndarray, panels: int, tol: float | None, max_panels: int) -> np.ndarray:
    """`estimate(items, p)` (len(items), 3) with p = `panels`, then, for the items whose estimate
    still moves by more than `tol` relative, with twice the panels, until none moves or
    `max_panels` is reached (tol=None: the first estimate)."""
    est = estimate(items, panels)
    p, todo = panels, np.arange(len(items))
    # Adaptive refinement: only the segments whose estimate still moves get more panels.
    while tol is not None and len(todo) and 2 * p <= max_panels:
        p *= 2
        finer = estimate(items[todo], p)
        moved = np.any(np.abs(finer - est[todo]) > tol * np.abs(finer), axis=1)
        est[todo] = finer
        todo = todo[moved]
    return est


def in_scatter_unoccluded(light: Light, medium: Medium, origins: np.ndarray, dirs: np.ndarray, D, **quad) -> np.ndarray:
    """In-scattering (N, 3) along rays s ∈ [0, D] with V = 1 everywhere, spot cone applied:
    `in_scatter_segments` over [0, D] (or over the part of it inside the cone)."""
    dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    n = len(dirs)
    a = np.zeros(n)
    b = np.broadcast_to(np.asarray(D, dtype=np.float64), (n,))
    if isinstance(light, SpotLight):
        a, b = cone_interval(light, origins, dirs, a, b)
    return in_scatter_segments(light, medium, origins, dirs, a, b, **quad)


__all__ = ["GL_NODES", "LAMP_RADIUS_REL", "rgb", "phase", "light_position", "scene_size", "effective_far", "lamp_radius", "lamp_interval",
           "spot_axis", "in_spot_cone", "propagation_direction",
           "light_incident", "cone_interval", "in_scatter_segments", "in_scatter_unoccluded"]
