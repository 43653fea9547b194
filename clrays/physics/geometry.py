"""Geometry in float64: ray casts against every triangle, shadow rays, the exact lit set of
a ray (docs/design.md §4, `exact`; the lamp stage takes it for the eye in the lamp) and the
shading normals at a hit.

A triangle's shadow volume is convex (the region beyond its plane inside the three
planes through the light — or parallel to a directional light — and each edge), so it
meets a ray in one interval, found by clipping against 4 half-spaces; the shadowed set
of a ray is the union of those intervals and the lit set its complement (within a spot
light's cone), less the lamp ball around a point or spot light.
"""
from __future__ import annotations

import numpy as np

from .radiometry import cone_interval, lamp_interval, light_position, propagation_direction
from ..scene.model import Light, SpotLight

# Memory budget for the (rays × triangles) temporaries of one chunk.
BUDGET_BYTES = 100_000_000
# Bytes of float64 temporaries per (ray, triangle) pair, generous: MT holds ~6 vectors.
_RAYCAST_PAIR_BYTES = 8 * 24
CLIP_PAIR_BYTES = 8 * 16

# Relative (to the scene's coordinate scale) epsilons.
_T_MIN_REL = 1e-12  # hits closer than this along a ray are the ray's own start
_SHADOW_OFFSET_REL = 1e-9  # shadow-ray origins leave the surface by this much
_DEGENERATE_REL = 1e-12  # a plane this close to the light contains it


def _scale(*arrays) -> float:
    """Coordinate scale of a scene: the largest |coordinate| (at least 1e-300)."""
    m = 1e-300
    for x in arrays:
        x = np.asarray(x, dtype=np.float64)
        if x.size:
            m = max(m, float(np.max(np.abs(x[np.isfinite(x)]), initial=0.0)))
    return m


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...k,...k->...", a, b)


def triangle_normals(triangles: np.ndarray) -> np.ndarray:
    """Unnormalised geometric normals (T, 3): (p1 - p0) × (p2 - p0)."""
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    return np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])


def triangle_hits(o, d, p0, e1, e2, d_length, n_length) -> tuple[np.ndarray, np.ndarray]:
    """Möller–Trumbore for rays (o, d) against triangles (p0, e1, e2), broadcast: (t, whether
    the ray meets the triangle within its edges). `d_length`, `n_length`: |d| and |e1 × e2|,
    which make a grazing ray (|cos| < 1e-14 against the plane) a miss: its u, v, t are noise."""
    pvec = np.cross(d, e2)
    det = dot(pvec, e1)  # = -d·n
    ok = np.abs(det) > 1e-14 * d_length * n_length
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # only where not ok
        inv = 1.0 / det
        tvec = o - p0
        u = dot(tvec, pvec) * inv
        qvec = np.cross(tvec, e1)
        v = dot(d, qvec) * inv
        t = dot(e2, qvec) * inv
        ok &= (u >= 0) & (v >= 0) & (u + v <= 1)  # u + v is inf - inf where det = 0 (masked already)
    return t, ok


def raycast(origins, dirs, triangles, t_max=np.inf, t_min=None) -> tuple[np.ndarray, np.ndarray]:
    """First hits of rays o + t·d against triangles, Möller–Trumbore in float64.

    origins (N, 3) or (3,), dirs (N, 3) (t is in units of |d|), triangles (T, 3, 3),
    t_max scalar or (N,). Returns (t, index), each (N,): t = inf and index = -1 for a
    miss. Only hits with t_min < t < t_max count; t_min defaults to 1e-12 of the scene's
    coordinate scale (over |d|), so a ray leaving a surface does not hit it again at
    t ≈ 0. Edges are inclusive (u, v ≥ 0, u + v ≤ 1), so a ray through a shared edge of
    a mesh hits; rays within ~1e-14 rad of a triangle's plane miss it. Ties keep the
    lower triangle index. Work is chunked so temporaries stay near 100 MB.
    """
    dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    n = len(dirs)
    origins = np.broadcast_to(np.asarray(origins, dtype=np.float64), (n, 3))
    t_max = np.broadcast_to(np.asarray(t_max, dtype=np.float64), (n,))
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    t_best = np.full(n, np.inf)
    idx_best = np.full(n, -1, dtype=np.int64)
    if n == 0 or len(tri) == 0:
        return t_best, idx_best
    dir_len = np.linalg.norm(dirs, axis=1)
    if t_min is None:
        t_min = _T_MIN_REL * _scale(tri, origins) / np.maximum(dir_len, 1e-300)
    t_min = np.broadcast_to(np.asarray(t_min, dtype=np.float64), (n,))
    p0 = tri[:, 0]
    e1, e2 = tri[:, 1] - p0, tri[:, 2] - p0
    n_len = np.linalg.norm(np.cross(e1, e2), axis=1)
    pairs = max(1, BUDGET_BYTES // _RAYCAST_PAIR_BYTES)
    tc = min(len(tri), pairs)
    rc = max(1, pairs // tc)
    for r in range(0, n, rc):
        o, d = origins[r:r + rc, None, :], dirs[r:r + rc, None, :]
        for k in range(0, len(tri), tc):
            t, ok = triangle_hits(o, d, p0[None, k:k + tc], e1[None, k:k + tc], e2[None, k:k + tc],
                                  dir_len[r:r + rc, None], n_len[None, k:k + tc])
            ok &= (t > t_min[r:r + rc, None]) & (t < t_max[r:r + rc, None])
            t = np.where(ok, t, np.inf)
            j = np.argmin(t, axis=1)
            tj = t[np.arange(len(j)), j]
            better = tj < t_best[r:r + rc]
            t_best[r:r + rc] = np.where(better, tj, t_best[r:r + rc])
            idx_best[r:r + rc] = np.where(better, j + k, idx_best[r:r + rc])
    return t_best, idx_best


def occluded(points, light: Light, triangles, normals=None, eps: float = _SHADOW_OFFSET_REL) -> np.ndarray:
    """Boolean (N,): the segment from each point to the light (or the ray towards a
    directional light) hits a triangle.

    The shadow ray starts at x + ε·n on the light's side of the surface (n the unit
    `normals`, ε = eps × the scene's coordinate scale) so the surface that holds x does
    not shadow itself; without normals the start moves ε towards the light instead.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    if len(tri) == 0 or len(points) == 0:
        return np.zeros(len(points), dtype=bool)
    return shadow_rays_blocked(tri, points, light, normals, eps, lambda start, d, **k: raycast(start, d, tri, **k))


def shadow_rays_blocked(tri: np.ndarray, points: np.ndarray, light: Light, normals, eps: float, cast) -> np.ndarray:
    """`occluded`'s answer with the ray cast `cast(start, unit directions, t_max=...)` →
    (t, index) of one's choice: every triangle here, a BVH's (clrays.reference.bvh_queries)."""
    lpos = light_position(light)
    to_light = -propagation_direction(light, points)
    offset = eps * _scale(tri, points, lpos if lpos is not None else 0.0)
    if normals is None:
        start = points + offset * to_light
    else:
        nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
        side = np.where(dot(nrm, to_light) >= 0, 1.0, -1.0)
        start = points + (offset * side)[:, None] * nrm
    if lpos is None:
        t, _ = cast(start, to_light)
    else:
        d = lpos - start
        dist = np.linalg.norm(d, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            t, _ = cast(start, d / dist[:, None], t_max=dist)
    return np.isfinite(t)


def shadow_halfspaces(light: Light, triangles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each triangle's shadow volume as 4 half-spaces K·x + c ≥ 0 (K unit).

    Point / spot light l, triangle p0 p1 p2 with normal n = (p1 - p0)×(p2 - p0):
      beyond the plane, away from the light:  -sgn(n·(l - p0))·n·(x - p0) ≥ 0
      inside the plane through l, p_i, p_{i+1}: m_i = (p_i - l)×(p_{i+1} - l), oriented so
      that p_{i+2} is inside. The three side planes meet at l and bound the single nappe
      {l + Σ λ_i (p_i - l), λ ≥ 0}, so the volume is the frustum behind the triangle.
    Directional light w: beyond the plane is sgn(n·w)·n·(x - p0) ≥ 0, and the side planes
      hold the edge and w: m_i = (p_{i+1} - p_i)×w, oriented towards p_{i+2}.
    Triangles whose plane (nearly) contains the light, or parallel to a directional light,
    cast a shadow of zero volume and are dropped, as are zero-area ones.
    Returns (K (T', 4, 3), c (T', 4), kept triangle indices (T',)).
    """
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    nrm = triangle_normals(tri)
    n_len = np.linalg.norm(nrm, axis=1)
    p0 = tri[:, 0]
    nxt = np.roll(tri, -1, axis=1)  # p_{i+1}
    opp = np.roll(tri, -2, axis=1)  # p_{i+2}
    lpos = light_position(light)
    scale = _scale(tri, lpos if lpos is not None else 0.0)
    if lpos is None:
        w = np.asarray(light.direction, dtype=np.float64)
        w = w / np.linalg.norm(w)
        side = dot(nrm, w)
        keep = (np.abs(side) > _DEGENERATE_REL * n_len) & (n_len > 0)
        sgn = np.sign(side)
        k0 = sgn[:, None] * nrm
        m = np.cross(nxt - tri, w)
        orient = np.sign(dot(m, opp - tri))
        km = orient[..., None] * m
        cm = -dot(km, tri)
    else:
        side = dot(nrm, lpos - p0)
        keep = (np.abs(side) > _DEGENERATE_REL * scale * n_len) & (n_len > 0)
        sgn = -np.sign(side)
        k0 = sgn[:, None] * nrm
        m = np.cross(tri - lpos, nxt - lpos)
        orient = np.sign(dot(m, opp - lpos))
        km = orient[..., None] * m
        cm = -dot(km, np.broadcast_to(lpos, km.shape))
    c0 = -dot(k0, p0)
    K = np.concatenate([k0[:, None, :], km], axis=1)
    c = np.concatenate([c0[:, None], cm], axis=1)
    k_len = np.linalg.norm(K, axis=2)
    keep &= np.all(k_len > 0, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        K, c = K / k_len[..., None], c / k_len
    kept = np.flatnonzero(keep)
    return K[kept], c[kept], kept


def _clip(origins, dirs, lo, hi, K, c) -> tuple[np.ndarray, np.ndarray]:
    """Clip s ∈ [lo, hi] of rays o + s·v against every volume's 4 half-spaces.

    Each half-space K·x + c ≥ 0 becomes α + β·s ≥ 0 with α = K·o + c, β = K·v: β > 0
    raises the start to -α/β, β < 0 lowers the end to -α/β, β = 0 keeps all (α ≥ 0) or
    nothing. Returns (start, end), each (R, T); an empty clip has start ≥ end.
    """
    r, t = len(dirs), len(K)
    kf = K.reshape(-1, 3).T  # (3, 4T)
    alpha = (origins @ kf).reshape(-1, t, 4) + c  # (1 or R, T, 4)
    beta = (dirs @ kf).reshape(r, t, 4)
    with np.errstate(divide="ignore", invalid="ignore"):
        root = -alpha / beta
    start = np.max(np.where(beta > 0, root, -np.inf), axis=2)
    end = np.min(np.where(beta < 0, root, np.inf), axis=2)
    never = np.any((beta == 0) & (alpha < 0), axis=2)
    start = np.maximum(start, lo[:, None])
    end = np.where(never, -np.inf, np.minimum(end, hi[:, None]))
    return start, end


def _lit_from_clips(lo, hi, start, end) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Complement of the union of [start, end) within [lo, hi], flattened to (ray, a, b).

    Empty clips become (hi, hi); a sentinel (hi, hi) is appended to every ray; after sorting
    by start, the gap between the running max of the previous ends and each start is lit.
    The sentinel's gap is the tail [max end, hi], so no separate last step is needed.
    """
    empty = ~(end > start)
    start = np.where(empty, hi[:, None], start)
    end = np.where(empty, hi[:, None], end)
    start = np.concatenate([start, hi[:, None]], axis=1)
    end = np.concatenate([end, hi[:, None]], axis=1)
    order = np.argsort(start, axis=1, kind="stable")
    start = np.take_along_axis(start, order, axis=1)
    end = np.maximum.accumulate(np.take_along_axis(end, order, axis=1), axis=1)
    prev_end = np.concatenate([lo[:, None], np.maximum(end[:, :-1], lo[:, None])], axis=1)
    ray, col = np.nonzero(start > prev_end)
    return ray, prev_end[ray, col], start[ray, col]


def _ray_range(light: Light, origins, dirs, D) -> tuple[np.ndarray, np.ndarray]:
    """The part of [0, D] the light can reach at all: all of it, or a spot light's cone."""
    n = len(dirs)
    D = np.broadcast_to(np.asarray(D, dtype=np.float64), (n,))
    if isinstance(light, SpotLight):
        return cone_interval(light, origins, dirs, np.zeros(n), D)
    return np.zeros(n), D.copy()


def lit_intervals(origins, dirs, D, light: Light, triangles, halfspaces=None, lamp_radius: float = 0.0,
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lit set of each ray's [0, D], as flattened disjoint intervals (ray, a, b).

    lit = (cone ∩ [0, D]) \\ (⋃_triangles shadow volume ∪ lamp), the cone being everything
    except for a spot light and the lamp the ball of `lamp_radius` around a point or spot
    light, which holds no medium (`radiometry.lamp_radius`; 0: none). `halfspaces` may pass
    a precomputed `shadow_halfspaces(light, triangles)`.
    Rays are chunked so the (rays × triangles) temporaries stay near 100 MB; intervals come
    out sorted by ray, then by a.
    """
    dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    n = len(dirs)
    origins = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    lo, hi = _ray_range(light, origins, dirs, D)
    K, c, _ = halfspaces if halfspaces is not None else shadow_halfspaces(light, triangles)
    rc = max(1, BUDGET_BYTES // (CLIP_PAIR_BYTES * (len(K) + 1)))
    rays, a_all, b_all = [], [], []
    for r in range(0, n, rc):
        sl = slice(r, r + rc)
        o = origins if len(origins) == 1 else origins[sl]
        if len(K):
            start, end = _clip(o, dirs[sl], lo[sl], hi[sl], K, c)
        else:
            start = end = np.zeros((len(lo[sl]), 0))
        if lamp_radius > 0:
            ball_start, ball_end = lamp_interval(light, o, dirs[sl], lamp_radius)
            start = np.concatenate([start, ball_start[:, None]], axis=1)
            end = np.concatenate([end, ball_end[:, None]], axis=1)
        ray, a, b = _lit_from_clips(lo[sl], hi[sl], start, end)
        rays.append(ray + r)
        a_all.append(a)
        b_all.append(b)
    if not rays:
        return np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0)
    return np.concatenate(rays), np.concatenate(a_all), np.concatenate(b_all)


def shading_normals(geometry, tri: np.ndarray, ids: np.ndarray, x: np.ndarray, face: np.ndarray) -> np.ndarray:
    """Unit shading normals at hit points x on triangles `ids`: the face normal `face`, or on
    a smooth triangle its vertex normals weighted by the barycentric coordinates of x
    (clamped to the triangle, as the device does), falling back to `face` where they cancel."""
    shading = face.copy()
    smooth = np.flatnonzero(np.asarray(geometry.smooth)[ids])
    if len(smooth) == 0:
        return shading
    corners = tri[ids[smooth]]
    v0, e1, e2 = corners[:, 0], corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    rel = x[smooth] - v0
    d11, d12, d22 = dot(e1, e1), dot(e1, e2), dot(e2, e2)
    r1, r2 = dot(rel, e1), dot(rel, e2)
    denom = d11 * d22 - d12 * d12
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.clip((d22 * r1 - d12 * r2) / denom, 0.0, 1.0)
        v = np.clip((d11 * r2 - d12 * r1) / denom, 0.0, 1.0)
    over = u + v > 1.0
    u[over], v[over] = u[over] / (u + v)[over], v[over] / (u + v)[over]
    vertex_normals = np.asarray(geometry.normals, dtype=np.float64)[ids[smooth]]
    n = (1.0 - u - v)[:, None] * vertex_normals[:, 0] + u[:, None] * vertex_normals[:, 1] \
        + v[:, None] * vertex_normals[:, 2]
    length = np.linalg.norm(n, axis=1)
    good = np.isfinite(length) & (length > 0.0) & (denom > 0.0)
    shading[smooth[good]] = n[good] / length[good, None]
    return shading
