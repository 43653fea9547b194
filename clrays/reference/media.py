"""A bounded or heterogeneous medium in `exact` (docs/media.md): numpy, float64.

The medium's density ρ(x) ≥ 0 multiplies σs and σa: the box's indicator (`Medium.bounds`)
times exp(−(y − base)/H) (`HeightDensity`) or the grid's trilinear value (`GridDensity`:
between voxel centres, held at the outermost centres out to the grid's bounds, 0 beyond).
Along a ray x(s) = o + s·v (v unit):

    T_e(s) = exp(−σt·τ(o, v, 0, s)),   τ(o, v, s0, s1) = ∫_{s0}^{s1} ρ(x(s')) ds'  (optical depth of ρ)
    T_l(x) = exp(−σt·τ(x, ω, 0, r))    ω towards the light, r its distance (∞ for a directional light)
    L_in   = Σ_lit [a, b] ∫_a^b σs·ρ(x_s)·p(cosθ)·Lin₀(x_s)·T_e(s)·T_l(x_s) ds

Lin₀ being the light's unattenuated incident radiance (I/d², or E; a texture multiplies it).

- τ of a box or height fog is closed form: with L the part of [s0, s1] in the box and
  z = |v_y|·L/H, τ = ρ(lower end)·L·(1 − e^{−z})/z (ρ·H/v_y for an unbounded ray rising).
- τ through a grid is exact up to rounding: along a line ρ is a cubic polynomial between the
  planes through voxel centres (and the bounds), so each piece between them takes 3-point
  Gauss–Legendre (exact to degree 5).
- The in-scattering is composite Gauss–Legendre (GL_NODES per panel) on the pieces between
  the box's faces and the grid's planes, in s for a directional light and in the angle φ of
  s = s0 + h·tanφ for a point or spot light (ds/d² = dφ/h, as `radiometry.in_scatter_segments`);
  the panels double until two estimates agree to `tol` relative (or MAX_PANELS).
"""
from __future__ import annotations

import numpy as np

from ..physics.light_texture import light_texture, textured, textured_in_scatter
from ..physics.radiometry import (in_scatter_segments, light_incident, phase, propagation_direction, refined,
                                  rgb)
from ..scene.model import Box, DirectionalLight, GridDensity, HeightDensity, Light, Medium

#: Gauss–Legendre nodes per piece of a grid's optical depth: ρ is cubic there, 2 would do.
DEPTH_NODES = 3
_DEPTH_X, _DEPTH_W = np.polynomial.legendre.leggauss(DEPTH_NODES)
#: Gauss–Legendre nodes per panel of the in-scattering quadrature.
GL_NODES = 8
_GL_X, _GL_W = np.polynomial.legendre.leggauss(GL_NODES)
#: The most panels per piece the in-scattering's doubling reaches.
MAX_PANELS = 256
#: The tightest relative tolerance of the in-scattering's doubling: a grid's T_l has kinks
#: between the pieces (where light rays cross voxel-centre lines), so the last digits converge
#: slowly, and 1e-6 is far below every comparison made with `exact`.
MEDIA_TOLERANCE = 1e-6
#: exp(−(y − base)/H) with its exponent at most this (e^700 is still a float64).
HEIGHT_EXPONENT_MAX = 700.0
#: Bound on the float64 elements of a batch of optical depths (rays × pieces × nodes).
_BATCH_ELEMENTS = 2_000_000


def media_tolerance(tol: float | None) -> float | None:
    """`exact`'s quadrature tolerance as the media's quadrature takes it (MEDIA_TOLERANCE at the tightest)."""
    return None if tol is None else max(tol, MEDIA_TOLERANCE)


def clip_box(box: Box, origins, dirs, t0, t1) -> tuple[np.ndarray, np.ndarray]:
    """[t0, t1] of each ray o + t·v clipped to `box` (slabs), each (N,); empty where t0 ≥ t1."""
    origins, dirs = np.asarray(origins, dtype=np.float64), np.asarray(dirs, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / dirs
        ta = (np.asarray(box.min) - origins) * inv
        tb = (np.asarray(box.max) - origins) * inv
    # A ray parallel to a slab is inside it for every t or for none (0·inf is NaN: inside).
    near = np.where(np.isnan(ta) | np.isnan(tb), -np.inf, np.minimum(ta, tb))
    far = np.where(np.isnan(ta) | np.isnan(tb), np.inf, np.maximum(ta, tb))
    return np.maximum(t0, near.max(axis=-1)), np.minimum(t1, far.min(axis=-1))


def medium_extent(medium: Medium, origins, dirs, t0, t1) -> tuple[np.ndarray, np.ndarray]:
    """[t0, t1] clipped to where the medium can be: the box, and a grid's bounds."""
    if medium.bounds is not None:
        t0, t1 = clip_box(medium.bounds, origins, dirs, t0, t1)
    if isinstance(medium.density, GridDensity):
        t0, t1 = clip_box(medium.density.bounds, origins, dirs, t0, t1)
    return t0, t1


def height_factor(density: HeightDensity, y) -> np.ndarray:
    return np.exp(np.minimum(-(np.asarray(y, dtype=np.float64) - density.base) / density.scale_height,
                             HEIGHT_EXPONENT_MAX))


def grid_values(density: GridDensity, points) -> np.ndarray:
    """The grid's trilinear value at each point (N,): between voxel centres, held at the
    outermost centres out to the bounds, 0 beyond them."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    flat = density.values.reshape(-1)
    nz, ny, nx = density.values.shape
    size = np.array([nx, ny, nz], dtype=np.float64)
    lo, hi = np.asarray(density.bounds.min), np.asarray(density.bounds.max)
    c = (p - lo) / (hi - lo) * size
    inside = np.all((c >= 0) & (c <= size), axis=1)
    c = np.clip(c - 0.5, 0.0, size - 1.0)
    cell = np.floor(c)
    f = c - cell
    i = cell.astype(np.intp)
    # The next voxel along each axis (none past the last: its weight is then 0 anyway).
    dx = (i[:, 0] + 1 < nx).astype(np.intp)
    dy = (i[:, 1] + 1 < ny) * nx
    dz = (i[:, 2] + 1 < nz) * (nx * ny)
    base = (i[:, 2] * ny + i[:, 1]) * nx + i[:, 0]
    fx, fy, fz = f[:, 0], f[:, 1], f[:, 2]

    def along_x(offset):
        v0 = flat[base + offset]
        return v0 + fx * (flat[base + offset + dx] - v0)

    near = along_x(0) + fy * (along_x(dy) - along_x(0))
    far = along_x(dz) + fy * (along_x(dz + dy) - along_x(dz))
    return np.where(inside, near + fz * (far - near), 0.0)


def density_at(medium: Medium, points) -> np.ndarray:
    """ρ(x) (N,): the box's indicator × the height or grid factor."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    rho = np.ones(len(p))
    if medium.bounds is not None:
        rho *= np.all((p >= medium.bounds.min) & (p <= medium.bounds.max), axis=1)
    if isinstance(medium.density, HeightDensity):
        rho *= height_factor(medium.density, p[:, 1])
    elif isinstance(medium.density, GridDensity):
        rho *= grid_values(medium.density, p)
    return rho


def _grid_planes(density: GridDensity) -> list[np.ndarray]:
    """Per axis, the planes where ρ along a line stops being one cubic: the voxel centres' and
    the bounds'."""
    lo, hi = np.asarray(density.bounds.min), np.asarray(density.bounds.max)
    planes = []
    for axis, n in enumerate(density.values.shape[::-1]):
        centres = lo[axis] + (np.arange(n) + 0.5) * (hi[axis] - lo[axis]) / n
        planes.append(np.concatenate([[lo[axis]], centres, [hi[axis]]]))
    return planes


def breaks(medium: Medium, origins, dirs, t0, t1) -> np.ndarray:
    """(N, K) sorted parameters in [t0, t1] between which ρ along each ray is smooth (one
    cubic in a grid): t0, t1 and the crossings of the grid's planes (t0 where none)."""
    origins = np.broadcast_to(np.asarray(origins, dtype=np.float64), np.shape(dirs))
    dirs = np.asarray(dirs, dtype=np.float64)
    t0, t1 = np.asarray(t0, dtype=np.float64), np.asarray(t1, dtype=np.float64)
    cuts = [t0[:, None], t1[:, None]]
    if isinstance(medium.density, GridDensity):
        with np.errstate(divide="ignore", invalid="ignore"):
            for axis, planes in enumerate(_grid_planes(medium.density)):
                cuts.append((planes[None, :] - origins[:, axis:axis + 1]) / dirs[:, axis:axis + 1])
    t = np.concatenate(cuts, axis=1)
    t = np.where(np.isfinite(t), t, t0[:, None])
    return np.sort(np.clip(t, t0[:, None], np.maximum(t0, t1)[:, None]), axis=1)


def optical_depth(medium: Medium, origins, dirs, t0, t1) -> np.ndarray:
    """τ = ∫ρ ds (N,) over [t0, t1] of the rays o + t·v (v unit; t1 may be +inf): closed form
    for a box and height fog, exact piecewise Gauss–Legendre in a grid (module docstring)."""
    dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    n = len(dirs)
    origins = np.broadcast_to(np.asarray(origins, dtype=np.float64).reshape(-1, 3), (n, 3))
    t0 = np.broadcast_to(np.asarray(t0, dtype=np.float64), (n,))
    t1 = np.broadcast_to(np.asarray(t1, dtype=np.float64), (n,))
    a, b = medium_extent(medium, origins, dirs, t0, t1)
    live = b > a
    a, b = np.where(live, a, 0.0), np.where(live, b, 0.0)
    density = medium.density
    if isinstance(density, GridDensity):
        return _grid_depth(medium, origins, dirs, a, b)
    length = b - a
    if isinstance(density, HeightDensity):
        vy = dirs[:, 1]
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            lower = origins[:, 1] + np.where(vy > 0, a, b) * vy
            z = np.abs(vy) * length / density.scale_height
            ratio = np.where(z > 1e-8, -np.expm1(-z) / z, 1.0 - 0.5 * z)
            finite = height_factor(density, lower) * length * ratio
            rising = height_factor(density, origins[:, 1] + a * vy) * density.scale_height / vy
        depth = np.where(np.isinf(length), np.where(vy > 0, rising, np.inf), finite)
        return np.where(live, depth, 0.0)
    return np.where(live, length, 0.0)


def _grid_depth(medium: Medium, origins, dirs, a, b) -> np.ndarray:
    n = len(dirs)
    out = np.zeros(n)
    pieces = 2 + sum(len(p) for p in _grid_planes(medium.density))
    batch = max(1, _BATCH_ELEMENTS // (pieces * DEPTH_NODES))
    for start in range(0, n, batch):
        sl = slice(start, start + batch)
        t = breaks(medium, origins[sl], dirs[sl], a[sl], b[sl])
        mid, half = 0.5 * (t[:, 1:] + t[:, :-1]), 0.5 * (t[:, 1:] - t[:, :-1])
        s = mid[..., None] + half[..., None] * _DEPTH_X  # (rays, pieces, nodes)
        points = origins[sl, None, None, :] + s[..., None] * dirs[sl, None, None, :]
        rho = density_at(medium, points.reshape(-1, 3)).reshape(s.shape)
        out[sl] = np.einsum("rpk,rp,k->r", rho, half, _DEPTH_W)
    return out


def light_depth(light: Light, medium: Medium, points) -> np.ndarray:
    """τ (N,) from each point to the light (to infinity against a directional light's direction)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    towards = -propagation_direction(light, points)
    if isinstance(light, DirectionalLight):
        reach = np.full(len(points), np.inf)
    else:
        reach = np.linalg.norm(np.asarray(light.position) - points, axis=1)
        towards = np.where(reach[:, None] > 0, towards, 0.0)
    return optical_depth(medium, points, towards, 0.0, reach)


def light_incident_media(light: Light, medium: Medium, points) -> np.ndarray:
    """Lin (N, 3) at each point through the medium: the unattenuated light (a spot's cone and
    a texture applied) × T_l = exp(−σt·τ to the light)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    sigma_t = rgb(medium.sigma_s) + rgb(medium.sigma_a)
    lin = light_incident(light, points, 0.0)
    with np.errstate(invalid="ignore"):  # σt = 0 with τ = ∞: no medium, T = 1
        attenuation = np.exp(-np.where(sigma_t > 0, sigma_t * light_depth(light, medium, points)[:, None], 0.0))
    return lin * attenuation


def in_scatter_media(light: Light, medium: Medium, origin, dirs, a, b, *, tol: float | None = MEDIA_TOLERANCE,
                     panels: int = 2) -> np.ndarray:
    """In-scattered radiance (M, 3) over the lit segments [a, b] of rays from `origin` along
    unit `dirs` (module docstring); the spot cone and the lamp are the lit intervals' (the
    caller's). `panels` per piece to start, doubled while the estimate moves by more than
    `tol` relative (None: one pass)."""
    dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    m = len(dirs)
    origin = np.asarray(origin, dtype=np.float64).reshape(3)
    a, b = medium_extent(medium, origin, dirs, np.asarray(a, np.float64), np.asarray(b, np.float64))
    out = np.zeros((m, 3))
    live = np.flatnonzero(b > a)
    if not len(live) or not np.any(rgb(medium.sigma_s) > 0):
        return out
    point = not isinstance(light, DirectionalLight)
    if point:  # s = s0 + h·tanφ about the ray's closest approach to the light
        to_light = np.asarray(light.position) - origin
        s0 = dirs @ to_light
        h = np.linalg.norm(to_light[None, :] - s0[:, None] * dirs, axis=1)
        h = np.maximum(h, 1e-12 * (np.linalg.norm(to_light) + np.abs(a) + np.abs(b)) + np.finfo(float).tiny)
    else:
        s0 = h = np.zeros(m)

    def estimate(rays: np.ndarray, p: int) -> np.ndarray:
        res = np.empty((len(rays), 3))
        width = breaks(medium, origin, dirs[rays[:1]], a[rays[:1]], b[rays[:1]]).shape[1] * p * GL_NODES
        batch = max(1, _BATCH_ELEMENTS // (8 * width))
        for k in range(0, len(rays), batch):
            res[k:k + batch] = _in_scatter_panels(light, medium, origin, dirs, a, b, s0, h, point,
                                                  rays[k:k + batch], p)
        return res

    out[live] = refined(estimate, live, panels, tol, MAX_PANELS)
    return out


def _in_scatter_panels(light, medium, origin, dirs, a, b, s0, h, point: bool, rays, p: int) -> np.ndarray:
    """One composite Gauss–Legendre estimate (len(rays), 3) with `p` panels per piece."""
    v = dirs[rays]
    t = breaks(medium, origin, v, a[rays], b[rays])  # (R, K)
    u = np.arctan2(t - s0[rays, None], h[rays, None]) if point else t  # the variable of integration
    k = np.arange(p)[:, None]
    unit = ((k + 0.5 * (_GL_X[None, :] + 1.0)) / p).reshape(-1)  # (p·G,) in [0, 1]
    weights = np.tile(_GL_W, p) * 0.5 / p
    lo, width = u[:, :-1], u[:, 1:] - u[:, :-1]  # (R, K-1)
    nodes = lo[..., None] + width[..., None] * unit  # (R, K-1, p·G)
    jac = width[..., None] * weights  # du per node
    if point:
        s = s0[rays, None, None] + h[rays, None, None] * np.tan(nodes)
        jac = jac / h[rays, None, None]  # ds/d² = dφ/h; Lin₀·d² = I below
    else:
        s = nodes
    x = origin + s.reshape(len(rays), -1, 1) * v[:, None, :]  # (R, nodes, 3)
    x = x.reshape(-1, 3)
    sigma_s, sigma_t = rgb(medium.sigma_s), rgb(medium.sigma_s) + rgb(medium.sigma_a)
    rho = density_at(medium, x)
    ray_dirs = np.repeat(v, s[0].size, axis=0)
    if isinstance(medium.density, GridDensity):
        eye_depth = _eye_depth_in_pieces(medium, origin, v, t, s).reshape(-1)
    else:
        eye_depth = optical_depth(medium, origin, ray_dirs, 0.0, s.reshape(-1))
    tau = eye_depth + light_depth(light, medium, x)
    cos_theta = -np.einsum("ij,ij->i", propagation_direction(light, x), ray_dirs)
    if point:  # I·ρ_phase·(1/d²·d²): light_incident's 1/d² is the Jacobian's
        d2 = np.sum((x - np.asarray(light.position)) ** 2, axis=1)
        lin = light_incident(light, x, 0.0) * d2[:, None]
    else:
        lin = light_incident(light, x, 0.0)
    lin *= light_texture(light, x)
    with np.errstate(invalid="ignore"):  # a channel with σt = 0 sees no extinction, even over τ = ∞
        extinction = np.where(sigma_t > 0, sigma_t * tau[:, None], 0.0)
    f = sigma_s * lin * (rho * phase(cos_theta, medium.phase))[:, None] * np.exp(-extinction)
    f = np.where(rho[:, None] > 0, f, 0.0)
    return np.einsum("rnc,rn->rc", f.reshape(len(rays), -1, 3), jac.reshape(len(rays), -1))


def _eye_depth_in_pieces(medium: Medium, origin, v, t, s) -> np.ndarray:
    """τ from the eye to each node s (R, K-1, n) of the pieces between the breaks t (R, K), along
    which ρ is one cubic: the depth to t[:, 0], the pieces' depths before the node's (each by
    3-point Gauss–Legendre, exact), and the part of its own piece up to it (the same)."""
    def rho(points_s):  # ρ at parameters (R, ...) along each ray
        x = origin + points_s[..., None] * v.reshape((len(v),) + (1,) * (points_s.ndim - 1) + (3,))
        return density_at(medium, x.reshape(-1, 3)).reshape(points_s.shape)

    def piece_depth(lo, hi):  # ∫_lo^hi ρ, lo and hi (R, ...) in one piece each
        half = 0.5 * (hi - lo)
        nodes = 0.5 * (hi + lo)[..., None] + half[..., None] * _DEPTH_X
        return half * (rho(nodes) @ _DEPTH_W)

    before = optical_depth(medium, origin, v, 0.0, t[:, 0])
    pieces = piece_depth(t[:, :-1], t[:, 1:])
    starts = before[:, None] + np.concatenate([np.zeros((len(v), 1)), np.cumsum(pieces, axis=1)[:, :-1]], axis=1)
    lo = np.broadcast_to(t[:, :-1, None], s.shape)
    return starts[..., None] + piece_depth(lo, np.clip(s, lo, t[:, 1:, None]))


# ------------------------------------------------- what `exact` and its translucent path call


def incident_through(light: Light, medium: Medium, points) -> np.ndarray:
    """Lin (N, 3) at surface points: e^{-σt·d} over the light's path in the homogeneous medium
    (`radiometry.light_incident`), T_l in any other (`light_incident_media`)."""
    if medium.homogeneous:
        return light_incident(light, points, rgb(medium.sigma_s) + rgb(medium.sigma_a))
    return light_incident_media(light, medium, points)


def eye_transmittance(medium: Medium, origin, dirs, t, start=0.0) -> np.ndarray:
    """T_e (N, 3) along each unit ray from `start` (the ray's start, `camera.near`; 0: the
    eye) to distance t: e^{-σt·(t − start)}, or e^{-σt·∫ρ}."""
    sigma_t = rgb(medium.sigma_s) + rgb(medium.sigma_a)
    t = np.asarray(t, dtype=np.float64)
    start = np.broadcast_to(np.asarray(start, dtype=np.float64), t.shape)
    depth = t - start if medium.homogeneous else optical_depth(medium, origin, dirs, start, t)
    return np.exp(-sigma_t * depth[:, None])


def near_gain(medium: Medium, origin, dirs, starts, depth) -> np.ndarray:
    """(N, 3) 1 / T_e(min(t0, D)): what turns light attenuated from the eye into light
    attenuated from each ray's start t0 (`camera.ray_starts`), e^{σt·t0} in the homogeneous
    medium. A surface nearer than t0 stays as seen from the eye."""
    return 1.0 / eye_transmittance(medium, origin, dirs, np.minimum(starts, depth))


def in_scatter_lit(light: Light, medium: Medium, origin, dirs, a, b, quad: dict) -> np.ndarray:
    """In-scattering (M, 3) of the lit segments [a, b]: `in_scatter_media` in a bounded or
    heterogeneous medium; else a textured light's cut at its texels, or
    `radiometry.in_scatter_segments` (`quad`: its panels and tol)."""
    if not medium.homogeneous:
        return in_scatter_media(light, medium, origin, dirs, a, b, tol=media_tolerance(quad["tol"]))
    if textured(light):  # cut at the texture's texel centres (clrays.physics.light_texture)
        return textured_in_scatter(light, medium, origin, dirs, a, b)
    return in_scatter_segments(light, medium, origin, dirs, a, b, **quad)


__all__ = ["incident_through", "eye_transmittance", "near_gain", "in_scatter_lit", "media_tolerance", "clip_box", "medium_extent",
           "density_at", "optical_depth", "light_depth", "light_incident_media", "in_scatter_media", "grid_values",
           "height_factor"]
