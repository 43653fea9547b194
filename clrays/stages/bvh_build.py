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


def bvh_build_tree(device: Device, triangles: np.ndarray, timer: StageTimer) -> DeviceBvhTree:
    """The tree of n ≥ 2 (T, 3, 3) world-space triangles: Morton keys sorted on the host
    (timed as host `bvh`), the radix tree on the device (`bvh` events)."""
    start = time.perf_counter()
    keys, order = sorted_morton_keys(triangles)
    n = len(keys)
    timer.add_host("bvh", (time.perf_counter() - start) * 1e3)
    tree = DeviceBvhTree(device.buffer(nbytes=8 * (n - 1)), device.buffer(nbytes=8 * (n - 1)),
                         device.buffer(order.astype(np.int32), writable=False), device.buffer(nbytes=4 * (n - 1)),
                         device.buffer(nbytes=4 * n), n)
    device.fill(tree.node_parent, np.int32(-1), 4 * (n - 1), timer, "bvh")  # the root's; the others are written
    timer.add("bvh", device.kernel("bvh_build", "bvh_build_tree")(
        device.queue, (n - 1,), None, device.buffer(keys, writable=False), tree.order, np.int32(n),
        tree.node_children, tree.node_keys, tree.node_parent, tree.leaf_parent))
    return tree


def bvh_build_refit(device: Device, tree: DeviceBvhTree, vertices: np.ndarray, vertex_buffer, timer: StageTimer):
    """node_bounds (float4 lo, hi per internal node) of `tree` around the frame's eye-space
    vertices (`vertices`, (3T, 4) float32, 3 per triangle in the tree's triangle order, and
    `vertex_buffer`, the same on the device), padded as clrays.bvh.refit_bvh pads them: the
    pad from the vertices' box on the host (timed as host `bvh`), the boxes on the device."""
    start = time.perf_counter()
    # Column by column (numpy reduces a (3T, 4) array down its first axis 20× slower); the
    # pad rounded up to float32, so that every box holds refit_bvh's.
    columns = [vertices[:, axis] for axis in range(3)]
    pad = box_pad([column.min() for column in columns], [column.max() for column in columns])
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
