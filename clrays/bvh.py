"""A bounding volume hierarchy over the scene's triangles, built on the host in numpy:
a linear BVH (Morton codes of the triangle centroids sorted, then Karras's radix-tree
construction, "Maximizing parallelism in the construction of BVHs, octrees and k-d
trees", HPG 2012), its boxes refit bottom-up. Every step is a numpy pass over all nodes,
so a million triangles build in seconds (docs/design.md §4, visibility).

The device walks it in `cl/bvh.h` (shadow rays of the visibility stage). Layout, for
n ≥ 1 triangles, n - 1 internal nodes (node 0 is the root; one triangle: no node):

    node_bounds[2i], node_bounds[2i + 1]   float4 lo, hi of internal node i
    node_children[i]                       int2 (left, right): ≥ 0 an internal node,
                                           < 0 a leaf holding triangle -(child + 1)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Boxes grow by this fraction of the scene's extent (and of |coordinate|) on every side, so
#: that the float32 slab test on the device never misses a triangle lying on a box face.
BOX_PAD_REL = 1e-6


@dataclass
class Bvh:
    node_bounds: np.ndarray  # (2·(n - 1), 4) float32: lo, hi per internal node
    node_children: np.ndarray  # (n - 1, 2) int32
    triangle_count: int

    @property
    def root(self) -> int:
        """The first child to visit: node 0, or the single leaf of a one-triangle scene."""
        return 0 if self.triangle_count > 1 else -1


def _spread_bits(x: np.ndarray) -> np.ndarray:
    """10-bit integers with two zero bits inserted between their bits (for 30-bit Morton codes)."""
    x = x.astype(np.uint64) & np.uint64(0x3FF)
    x = (x | (x << np.uint64(16))) & np.uint64(0x030000FF)
    x = (x | (x << np.uint64(8))) & np.uint64(0x0300F00F)
    x = (x | (x << np.uint64(4))) & np.uint64(0x030C30C3)
    x = (x | (x << np.uint64(2))) & np.uint64(0x09249249)
    return x


def _leading_zeros(x: np.ndarray) -> np.ndarray:
    """Leading zero bits of uint64 values (64 for 0), exact: each 32-bit half goes through
    frexp, which is exact for integers below 2**53."""
    hi = (x >> np.uint64(32)).astype(np.float64)
    lo = (x & np.uint64(0xFFFFFFFF)).astype(np.float64)
    hi_bits = np.frexp(hi)[1]  # bit length: 0 for 0
    lo_bits = np.frexp(lo)[1]
    return np.where(hi_bits > 0, 32 - hi_bits, 64 - lo_bits).astype(np.int64)


def build_bvh(triangles: np.ndarray) -> Bvh:
    """The BVH of (T, 3, 3) triangles (any float dtype; boxes are rounded outwards to
    float32 and padded by BOX_PAD_REL)."""
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    n = len(tri)
    if n <= 1:
        return Bvh(np.zeros((0, 4), np.float32), np.zeros((0, 2), np.int32), n)
    tri_lo, tri_hi = tri.min(axis=1), tri.max(axis=1)
    centroid = (tri_lo + tri_hi) / 2
    lo, hi = centroid.min(axis=0), centroid.max(axis=0)
    cell = np.clip((centroid - lo) / np.maximum(hi - lo, 1e-300) * 1023.0, 0, 1023).astype(np.uint64)
    morton = (_spread_bits(cell[:, 0]) << np.uint64(2)) | (_spread_bits(cell[:, 1]) << np.uint64(1)) \
        | _spread_bits(cell[:, 2])
    order = np.argsort(morton, kind="stable")
    # Sorted position in the low bits makes every key unique (Karras §4's tie-break).
    keys = (morton[order] << np.uint64(32)) | np.arange(n, dtype=np.uint64)

    def delta(i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Common prefix length of keys i and j; -1 where j is outside [0, n)."""
        inside = (j >= 0) & (j < n)
        jj = np.clip(j, 0, n - 1)
        return np.where(inside, _leading_zeros(keys[i] ^ keys[jj]), -1)

    i = np.arange(n - 1, dtype=np.int64)
    direction = np.where(delta(i, i + 1) - delta(i, i - 1) >= 0, 1, -1)
    delta_min = delta(i, i - direction)
    # The far end of each node's key range: an exponential, then a binary search.
    length_max = np.full(n - 1, 2, dtype=np.int64)
    grow = delta(i, i + length_max * direction) > delta_min
    while grow.any():
        length_max = np.where(grow, length_max * 2, length_max)
        grow &= delta(i, i + length_max * direction) > delta_min
    length = np.zeros(n - 1, dtype=np.int64)
    step = length_max // 2
    while (step >= 1).any():
        take = (step >= 1) & (delta(i, i + (length + step) * direction) > delta_min)
        length = np.where(take, length + step, length)
        step //= 2
    j = i + length * direction
    delta_node = delta(i, j)
    # The split: the last key sharing more than delta_node bits with key i.
    split = np.zeros(n - 1, dtype=np.int64)
    searching = np.ones(n - 1, dtype=bool)  # a node stops after its step of 1
    divisor = 2
    while searching.any():
        step = (length + divisor - 1) // divisor
        take = searching & (delta(i, i + (split + step) * direction) > delta_node)
        split = np.where(take, split + step, split)
        searching &= step > 1
        divisor *= 2
    gamma = i + split * direction + np.minimum(direction, 0)
    first, last = np.minimum(i, j), np.maximum(i, j)
    # Children: a leaf -(sorted position + 1) where the range is a single key, else a node.
    left = np.where(first == gamma, -(gamma + 1), gamma)
    right = np.where(last == gamma + 1, -(gamma + 2), gamma + 1)
    children = np.stack([left, right], axis=1)

    # Depth of every internal node (top-down), then boxes refit from the deepest level up.
    depth = np.full(n - 1, -1, dtype=np.int64)
    depth[0] = 0
    frontier = np.array([0])
    level = 0
    while frontier.size:
        level += 1
        kids = children[frontier].ravel()
        frontier = kids[kids >= 0]
        depth[frontier] = level
    node_lo = np.empty((n - 1, 3))
    node_hi = np.empty((n - 1, 3))
    leaf_lo, leaf_hi = tri_lo[order], tri_hi[order]
    for d in range(level - 1, -1, -1):
        nodes = np.nonzero(depth == d)[0]
        child_lo = np.empty((len(nodes), 2, 3))
        child_hi = np.empty((len(nodes), 2, 3))
        for side in (0, 1):
            c = children[nodes, side]
            leaf = c < 0
            child_lo[leaf, side], child_hi[leaf, side] = leaf_lo[-c[leaf] - 1], leaf_hi[-c[leaf] - 1]
            child_lo[~leaf, side], child_hi[~leaf, side] = node_lo[c[~leaf]], node_hi[c[~leaf]]
        node_lo[nodes], node_hi[nodes] = child_lo.min(axis=1), child_hi.max(axis=1)

    pad = BOX_PAD_REL * (np.max(tri_hi.max(axis=0) - tri_lo.min(axis=0)) + np.max(np.abs(tri)))
    bounds = np.zeros((n - 1, 2, 4), dtype=np.float32)
    bounds[:, 0, :3] = np.nextafter((node_lo - pad).astype(np.float32), np.float32(-np.inf))
    bounds[:, 1, :3] = np.nextafter((node_hi + pad).astype(np.float32), np.float32(np.inf))
    # Leaves name triangles, not sorted positions.
    leaf = children < 0
    children[leaf] = -(order[-children[leaf] - 1] + 1)
    return Bvh(bounds.reshape(-1, 4), children.astype(np.int32), n)


def occluded_by_bvh(bvh: Bvh, triangles: np.ndarray, origin, target) -> bool:
    """Host walk of the BVH for one segment origin → target (float64): whether any
    triangle crosses it. For tests of the device walk; slow in Python."""
    from .reference.geometry import raycast

    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    origin, target = np.asarray(origin, float), np.asarray(target, float)
    d = target - origin
    if bvh.root < 0:
        candidates = list(range(len(tri)))
    else:
        candidates, stack = [], [0]
        lo, hi = bvh.node_bounds[0::2, :3].astype(float), bvh.node_bounds[1::2, :3].astype(float)
        while stack:
            node = stack.pop()
            with np.errstate(divide="ignore", invalid="ignore"):
                t0, t1 = (lo[node] - origin) / d, (hi[node] - origin) / d
            near = np.nanmax(np.minimum(t0, t1))
            far = np.nanmin(np.maximum(t0, t1))
            if near > min(far, 1.0) or far < 0:
                continue
            for child in bvh.node_children[node]:
                (candidates.append(-child - 1) if child < 0 else stack.append(int(child)))
    if not candidates:
        return False
    t, _ = raycast(origin, d, tri[candidates], t_max=1.0)
    return bool(np.isfinite(t[0]))
