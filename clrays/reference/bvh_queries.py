"""The `exact` reference's three geometric queries on a BVH (docs/design.md §4.8, `exact`):
first hits of camera rays, shadow rays from surface points, and the lit set of each
camera ray. Each gives what `geometry.raycast`, `geometry.occluded` and
`geometry.lit_intervals` give against every triangle, at a cost that grows with the
triangles a query can touch instead of all of them.

A batched walk of `clrays.bvh` (float64 numpy, level by level over (query, node) pairs)
lists candidate triangles: those whose box, and every box above it, passes a conservative
test. The float64 arithmetic of `geometry` then runs on the (query, triangle) pairs only.

- A ray's candidates: the boxes it crosses (slab test) within [0, t_max].
- The lit set of the camera ray's segment P0–P1: a triangle can shadow a point x of it
  only if it crosses the path from x to the light, and these paths fill the planar
  triangle (light, P0, P1) — for a directional light, the parallelogram swept from P0–P1
  back along the light's direction to the scene's bounds. A separating-axis test
  (the box's 3 axes, the polygon's normal, the products of box axes and polygon edges)
  keeps the boxes that polygon may meet.

Boxes are padded by PAD_REL of the scene's coordinate scale (and, against a polygon, of
the polygon's, whose far corner may lie well outside the scene), far above the float64
rounding of the tests, so a triangle that the all-triangles arithmetic would count is
never left out; an extra candidate changes nothing (its clip is empty, its hit is not
the nearest), so the images are those of the all-triangles code up to rounding.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..bvh import Bvh, build_bvh
from ..physics.geometry import (_SHADOW_OFFSET_REL, _T_MIN_REL, _lit_from_clips, _ray_range, _scale, dot,
                                shadow_rays_blocked, triangle_hits)
from ..physics.radiometry import lamp_interval, light_position
from ..scene.model import Light

#: Box padding, relative to the scene's coordinate scale (module docstring).
PAD_REL = 1e-9
#: Float64 elements of one dense block of clip intervals (rays × their most candidates).
_DENSE_ELEMENTS = 2_000_000


@dataclass
class SceneBvh:
    """A scene's triangles (float64), their BVH and the per-triangle data the queries reuse."""

    triangles: np.ndarray  # (T, 3, 3) float64
    bvh: Bvh
    node_lo: np.ndarray  # (T - 1, 3) float64, padded
    node_hi: np.ndarray
    tri_lo: np.ndarray  # (T, 3) float64, padded
    tri_hi: np.ndarray
    scale: float  # largest |coordinate| of the triangles (geometry._scale)

    @classmethod
    def build(cls, triangles) -> "SceneBvh":
        tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
        bvh = build_bvh(tri)
        scale = _scale(tri)
        pad = PAD_REL * scale
        bounds = bvh.node_bounds.astype(np.float64).reshape(-1, 2, 4)
        return cls(tri, bvh, bounds[:, 0, :3] - pad, bounds[:, 1, :3] + pad,
                   tri.min(axis=1) - pad, tri.max(axis=1) + pad, scale)

    def candidates(self, count: int, meets_boxes) -> tuple[np.ndarray, np.ndarray]:
        """(query, triangle) pairs, int64 each: the triangles whose own box and every BVH
        box above them pass `meets_boxes(queries, lo, hi) -> bool` for queries 0 … count - 1."""
        if len(self.triangles) == 0 or count == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        query = np.arange(count, dtype=np.int64)
        if self.bvh.root < 0:  # one triangle, no internal node
            keep = meets_boxes(query, self.tri_lo[[0] * count], self.tri_hi[[0] * count])
            return query[keep], np.zeros(int(keep.sum()), np.int64)
        node = np.zeros(count, dtype=np.int64)
        children = self.bvh.node_children.astype(np.int64)
        found_query, found_tri = [], []
        while len(query):
            keep = meets_boxes(query, self.node_lo[node], self.node_hi[node])
            query = np.repeat(query[keep], 2)
            child = children[node[keep]].ravel()
            leaf = child < 0
            leaf_query, leaf_tri = query[leaf], -child[leaf] - 1
            hit = meets_boxes(leaf_query, self.tri_lo[leaf_tri], self.tri_hi[leaf_tri])
            found_query.append(leaf_query[hit])
            found_tri.append(leaf_tri[hit])
            query, node = query[~leaf], child[~leaf]
        return np.concatenate(found_query), np.concatenate(found_tri)

    # --- rays ---------------------------------------------------------------------------

    def _ray_candidates(self, origins, dirs, t_max) -> tuple[np.ndarray, np.ndarray]:
        with np.errstate(divide="ignore", over="ignore"):  # ±inf for a zero or subnormal component: the slabs allow it
            inv_dir = 1.0 / dirs

        def meets_boxes(q, lo, hi):
            o, inv = origins[q], inv_dir[q]
            with np.errstate(invalid="ignore"):  # 0·inf where a ray lies in a slab's plane
                t0, t1 = (lo - o) * inv, (hi - o) * inv
            # fmin / fmax drop those NaNs: such an axis does not bound the ray.
            near = np.fmax(np.max(np.fmin(t0, t1), axis=1, initial=-np.inf), 0.0)
            far = np.fmin(np.min(np.fmax(t0, t1), axis=1, initial=np.inf), t_max[q])
            return near <= far

        return self.candidates(len(dirs), meets_boxes)

    def _hits(self, origins, dirs, t_min, t_max, ray, tri_index) -> np.ndarray:
        """t of each (ray, triangle) pair, inf where it misses: geometry.raycast's arithmetic."""
        tri = self.triangles[tri_index]
        p0 = tri[:, 0]
        e1, e2 = tri[:, 1] - p0, tri[:, 2] - p0
        n_len = np.linalg.norm(np.cross(e1, e2), axis=1)
        t, ok = triangle_hits(origins[ray], dirs[ray], p0, e1, e2, np.linalg.norm(dirs, axis=1)[ray], n_len)
        ok &= (t > t_min[ray]) & (t < t_max[ray])
        return np.where(ok, t, np.inf)

    def raycast(self, origins, dirs, t_max=np.inf, t_min=None) -> tuple[np.ndarray, np.ndarray]:
        """geometry.raycast on the BVH: (t, triangle index) of each ray's first hit, inf and
        -1 for a miss; ties keep the lower triangle index. t_min defaults to raycast's,
        from the scale of every triangle of the scene (not only the candidates)."""
        dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
        n = len(dirs)
        origins = np.ascontiguousarray(np.broadcast_to(np.asarray(origins, dtype=np.float64), (n, 3)))
        t_max = np.broadcast_to(np.asarray(t_max, dtype=np.float64), (n,))
        t_best = np.full(n, np.inf)
        idx_best = np.full(n, -1, dtype=np.int64)
        if n == 0 or len(self.triangles) == 0:
            return t_best, idx_best
        if t_min is None:
            t_min = _T_MIN_REL * _scale(self.triangles, origins) / np.maximum(np.linalg.norm(dirs, axis=1), 1e-300)
        t_min = np.broadcast_to(np.asarray(t_min, dtype=np.float64), (n,))
        ray, tri_index = self._ray_candidates(origins, dirs, t_max)
        t = self._hits(origins, dirs, t_min, t_max, ray, tri_index)
        np.minimum.at(t_best, ray, t)
        nearest = np.isfinite(t) & (t == t_best[ray])
        lowest = np.full(n, np.iinfo(np.int64).max)
        np.minimum.at(lowest, ray[nearest], tri_index[nearest])
        idx_best = np.where(np.isfinite(t_best), lowest, -1)
        return t_best, idx_best

    def occluded(self, points, light: Light, normals=None, eps: float = _SHADOW_OFFSET_REL) -> np.ndarray:
        """geometry.occluded on the BVH (same shadow-ray start, offset and range)."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if len(self.triangles) == 0 or len(points) == 0:
            return np.zeros(len(points), dtype=bool)
        return shadow_rays_blocked(self.triangles, points, light, normals, eps, self.raycast)

    # --- lit sets -------------------------------------------------------------------------

    def _polygon_candidates(self, polygons: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(polygon, triangle) pairs for planar convex polygons (N, k, 3): the boxes that pass
        the separating-axis test (module docstring)."""
        normal = np.cross(polygons[:, 1] - polygons[:, 0], polygons[:, 2] - polygons[:, 0])
        edges = np.roll(polygons, -1, axis=1) - polygons  # (N, k, 3)
        # Box axis j × edge: the three products, (N, 3·k, 3).
        zero = np.zeros(edges.shape[:2])
        axes = np.concatenate([np.stack([zero, -edges[..., 2], edges[..., 1]], axis=-1),
                               np.stack([edges[..., 2], zero, -edges[..., 0]], axis=-1),
                               np.stack([-edges[..., 1], edges[..., 0], zero], axis=-1)], axis=1)
        poly_lo, poly_hi = polygons.min(axis=1), polygons.max(axis=1)
        poly_pad = PAD_REL * np.abs(polygons).max(axis=(1, 2))
        poly_lo, poly_hi = poly_lo - poly_pad[:, None], poly_hi + poly_pad[:, None]
        # The polygon's side of every axis, once: its plane's offset and its extent along
        # each edge axis; a box then costs one projection of its centre per axis.
        plane = dot(normal, polygons[:, 0])
        extent = np.einsum("nak,nvk->nav", axes, polygons)
        extent_lo, extent_hi = extent.min(axis=2), extent.max(axis=2)
        abs_normal, abs_axes = np.abs(normal), np.abs(axes)

        def meets_boxes(q, lo, hi):
            # Cheapest first: the box axes, then the plane, then the edge axes on what is left.
            keep = np.all(poly_lo[q] <= hi, axis=1) & np.all(poly_hi[q] >= lo, axis=1)
            where = np.flatnonzero(keep)
            qk = q[where]
            center, half = (lo[where] + hi[where]) / 2, (hi[where] - lo[where]) / 2 + poly_pad[qk, None]
            plane_ok = np.abs(plane[qk] - dot(normal[qk], center)) <= dot(abs_normal[qk], half)
            where, center, half, qk = where[plane_ok], center[plane_ok], half[plane_ok], qk[plane_ok]
            at = np.einsum("mak,mk->ma", axes[qk], center)
            radius = np.einsum("mak,mk->ma", abs_axes[qk], half)
            edge_ok = np.all((extent_lo[qk] - at <= radius) & (extent_hi[qk] - at >= -radius), axis=1)
            out = np.zeros(len(q), dtype=bool)
            out[where[edge_ok]] = True
            return out

        return self.candidates(len(polygons), meets_boxes)

    def _shadow_polygons(self, light: Light, origins, dirs, lo, hi) -> np.ndarray:
        """The region of every path from a point of [lo, hi] on each ray to the light."""
        near = origins + lo[:, None] * dirs
        far = origins + hi[:, None] * dirs
        lpos = light_position(light)
        if lpos is not None:
            return np.stack([np.broadcast_to(lpos, near.shape), near, far], axis=1)
        w = np.asarray(light.direction, dtype=np.float64)
        w = w / np.linalg.norm(w)
        # Back along w until past every triangle: no vertex lies further than `reach` before
        # a point of the segment (the corners of the triangles' box bound (x - y)·w).
        corners = np.stack(np.meshgrid(*zip(self.tri_lo.min(axis=0), self.tri_hi.max(axis=0)),
                                       indexing="ij"), axis=-1).reshape(-1, 3)
        reach = np.maximum(np.maximum((near @ w)[:, None], (far @ w)[:, None]) - (corners @ w)[None, :], 0.0)
        back = (reach.max(axis=1) + PAD_REL * self.scale)[:, None] * w
        return np.stack([near, far, far - back, near - back], axis=1)

    def lit_intervals(self, origins, dirs, D, light: Light, halfspaces, lamp_radius: float = 0.0,
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """geometry.lit_intervals on the BVH: flattened disjoint lit intervals (ray, a, b),
        sorted by ray, then by a. `halfspaces` is `shadow_halfspaces(light, triangles)`."""
        dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
        n = len(dirs)
        origins = np.ascontiguousarray(np.broadcast_to(np.asarray(origins, dtype=np.float64), (n, 3)))
        lo, hi = _ray_range(light, origins, dirs, D)
        K, c, kept = halfspaces
        row_of = np.full(len(self.triangles), -1, dtype=np.int64)
        row_of[kept] = np.arange(len(kept))
        live = np.flatnonzero(hi > lo) if len(kept) else np.zeros(0, dtype=np.int64)
        pair_ray, pair_tri = np.zeros(0, np.int64), np.zeros(0, np.int64)
        if len(live):
            pair_ray, pair_tri = self._polygon_candidates(self._shadow_polygons(light, origins[live], dirs[live],
                                                                                lo[live], hi[live]))
        pair_ray = live[pair_ray]
        row = row_of[pair_tri]
        pair_ray, row = pair_ray[row >= 0], row[row >= 0]
        start, end = _clip_pairs(origins[pair_ray], dirs[pair_ray], lo[pair_ray], hi[pair_ray], K[row], c[row])
        # Only non-empty clips matter (_lit_from_clips treats an empty one as none).
        nonempty = end > start
        pair_ray, start, end = pair_ray[nonempty], start[nonempty], end[nonempty]
        if lamp_radius > 0:
            ball_start, ball_end = lamp_interval(light, origins, dirs, lamp_radius)
            pair_ray = np.concatenate([pair_ray, np.arange(n)])
            start, end = np.concatenate([start, ball_start]), np.concatenate([end, ball_end])
        return _lit_from_pairs(n, lo, hi, pair_ray, start, end)


def _clip_pairs(o, v, lo, hi, K, c) -> tuple[np.ndarray, np.ndarray]:
    """geometry._clip for pairs: ray o + s·v, s ∈ [lo, hi], against one volume's 4
    half-spaces K·x + c ≥ 0 (K (M, 4, 3), c (M, 4)). Returns (start, end), each (M,)."""
    alpha = np.einsum("mhk,mk->mh", K, o) + c
    beta = np.einsum("mhk,mk->mh", K, v)
    with np.errstate(divide="ignore", invalid="ignore"):
        root = -alpha / beta
    start = np.max(np.where(beta > 0, root, -np.inf), axis=1)
    end = np.min(np.where(beta < 0, root, np.inf), axis=1)
    never = np.any((beta == 0) & (alpha < 0), axis=1)
    start = np.maximum(start, lo)
    end = np.where(never, -np.inf, np.minimum(end, hi))
    return start, end


def _lit_from_pairs(n: int, lo, hi, ray, start, end) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """geometry._lit_from_clips for ragged clips: each ray's [start, end) pairs set into a
    dense (rays × most pairs) block, padded with empty clips, rays of like counts together."""
    order = np.argsort(ray, kind="stable")
    ray, start, end = ray[order], start[order], end[order]
    counts = np.bincount(ray, minlength=n)
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    column = np.arange(len(ray)) - first[ray]
    by_count = np.argsort(counts, kind="stable")
    out_ray, out_a, out_b = [], [], []
    i = 0
    while i < n:
        # As many rays as fit the budget at the widest of them (counts ascend along by_count).
        take = n - i
        while take > 64 and int(counts[by_count[i + take - 1]]) * take > _DENSE_ELEMENTS:
            take //= 2
        rays = np.sort(by_count[i:i + take])
        width = max(int(counts[rays].max()), 1)
        dense_start = np.full((len(rays), width), np.nan)
        dense_end = np.full((len(rays), width), np.nan)
        slot = np.full(n, -1, dtype=np.int64)
        slot[rays] = np.arange(len(rays))
        mine = slot[ray] >= 0
        dense_start[slot[ray[mine]], column[mine]] = start[mine]
        dense_end[slot[ray[mine]], column[mine]] = end[mine]
        # NaN padding: `end > start` is false, so _lit_from_clips makes it an empty clip.
        r, a, b = _lit_from_clips(lo[rays], hi[rays], dense_start, dense_end)
        out_ray.append(rays[r])
        out_a.append(a)
        out_b.append(b)
        i += take
    if not out_ray:
        return np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0)
    ray, a, b = np.concatenate(out_ray), np.concatenate(out_a), np.concatenate(out_b)
    order = np.lexsort((a, ray))
    return ray[order], a[order], b[order]


__all__ = ["SceneBvh", "PAD_REL"]
