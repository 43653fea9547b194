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


@dataclass
class BvhTopology:
    """The tree alone: what depends on the triangles' order in space, not on where they
    are exactly. A rigidly moved scene (eye space, as the camera moves) keeps it and
    only refits its boxes (`refit_bvh`)."""

    children: np.ndarray  # (n - 1, 2) int64, leaves as -(triangle + 1)
    levels: list  # internal node indices per depth, deepest first
    triangle_count: int


def _spread_bits(x: np.ndarray) -> np.ndarray:
    """10-bit integers with two zero bits inserted between their bits (for 30-bit Morton codes)."""
    x = x.astype(np.uint64) & np.uint64(0x3FF)
    x = (x | (x << np.uint64(16))) & np.uint64(0x030000FF)
    x = (x | (x << np.uint64(8))) & np.uint64(0x0300F00F)
    x = (x | (x << np.uint64(4))) & np.uint64(0x030C30C3)
    x = (x | (x << np.uint64(2))) & np.uint64(0x09249249)
    return x


def _highest_bit(x: np.ndarray) -> np.ndarray:
    """The highest set bit of uint64 values, as a power of two (0 for 0): the bits below it
    are smeared to ones, then the value less its half is that bit."""
    x = x.copy()
    for shift in (1, 2, 4, 8, 16, 32):
        x |= x >> np.uint64(shift)
    return x - (x >> np.uint64(1))


def build_bvh(triangles: np.ndarray) -> Bvh:
    """The BVH of (T, 3, 3) triangles (any float dtype; boxes are rounded outwards to
    float32 and padded by BOX_PAD_REL): `refit_bvh(bvh_topology(triangles), triangles)`."""
    return refit_bvh(bvh_topology(triangles), triangles)


def _triangle_boxes(tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    # Corner by corner: numpy reduces a middle axis of length 3 far more slowly.
    return (np.minimum(np.minimum(tri[:, 0], tri[:, 1]), tri[:, 2]),
            np.maximum(np.maximum(tri[:, 0], tri[:, 1]), tri[:, 2]))


def sorted_morton_keys(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(keys, order, box) of n ≥ 2 (T, 3, 3) triangles: the 30-bit Morton codes of their box
    centres on a 1024³ grid over the centres' box, each shifted up 32 bits above its sorted
    position (Karras §4's tie-break: unique keys), sorted; order[k] is the triangle of key k;
    box, (2, 3) float64, the lo and hi corners of every vertex. The start of `bvh_topology`,
    shared with the device build (clrays.stages.bvh_build)."""
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    n = len(tri)
    # One copy into rows of T (corner-major, then coordinate): numpy's passes over a last
    # axis of length 3, or down strided columns, cost several times those over
    # contiguous rows (same values, so the same codes).
    rows = tri.reshape(n, 9).T.copy(order="C")
    centroid = np.minimum(rows[0:3], rows[3:6])
    np.minimum(centroid, rows[6:9], out=centroid)
    tri_hi = np.maximum(rows[0:3], rows[3:6])
    np.maximum(tri_hi, rows[6:9], out=tri_hi)
    box = np.stack([centroid.min(axis=1), tri_hi.max(axis=1)])
    centroid += tri_hi
    centroid /= 2
    lo, hi = centroid.min(axis=1, keepdims=True), centroid.max(axis=1, keepdims=True)
    centroid -= lo
    centroid /= np.maximum(hi - lo, 1e-300)
    centroid *= 1023.0
    cell = np.clip(centroid, 0, 1023, out=centroid).astype(np.uint64)
    morton = (_spread_bits(cell[0]) << np.uint64(2)) | (_spread_bits(cell[1]) << np.uint64(1)) | _spread_bits(cell[2])
    # Triangle index in the low bits, then one sort: the order of a stable sort of the
    # codes, at a fraction of its cost; the sorted position then replaces the index.
    keys = np.sort((morton << np.uint64(32)) | np.arange(n, dtype=np.uint64))
    order = (keys & np.uint64(0xFFFFFFFF)).astype(np.int64)
    keys &= ~np.uint64(0xFFFFFFFF)
    keys |= np.arange(n, dtype=np.uint64)
    return keys, order, box


def bvh_topology(triangles: np.ndarray) -> BvhTopology:
    """The tree of (T, 3, 3) triangles, without boxes (module docstring)."""
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    n = len(tri)
    if n <= 1:
        return BvhTopology(np.zeros((0, 2), np.int64), [], n)
    keys, order, _ = sorted_morton_keys(tri)

    # Two keys share more leading bits than keys i and k exactly when their XOR is below
    # the highest bit of keys[i] ^ keys[k] (its "bound"), so the searches below compare
    # integers instead of counting bits; 2**63 (above every XOR of keys < 2**62) stands for
    # a neighbour outside [0, n), with whom no key shares anything.
    outside = np.uint64(1 << 63)
    neighbour_bound = _highest_bit(keys[:-1] ^ keys[1:])  # keys k and k + 1

    def longer_prefix(i: np.ndarray, j: np.ndarray, bound: np.ndarray) -> np.ndarray:
        """Whether keys i and j share more leading bits than `bound` stands for; false
        where j is outside [0, n)."""
        inside = (j >= 0) & (j < n)
        return inside & ((keys[i] ^ keys[np.clip(j, 0, n - 1)]) < bound)

    i = np.arange(n - 1, dtype=np.int64)
    bound_next = neighbour_bound  # keys i, i + 1
    bound_prev = np.concatenate([[outside], neighbour_bound[:-1]])  # keys i - 1, i
    # Karras's direction: towards the neighbour sharing the longer prefix (never a tie for
    # unique keys); the other neighbour's prefix is the least the range's keys share.
    direction = np.where(bound_next <= bound_prev, 1, -1)
    bound_min = np.where(direction > 0, bound_prev, bound_next)
    # The far end of each node's key range: an exponential, then a binary search, each
    # pass over the nodes still searching only.
    length_max = np.full(n - 1, 2, dtype=np.int64)
    active = np.flatnonzero(longer_prefix(i, i + 2 * direction, bound_min))
    while active.size:
        length_max[active] *= 2
        active = active[longer_prefix(active, active + length_max[active] * direction[active], bound_min[active])]
    length = np.zeros(n - 1, dtype=np.int64)
    step = length_max // 2
    active = i
    while active.size:
        s = step[active]
        take = longer_prefix(active, active + (length[active] + s) * direction[active], bound_min[active])
        length[active[take]] += s[take]
        step[active] = s // 2
        active = active[s // 2 >= 1]
    j = i + length * direction
    bound_node = _highest_bit(keys[i] ^ keys[j])
    # The split: the last key sharing more leading bits with key i than key j does.
    split = np.zeros(n - 1, dtype=np.int64)
    active = i  # a node stops after its step of 1
    divisor = 2
    while active.size:
        step = (length[active] + divisor - 1) // divisor
        take = longer_prefix(active, active + (split[active] + step) * direction[active], bound_node[active])
        split[active[take]] += step[take]
        active = active[step > 1]
        divisor *= 2
    gamma = i + split * direction + np.minimum(direction, 0)
    first, last = np.minimum(i, j), np.maximum(i, j)
    # Children: a leaf -(sorted position + 1) where the range is a single key, else a node.
    left = np.where(first == gamma, -(gamma + 1), gamma)
    right = np.where(last == gamma + 1, -(gamma + 2), gamma + 1)
    children = np.stack([left, right], axis=1)

    # Depth of every internal node (top-down): the levels the refit goes up by.
    depth = np.full(n - 1, -1, dtype=np.int64)
    depth[0] = 0
    frontier = np.array([0])
    level = 0
    while frontier.size:
        level += 1
        kids = children[frontier].ravel()
        frontier = kids[kids >= 0]
        depth[frontier] = level
    # Leaves name triangles, not sorted positions.
    leaf = children < 0
    children[leaf] = -(order[-children[leaf] - 1] + 1)
    by_depth = np.argsort(-depth, kind="stable")
    level_ends = np.cumsum(np.bincount(depth)[::-1])
    levels = [by_depth[first:last] for first, last in zip(np.concatenate([[0], level_ends[:-1]]), level_ends)]
    return BvhTopology(children, levels, n)


def refit_bvh(topology: BvhTopology, triangles: np.ndarray) -> Bvh:
    """The boxes of `topology` around `triangles` (the same triangles, in the same order,
    moved or not: any tree is a valid BVH once its boxes hold its triangles), refit from the
    deepest level up, rounded outwards to float32 and padded by BOX_PAD_REL."""
    # Min and max are exact in any float type, so float32 triangles (the device's) are
    # refit in float32, at half the memory traffic, with the same boxes as in float64.
    dtype = np.float32 if np.asarray(triangles).dtype == np.float32 else np.float64
    tri = np.asarray(triangles, dtype=dtype).reshape(-1, 3, 3)
    n = topology.triangle_count
    if len(tri) != n:
        raise ValueError(f"refit_bvh: the topology holds {n} triangles, got {len(tri)}")
    if n <= 1:
        return Bvh(np.zeros((0, 4), np.float32), np.zeros((0, 2), np.int32), n)
    tri_lo, tri_hi = _triangle_boxes(tri)
    children = topology.children
    # One array of boxes, internal nodes first, then the triangles, so a level's refit is
    # one gather per child: child c ≥ 0 is row c, leaf -(t + 1) row n - 1 + t. A row holds
    # (lo, -hi), so one minimum refits both sides.
    boxes = np.empty((2 * n - 1, 6), dtype)
    boxes[n - 1:, :3], boxes[n - 1:, 3:] = tri_lo, -tri_hi
    rows = np.where(children >= 0, children, n - 2 - children)
    for nodes in topology.levels:
        boxes[nodes] = np.minimum(boxes[rows[nodes, 0]], boxes[rows[nodes, 1]])
    node_lo, node_hi = boxes[:n - 1, :3].astype(np.float64), -boxes[:n - 1, 3:].astype(np.float64)
    tri_lo, tri_hi = tri_lo.astype(np.float64), tri_hi.astype(np.float64)

    pad = box_pad(tri_lo.min(axis=0), tri_hi.max(axis=0))
    bounds = np.zeros((n - 1, 2, 4), dtype=np.float32)
    bounds[:, 0, :3] = np.nextafter((node_lo - pad).astype(np.float32), np.float32(-np.inf))
    bounds[:, 1, :3] = np.nextafter((node_hi + pad).astype(np.float32), np.float32(np.inf))
    return Bvh(bounds.reshape(-1, 4), children.astype(np.int32), n)


def box_pad(scene_lo: np.ndarray, scene_hi: np.ndarray) -> float:
    """How far every box grows on each side (float64): BOX_PAD_REL of the scene box's
    largest extent plus its largest |coordinate|."""
    scene_lo, scene_hi = np.asarray(scene_lo, np.float64), np.asarray(scene_hi, np.float64)
    return float(BOX_PAD_REL * (np.max(scene_hi - scene_lo) + max(-scene_lo.min(), scene_hi.max())))
