"""The visibility stage's BVH built on the device (`clrays.stages.bvh_build`, docs/design.md
§4.6) against the host build of `clrays.bvh`: the same tree node for node, and boxes that
hold the host's, equal to them or one float32 step wider (the pad rounded up to float32)."""
from __future__ import annotations

import numpy as np
import pytest

from clrays.bvh import bvh_topology, refit_bvh, sorted_morton_keys
from clrays.device import StageTimer
from clrays.stages.bvh_build import bvh_build_refit, bvh_build_tree


def eye_space_vertices(triangles: np.ndarray, eye) -> np.ndarray:
    """(3T, 4) float32 vertices as clrays.inputs makes them: float64 v − eye, rounded once."""
    vertices = (triangles - np.asarray(eye, np.float64)).reshape(-1, 3)
    return np.concatenate([vertices, np.zeros((len(vertices), 1))], axis=1).astype(np.float32)


def soups() -> dict:
    rng = np.random.default_rng(11)
    flat = np.concatenate([rng.random((400, 3, 2)), np.zeros((400, 3, 1))], axis=2)
    return {
        "random": rng.random((3000, 3, 3)) * 4.0 - 1.0,
        "two": rng.random((2, 3, 3)),
        "three": rng.random((3, 3, 3)),
        "flat": flat,  # a zero extent: every key on one plane
        "repeated": np.repeat(rng.random((7, 3, 3)), 40, axis=0),  # equal Morton codes
        "far": rng.random((500, 3, 3)) + 1e4,  # the scene moved by 1e4
        "needles": np.cumsum(rng.standard_normal((2000, 3, 3)) * 1e-3, axis=0),
    }


@pytest.mark.parametrize("name", list(soups()))
def test_the_device_tree_and_boxes_are_the_hosts(device, name):
    triangles = soups()[name]
    n = len(triangles)
    eye = triangles.reshape(-1, 3).mean(axis=0) + 0.37
    vertices = eye_space_vertices(triangles, eye)
    timer = StageTimer()
    tree = bvh_build_tree(device, triangles, timer)
    node_bounds = bvh_build_refit(device, tree, eye, device.buffer(vertices, writable=False), timer)
    children = device.read(tree.node_children, (n - 1, 2), np.int32)
    bounds = device.read(node_bounds, (2 * (n - 1), 4), np.float32)

    host = refit_bvh(bvh_topology(triangles), vertices[:, :3].reshape(-1, 3, 3))
    np.testing.assert_array_equal(children, host.node_children)
    lo, hi, host_lo, host_hi = bounds[0::2], bounds[1::2], host.node_bounds[0::2], host.node_bounds[1::2]
    assert (lo <= host_lo).all() and (hi >= host_hi).all()
    assert (np.nextafter(lo, np.float32(np.inf)) >= host_lo).all()
    assert (np.nextafter(hi, np.float32(-np.inf)) <= host_hi).all()
    assert np.mean(lo == host_lo) > 0.99 and np.mean(hi == host_hi) > 0.99


def test_sorted_morton_keys_are_unique_and_sorted():
    triangles = soups()["repeated"]
    keys, order, box = sorted_morton_keys(triangles)
    np.testing.assert_array_equal(box, [triangles.reshape(-1, 3).min(axis=0), triangles.reshape(-1, 3).max(axis=0)])
    assert (keys[1:] > keys[:-1]).all()
    assert sorted(order.tolist()) == list(range(len(triangles)))
    # Equal codes keep the triangles' order (a stable sort), as Karras's tie-break wants.
    codes = keys >> np.uint64(32)
    for code in np.unique(codes):
        assert (np.diff(order[codes == code]) > 0).all()
