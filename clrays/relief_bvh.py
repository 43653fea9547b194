"""The visibility stage's BVH for a geometry with reliefs (docs/design.md, "What a frame
carries"): each relief's subtree built once and kept with the relief, the other
triangles' tree built per frame, the two joined under a few nodes on top.

A topology stays valid for its triangles wherever an affine map puts them (a refit fits
the boxes to where they are), so a relief's subtree, built over its triangles the first
time it is seen, serves every later frame and placement. Its boxes are kept too, in
world space per placement: the refit's boxes must hold the frame's float32 eye-space
vertices fl32(v − eye), and rounding is monotone, so the smallest of those is
fl32(min v − eye): a relief's eye-space boxes are its world boxes moved and rounded, the
same floats a refit over its 2 M triangles would give, in one pass over its nodes.
Without reliefs all this is `bvh_topology` and `refit_bvh`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .bvh import BOX_PAD_REL, Bvh, BvhTopology, bvh_topology, refit_bvh
from .scene.relief_frame import handle_points, other_rows

#: World-space boxes kept per relief, one set per placement (as clrays.scene.relief_frame).
PLACEMENTS_KEPT = 2


@dataclass
class JoinedTopology(BvhTopology):
    """A topology joined from parts; `reliefs` lists the relief parts: (record, node base,
    its topology), whose boxes `refit_frame_bvh` takes from the record instead of refitting;
    `outer_levels` are the levels of every other node (join nodes, the other triangles')."""

    reliefs: list = field(default_factory=list)
    outer_levels: list = field(default_factory=list)


def geometry_bvh_topology(geometry) -> BvhTopology:
    """The BVH topology over all of `geometry`'s triangles, in their order (tree leaves are
    rows of geometry.triangles)."""
    if not geometry.reliefs:
        return bvh_topology(geometry.triangles)
    parts = [(rows.start, bvh_topology(geometry.triangles[rows]), None)
             for rows in other_rows(geometry.count, geometry.reliefs)]
    for record in geometry.reliefs:
        if "bvh" not in record.memo:
            record.memo["bvh"] = bvh_topology(geometry.triangles[record.rows])
        parts.append((record.rows.start, record.memo["bvh"], record))
    return join_topologies(parts, geometry.count)


def join_topologies(parts: list, count: int) -> JoinedTopology:
    """One topology over `count` triangles from parts (first row, topology of the rows from
    there, relief record or None): K parts hang under K − 1 join nodes, a chain (node 0,
    the root, then 1, …); each part's nodes follow, renumbered, its leaves shifted to its rows."""
    parts = [part for part in parts if part[1].triangle_count > 0]
    joins = len(parts) - 1
    chain, blocks, roots, reliefs = np.zeros((joins, 2), np.int64), [], [], []
    levels_at, outer_at = {}, {}  # depth from the root → node arrays
    base = joins
    for k, (first, topology, record) in enumerate(parts):
        roots.append(base if topology.triangle_count > 1 else -(first + 1))  # a single triangle: its leaf
        shifted = topology.children.copy()
        inner = shifted >= 0
        shifted[inner] += base
        shifted[~inner] -= first
        blocks.append(shifted)
        top = min(k, joins - 1) + 1 if joins else 0  # the depth of the part's root under the chain
        for index, nodes in enumerate(topology.levels):  # deepest first: the last is the part's root
            depth = top + len(topology.levels) - 1 - index
            levels_at.setdefault(depth, []).append(nodes + base)
            if record is None or topology.triangle_count < 2:
                outer_at.setdefault(depth, []).append(nodes + base)
        if record is not None and topology.triangle_count > 1:
            reliefs.append((record, base, topology))
        base += topology.triangle_count - 1
    for j in range(joins):
        chain[j] = (roots[j], j + 1 if j + 1 < joins else roots[-1])
        levels_at.setdefault(j, []).append(np.array([j], np.int64))
        outer_at.setdefault(j, []).append(np.array([j], np.int64))

    def by_depth(at: dict) -> list:
        return [np.concatenate(at[depth]) for depth in sorted(at, reverse=True)]

    return JoinedTopology(np.concatenate([chain] + blocks), by_depth(levels_at), count, reliefs, by_depth(outer_at))


def _world_boxes(record, topology: BvhTopology, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((n − 1, 3), (n − 1, 3)) float64 lo, hi of a relief subtree's nodes around its
    world-space triangles, exact (no padding, no rounding), kept per placement."""
    key = handle_points(record, triangles).tobytes()
    kept = record.memo.setdefault("bvh_boxes", {})
    if key not in kept:
        if len(kept) >= PLACEMENTS_KEPT:
            kept.pop(next(iter(kept)))
        tri = triangles[record.rows]
        n = topology.triangle_count
        # The refit of clrays.bvh.refit_bvh before its padding: nodes first, then the leaves.
        box_lo = np.concatenate([np.empty((n - 1, 3)), np.minimum(np.minimum(tri[:, 0], tri[:, 1]), tri[:, 2])])
        box_hi = np.concatenate([np.empty((n - 1, 3)), np.maximum(np.maximum(tri[:, 0], tri[:, 1]), tri[:, 2])])
        rows = np.where(topology.children >= 0, topology.children, n - 2 - topology.children)
        for nodes in topology.levels:
            left, right = rows[nodes, 0], rows[nodes, 1]
            box_lo[nodes] = np.minimum(box_lo[left], box_lo[right])
            box_hi[nodes] = np.maximum(box_hi[left], box_hi[right])
        kept[key] = (box_lo[:n - 1], box_hi[:n - 1])
    return kept[key]


def refit_frame_bvh(topology: BvhTopology, inputs) -> Bvh:
    """`refit_bvh` of the frame's eye-space float32 triangles (`inputs.tri_vertices`), the
    same boxes to the bit; a relief's nodes from its kept world boxes (module docstring)."""
    vertices = inputs.tri_vertices[:, :3].reshape(-1, 3, 3)
    if not isinstance(topology, JoinedTopology) or not topology.reliefs:
        return refit_bvh(topology, vertices)
    n, children = topology.triangle_count, topology.children
    triangles = inputs.scene.geometry.triangles
    box_lo, box_hi = np.empty((2 * n - 1, 3)), np.empty((2 * n - 1, 3))
    is_relief_row = np.zeros(n, bool)
    for record, base, part in topology.reliefs:
        world_lo, world_hi = _world_boxes(record, part, triangles)
        nodes = slice(base, base + part.triangle_count - 1)
        # fl32(fl64(v − eye)) is monotone in v: the eye-space float32 vertices' bounds.
        box_lo[nodes] = (world_lo - inputs.eye_ws).astype(np.float32)
        box_hi[nodes] = (world_hi - inputs.eye_ws).astype(np.float32)
        is_relief_row[record.rows] = True
    other = np.flatnonzero(~is_relief_row)  # leaves the outer levels may name
    tri = vertices[other].astype(np.float64)
    box_lo[n - 1 + other] = np.minimum(np.minimum(tri[:, 0], tri[:, 1]), tri[:, 2])
    box_hi[n - 1 + other] = np.maximum(np.maximum(tri[:, 0], tri[:, 1]), tri[:, 2])
    rows = np.where(children >= 0, children, n - 2 - children)
    for nodes in topology.outer_levels:
        left, right = rows[nodes, 0], rows[nodes, 1]
        box_lo[nodes] = np.minimum(box_lo[left], box_lo[right])
        box_hi[nodes] = np.maximum(box_hi[left], box_hi[right])
    node_lo, node_hi = box_lo[:n - 1], box_hi[:n - 1]
    lo, hi = node_lo[0], node_hi[0]  # the root's box: every triangle's
    pad = BOX_PAD_REL * (np.max(hi - lo) + max(-lo.min(), hi.max()))
    bounds = np.zeros((n - 1, 2, 4), dtype=np.float32)
    bounds[:, 0, :3] = np.nextafter((node_lo - pad).astype(np.float32), np.float32(-np.inf))
    bounds[:, 1, :3] = np.nextafter((node_hi + pad).astype(np.float32), np.float32(np.inf))
    return Bvh(bounds.reshape(-1, 4), children.astype(np.int32), n)
