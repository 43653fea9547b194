"""Stage bvh, on the device: the visibility stage's BVH built where its triangles are.
Host side of `cl/bvh_build.cl` (docs/design.md §4.6).

The host sorts the Morton keys (`clrays.bvh.sorted_morton_keys`, the one step a
device does not do in a kernel or two); `bvh_build_tree` then finds Karras's radix
tree, one work-item per node, and `bvh_build_refit` boxes it bottom-up around the frame's
eye-space float32 vertices, already on the device, and pads the boxes. The tree is that of
`clrays.bvh.bvh_topology`, node for node, and the boxes those of `clrays.bvh.refit_bvh`
to within a float32 rounding of the padding, never smaller; nothing crosses back to the
host. A scene with reliefs keeps the host path (clrays.relief_bvh), which reuses each
relief's subtree and boxes.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..bvh import box_pad, sorted_morton_keys
from ..device import Device, StageTimer


@dataclass
class DeviceBvhTree:
    """A BVH's tree on the device, without boxes: what a session keeps per geometry."""

    node_children: object  # int2 per internal node, the layout of clrays.bvh
    node_keys: object  # the same with leaves as -(key + 1): where the refit finds their boxes
    order: object  # int per key: its triangle
    node_parent: object  # int per internal node, -1 at the root
    leaf_parent: object  # int per key (sorted leaf): the node holding it
    triangle_count: int  # ≥ 2
    box_ws: np.ndarray  # (2, 3) float64: the lo and hi corners of every world-space vertex


def bvh_build_tree(device: Device, triangles: np.ndarray, timer: StageTimer) -> DeviceBvhTree:
    """The tree of n ≥ 2 (T, 3, 3) world-space triangles: Morton keys sorted on the host
    (timed as host `bvh`), the radix tree on the device (`bvh` events)."""
    start = time.perf_counter()
    keys, order, box_ws = sorted_morton_keys(triangles)
    n = len(keys)
    timer.add_host("bvh", (time.perf_counter() - start) * 1e3)
    tree = DeviceBvhTree(device.buffer(nbytes=8 * (n - 1)), device.buffer(nbytes=8 * (n - 1)),
                         device.buffer(order.astype(np.int32), writable=False), device.buffer(nbytes=4 * (n - 1)),
                         device.buffer(nbytes=4 * n), n, box_ws)
    device.fill(tree.node_parent, np.int32(-1), 4 * (n - 1), timer, "bvh")  # the root's; the others are written
    timer.add("bvh", device.kernel("bvh_build", "bvh_build_tree")(
        device.queue, (n - 1,), None, device.buffer(keys, writable=False), tree.order, np.int32(n),
        tree.node_children, tree.node_keys, tree.node_parent, tree.leaf_parent))
    return tree


def bvh_build_refit(device: Device, tree: DeviceBvhTree, eye_ws: np.ndarray, vertex_buffer, timer: StageTimer):
    """node_bounds (float4 lo, hi per internal node) of `tree` around the frame's eye-space
    vertices on the device (`vertex_buffer`: float32(v − eye_ws) as clrays.inputs makes
    them, 3 per triangle in the tree's triangle order), padded as clrays.bvh.refit_bvh pads
    them: the pad on the host (timed as host `bvh`), the boxes on the device."""
    start = time.perf_counter()
    # The vertices' box without reading them: float64 v − eye, then float32, is monotone in
    # v, so the smallest vertex gives the smallest float32 coordinate (and the largest the
    # largest), the box refit_bvh takes its pad from. The pad is rounded up to float32, so
    # that every box holds refit_bvh's.
    lo, hi = ((tree.box_ws - np.asarray(eye_ws, np.float64)).astype(np.float32))
    pad = box_pad(lo, hi)
    pad32 = np.float32(pad)
    if pad32 < pad:
        pad32 = np.nextafter(pad32, np.float32(np.inf))
    timer.add_host("bvh", (time.perf_counter() - start) * 1e3)
    n = tree.triangle_count
    arrivals = device.buffer(nbytes=4 * (n - 1))
    device.fill(arrivals, np.int32(0), 4 * (n - 1), timer, "bvh")
    leaf_bounds = device.buffer(nbytes=32 * n)
    timer.add("bvh", device.kernel("bvh_build", "bvh_build_leaves")(
        device.queue, (n,), None, vertex_buffer, tree.order, np.int32(n), pad32, leaf_bounds))
    node_bounds = device.buffer(nbytes=32 * (n - 1))
    timer.add("bvh", device.kernel("bvh_build", "bvh_build_refit")(
        device.queue, (n,), None, tree.node_keys, tree.node_parent, tree.leaf_parent, leaf_bounds, np.int32(n),
        arrivals, node_bounds))
    return node_bounds
