"""`exact` with translucent objects (docs/design.md, "Translucent occluders: the light
side" and "Translucent surfaces: the camera side"), float64 on the host.

A scene with translucent objects splits its triangles into the opaque ones and the
translucent ones (any channel of `opacity` below 1), each with its own BVH
(`bvh_queries.SceneBvh`):

- Light side. The light reaching a point x is the unshadowed light times the product of
  (1 − α) over the translucent triangles between x and the light, and 0 if an opaque one
  is between. On a surface: one shadow ray, all its translucent crossings. Along a camera
  ray: each translucent triangle's shadow volume meets the ray in one interval (as an
  opaque one's does, `geometry.shadow_halfspaces`); the opaque lit set is cut at those
  intervals' ends, and each piece carries the product of (1 − α) of the intervals that
  cover it: a piecewise-constant transmittance.
- Camera side. With translucent hits z_1 < … < z_n in front of the first opaque hit D
  and T(s) = Π_{z_k < s} (1 − α_k), the pixel is

      ∫_0^D T dL + Σ_k T(z_k⁻)·α_k·e^{−σt z_k}·S_k + T(D)·e^{−σt D}·S_D

  (S the surfaces' radiance, the background for a ray that hits nothing). T is piecewise
  constant too, so the first term is each lit piece's in-scattering times its T: the
  light's transmittance and the camera's cut the ray at their ends together.

With no fog and one pane in front of a wall this is α·S_pane + (1 − α)·S_wall.
"""
from __future__ import annotations

import math

import numpy as np

from ..physics import radiometry
from .bvh_queries import SceneBvh, _clip_pairs
from ..physics.geometry import (_SHADOW_OFFSET_REL, _T_MIN_REL, _ray_range, _scale, dot, shading_normals,
                                shadow_halfspaces, triangle_normals)
from ..physics.light_texture import light_texture
from ..physics.radiometry import light_position, propagation_direction, rgb
from ..scene.camera import from_ray_starts, ray_starts
from .media import eye_transmittance, in_scatter_lit, incident_through, near_gain
from ..scene.model import Light, Scene


class AllPairs(SceneBvh):
    """SceneBvh whose candidates are every (query, triangle) pair: the yardstick of the
    BVH path (`exact_pixels(..., bvh=False)`), as `exact.AllTriangles` is for opaque scenes."""

    def candidates(self, count, meets_boxes):
        query = np.repeat(np.arange(count, dtype=np.int64), len(self.triangles))
        return query, np.tile(np.arange(len(self.triangles), dtype=np.int64), count)


class TranslucentQueries:
    """The queries of `exact` on a scene with translucent objects: its opaque and its
    translucent triangles, each on a BVH (or, `bvh=False`, tested all)."""

    def __init__(self, geometry, bvh: bool = True):
        tri = np.asarray(geometry.triangles, dtype=np.float64).reshape(-1, 3, 3)
        opacity = geometry.opacity_or_ones()
        see_through = np.any(opacity < 1.0, axis=1)
        self.opaque_index = np.flatnonzero(~see_through)
        self.translucent_index = np.flatnonzero(see_through)
        kind = SceneBvh if bvh else AllPairs
        self.opaque = kind.build(tri[self.opaque_index])
        self.translucent = kind.build(tri[self.translucent_index])
        self.clear = 1.0 - opacity[self.translucent_index]  # (T', 3): what each translucent triangle lets through
        self.scale = _scale(tri)

    def halfspaces(self, light: Light):
        """(opaque, translucent) shadow volumes of `light` (`geometry.shadow_halfspaces`)."""
        return (shadow_halfspaces(light, self.opaque.triangles), shadow_halfspaces(light, self.translucent.triangles))

    def first_opaque_hit(self, origins, dirs, t_max):
        """(t, scene triangle index) of the first opaque hit, inf and -1 for none."""
        t, index = self.opaque.raycast(origins, dirs, t_max=t_max, t_min=self._t_min(origins, dirs))
        return t, np.where(index >= 0, self.opaque_index[np.maximum(index, 0)], -1)

    def crossings(self, origins, dirs, t_max):
        """Every translucent triangle each ray crosses within (t_min, t_max): (ray, t,
        translucent triangle index), sorted by ray, then t."""
        dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
        n = len(dirs)
        origins = np.ascontiguousarray(np.broadcast_to(np.asarray(origins, dtype=np.float64), (n, 3)))
        t_max = np.broadcast_to(np.asarray(t_max, dtype=np.float64), (n,))
        if n == 0 or len(self.translucent.triangles) == 0:
            return np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64)
        ray, tri = self.translucent._ray_candidates(origins, dirs, t_max)
        t = self.translucent._hits(origins, dirs, self._t_min(origins, dirs), t_max, ray, tri)
        hit = np.isfinite(t)
        ray, t, tri = ray[hit], t[hit], tri[hit]
        order = np.lexsort((t, ray))
        return ray[order], t[order], tri[order]

    def _t_min(self, origins, dirs):
        # geometry.raycast's default, from the whole scene's scale, so the split changes nothing.
        return _T_MIN_REL * _scale(self.scale, origins) / np.maximum(np.linalg.norm(dirs, axis=1), 1e-300)

    def transmittance_to_light(self, points, light: Light, normals) -> np.ndarray:
        """(N, 3): what reaches each surface point of the light, as a fraction: 0 behind an
        opaque triangle, else the product of (1 − α) of the translucent ones crossed. The
        shadow ray leaves as `geometry.occluded`'s does (the surface's own side facing the light)."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        n = len(points)
        lpos = light_position(light)
        to_light = -propagation_direction(light, points)
        offset = _SHADOW_OFFSET_REL * _scale(self.scale, points, lpos if lpos is not None else 0.0)
        nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
        side = np.where(dot(nrm, to_light) >= 0, 1.0, -1.0)
        start = points + (offset * side)[:, None] * nrm
        if lpos is None:
            dirs, dist = to_light, np.full(n, np.inf)
        else:
            d = lpos - start
            dist = np.linalg.norm(d, axis=1)
            with np.errstate(invalid="ignore", divide="ignore"):
                dirs = d / dist[:, None]
        out = np.ones((n, 3))
        t, _ = self.opaque.raycast(start, dirs, t_max=dist, t_min=self._t_min(start, dirs))
        out[np.isfinite(t)] = 0.0
        ray, _, tri = self.crossings(start, dirs, dist)
        np.multiply.at(out, ray, self.clear[tri])
        return out

    def lit_pieces(self, origins, dirs, D, light: Light, halfspaces, lamp_radius: float,
                   camera_events=None):
        """The lit set of each ray's [0, D] as pieces (ray, a, b, transmittance (M, 3)):
        the opaque lit intervals cut where translucent shadows begin and end, each piece
        with the product of (1 − α) of the translucent shadows covering it, and times the
        camera's transmittance when `camera_events` (ray, t, clear (F, 3)) lists the
        translucent surfaces the camera ray crosses. Pieces that pass nothing are dropped."""
        dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
        n = len(dirs)
        origins = np.ascontiguousarray(np.broadcast_to(np.asarray(origins, dtype=np.float64), (n, 3)))
        opaque_halfspaces, translucent_halfspaces = halfspaces
        lit_ray, lit_a, lit_b = self.opaque.lit_intervals(origins, dirs, D, light, opaque_halfspaces,
                                                          lamp_radius=lamp_radius)
        shade_ray, shade_a, shade_b, shade_tri = self._translucent_shadows(origins, dirs, D, light,
                                                                           translucent_halfspaces)
        cam_ray, cam_t, cam_clear = camera_events if camera_events is not None else (
            np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 3)))
        events = _Events()
        events.add(lit_ray, lit_a, lit=1)
        events.add(lit_ray, lit_b, lit=-1)
        events.add(shade_ray, shade_a, clear=self.clear[shade_tri])
        events.add(shade_ray, shade_b, clear=self.clear[shade_tri], remove=True)
        events.add(cam_ray, cam_t, clear=cam_clear)  # from z_k on, for the rest of the ray
        return events.pieces()

    def _translucent_shadows(self, origins, dirs, D, light, halfspaces):
        """(ray, start, end, translucent triangle) of each translucent shadow volume that
        meets a ray's [0, D] (within a spot light's cone): SceneBvh.lit_intervals' clipping."""
        K, c, kept = halfspaces
        lo, hi = _ray_range(light, origins, dirs, D)
        live = np.flatnonzero(hi > lo) if len(kept) else np.zeros(0, dtype=np.int64)
        if len(live) == 0:
            return np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros(0, np.int64)
        bvh = self.translucent
        pair_ray, pair_tri = bvh._polygon_candidates(bvh._shadow_polygons(light, origins[live], dirs[live],
                                                                          lo[live], hi[live]))
        pair_ray = live[pair_ray]
        row_of = np.full(len(bvh.triangles), -1, dtype=np.int64)
        row_of[kept] = np.arange(len(kept))
        row = row_of[pair_tri]
        keep = row >= 0
        pair_ray, pair_tri, row = pair_ray[keep], pair_tri[keep], row[keep]
        start, end = _clip_pairs(origins[pair_ray], dirs[pair_ray], lo[pair_ray], hi[pair_ray], K[row], c[row])
        nonempty = end > start
        return pair_ray[nonempty], start[nonempty], end[nonempty], pair_tri[nonempty]


class _Events:
    """Changes along rays, swept in order: +1/−1 to the lit count, and factors (1 − α) per
    channel that start (or, `remove`, end) multiplying the transmittance. A factor of 0 is
    counted rather than logged, so a channel it closes is exactly 0."""

    def __init__(self):
        self.ray, self.at, self.lit, self.log, self.zeros = [], [], [], [], []

    def add(self, ray, at, lit: int = 0, clear=None, remove: bool = False):
        m = len(ray)
        self.ray.append(np.asarray(ray, dtype=np.int64))
        self.at.append(np.asarray(at, dtype=np.float64))
        self.lit.append(np.full(m, lit, dtype=np.int64))
        sign = -1.0 if remove else 1.0
        if clear is None:
            self.log.append(np.zeros((m, 3)))
            self.zeros.append(np.zeros((m, 3), dtype=np.int64))
        else:
            clear = np.asarray(clear, dtype=np.float64).reshape(m, 3)
            closed = clear <= 0.0
            with np.errstate(divide="ignore"):
                self.log.append(sign * np.where(closed, 0.0, np.log(np.where(closed, 1.0, clear))))
            self.zeros.append(int(sign) * closed.astype(np.int64))

    def pieces(self):
        ray, at = np.concatenate(self.ray), np.concatenate(self.at)
        lit, log, zeros = np.concatenate(self.lit), np.concatenate(self.log), np.concatenate(self.zeros)
        order = np.lexsort((at, ray))
        ray, at, lit, log, zeros = ray[order], at[order], lit[order], log[order], zeros[order]
        # Running sums restarted at each ray's first event (a ray's factors need not end).
        first = np.flatnonzero(np.r_[True, ray[1:] != ray[:-1]]) if len(ray) else np.zeros(0, np.int64)
        start_of = np.repeat(first, np.diff(np.r_[first, len(ray)]))

        def running(values):
            total = np.cumsum(values, axis=0)
            before = np.concatenate([np.zeros((1,) + values.shape[1:], values.dtype), total])[start_of]
            return total - before

        lit_now, log_now, zeros_now = running(lit), running(log), running(zeros)
        # The state after event i holds until event i + 1 of the same ray.
        piece = np.flatnonzero((ray[:-1] == ray[1:]) & (at[1:] > at[:-1]) & (lit_now[:-1] > 0))
        transmittance = np.exp(log_now[piece]) * (zeros_now[piece] == 0)
        passes = np.any(transmittance > 0.0, axis=1)
        piece, transmittance = piece[passes], transmittance[passes]
        return ray[piece], at[piece], at[piece + 1], transmittance


def _camera_transmittance(n: int, ray, clear):
    """For crossings sorted by ray then depth: T before each (F, 3) and T past all of a
    ray's (n, 3), products of (1 − α)."""
    before = np.ones((len(ray), 3))
    after = np.ones((n, 3))
    # Exclusive running product per ray: few crossings per ray, so one pass per depth rank.
    first = np.flatnonzero(np.r_[True, ray[1:] != ray[:-1]]) if len(ray) else np.zeros(0, np.int64)
    rank = np.arange(len(ray)) - np.repeat(first, np.diff(np.r_[first, len(ray)]))
    for k in range(int(rank.max()) + 1 if len(rank) else 0):
        at_k = np.flatnonzero(rank == k)
        before[at_k] = after[ray[at_k]]
        after[ray[at_k]] *= clear[at_k]
    return before, after


def _surface_radiance(scene: Scene, queries: TranslucentQueries, prepared, x, dirs, tri_index) -> np.ndarray:
    """albedo/π × irradiance (M, 3) at hit points x of rays `dirs` on scene triangles
    `tri_index`: `exact._radiance`'s surface term with the light's transmittance in place
    of its binary shadow ray."""

    tri = np.asarray(scene.geometry.triangles, dtype=np.float64).reshape(-1, 3, 3)
    nrm = triangle_normals(tri[tri_index])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    shading = shading_normals(scene.geometry, tri, tri_index, x, nrm)
    facing = np.where(dot(nrm, dirs) > 0, -1.0, 1.0)[:, None]
    nrm *= facing
    shading *= facing
    irradiance = np.zeros((len(x), 3))
    for light, _ in prepared:
        to_light = -propagation_direction(light, x)
        # Unlit where the surface itself turns away (reference/exact.py, turned_away on the device).
        cos_l = np.where(dot(nrm, to_light) > 0.0, np.maximum(0.0, dot(shading, to_light)), 0.0)
        lin = incident_through(light, scene.medium, x) * cos_l[:, None] * light_texture(light, x)
        lit = np.flatnonzero(np.any(lin > 0, axis=1))
        if len(lit):
            lin[lit] *= queries.transmittance_to_light(x[lit], light, nrm[lit])
        irradiance += lin
    return np.asarray(scene.geometry.albedo, dtype=np.float64)[tri_index] / math.pi * irradiance


def translucent_radiance(scene: Scene, eye: np.ndarray, dirs: np.ndarray, prepared, quad: dict,
                         queries: TranslucentQueries) -> np.ndarray:
    """Radiance (N, 3) of unit rays from the eye in a scene with translucent objects (the
    module docstring); `prepared` pairs each light with `queries.halfspaces(light)`."""
    n = len(dirs)
    medium = scene.medium
    sigma_s = rgb(medium.sigma_s)
    far = radiometry.effective_far(scene)
    t, idx = queries.first_opaque_hit(eye, dirs, far)
    hit = idx >= 0
    D = np.where(hit, t, far)
    starts = ray_starts(scene.camera, dirs)  # camera.near, as exact._radiance
    cam_ray, cam_t, cam_tri = queries.crossings(eye, dirs, D)
    cam_clear = queries.clear[cam_tri]
    before, after = _camera_transmittance(n, cam_ray, cam_clear)

    surf = np.zeros((n, 3))
    surf[~hit] = rgb(scene.background)
    hits = np.flatnonzero(hit)
    if len(hits):
        surf[hits] = _surface_radiance(scene, queries, prepared, eye + t[hits, None] * dirs[hits], dirs[hits],
                                       idx[hits])
    out = after * surf * eye_transmittance(medium, eye, dirs, D)
    if len(cam_ray):
        scene_tri = queries.translucent_index[cam_tri]
        films = _surface_radiance(scene, queries, prepared, eye + cam_t[:, None] * dirs[cam_ray], dirs[cam_ray],
                                  scene_tri)
        films *= before * (1.0 - cam_clear) * eye_transmittance(medium, eye, dirs[cam_ray], cam_t)
        for ch in range(3):
            out[:, ch] += np.bincount(cam_ray, weights=films[:, ch], minlength=n)
    if np.any(sigma_s > 0):
        for light, halfspaces in prepared:
            ray, a, b, transmittance = queries.lit_pieces(eye, dirs, D, light, halfspaces,
                                                          radiometry.lamp_radius(scene), (cam_ray, cam_t, cam_clear))
            ray, a, b, transmittance = from_ray_starts(ray, a, b, starts, transmittance)
            seg = in_scatter_lit(light, medium, eye, dirs[ray], a, b, quad) * transmittance
            for ch in range(3):
                out[:, ch] += np.bincount(ray, weights=seg[:, ch], minlength=n)
    if scene.camera.near > 0.0:  # light attenuated from each ray's start (as cl/shade.cl)
        out *= near_gain(medium, eye, dirs, starts, D)
    return out


__all__ = ["TranslucentQueries", "translucent_radiance"]


def film_pixels(scene: Scene, grow: bool = False) -> np.ndarray:
    """(H, W) bool: the pixels whose centre ray crosses a translucent surface before its
    first opaque hit (`grow`: and their 4-neighbours), to leave out or pick out of a
    comparison."""
    from ..scene.camera import primary_rays

    queries = TranslucentQueries(scene.geometry)
    eye = np.asarray(scene.camera.position, dtype=np.float64)
    dirs = primary_rays(scene.camera, scene.image, np.array([[0.5, 0.5]])).reshape(-1, 3)
    far = radiometry.effective_far(scene)
    t, _ = queries.first_opaque_hit(eye, dirs, far)
    ray, _, _ = queries.crossings(eye, dirs, np.where(np.isfinite(t), t, far))
    films = np.zeros(len(dirs), bool)
    films[ray] = True
    films = films.reshape(scene.image.height, scene.image.width)
    if not grow:
        return films
    grown = films.copy()
    grown[1:] |= films[:-1]
    grown[:-1] |= films[1:]
    grown[:, 1:] |= films[:, :-1]
    grown[:, :-1] |= films[:, 1:]
    return grown
