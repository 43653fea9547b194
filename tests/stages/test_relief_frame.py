"""What a frame takes from a relief's texels instead of its triangles (docs/design.md,
"What a frame carries"): bounds and farthest vertex, digests, the triangles the device
buffers carry, the visibility BVH's kept subtree and boxes; and a relief listed before
other objects (its triangles moved last) rendering as one listed after them."""
from __future__ import annotations

import pickle

import numpy as np
import pytest

from clrays import Renderer
from clrays.bvh import refit_bvh
from clrays.inputs import frame_inputs
from clrays.reference.metrics import image_error
from clrays.relief_bvh import JoinedTopology, geometry_bvh_topology, refit_frame_bvh
from clrays.reuse import digest, geometry_parts
from clrays.scene.load import load_scene

SCENE = """version: 1
image: {{width: 64, height: 48}}
camera: {{position: [2.2, 2.4, 3.0], look_at: [0, 0.1, 0], fov_deg: 50, far: 20}}
lights: [{{type: spot, position: [1.5, 3.5, 1.0], direction: [-0.35, -1, -0.2], cone_deg: 40, intensity: 12}}]
medium: {{sigma_s: 0.08, sigma_a: 0.01}}
render: {{surface_shadows: {shadows}}}
objects:
{objects}
"""
RELIEF = ("  - {type: relief, center: [0, 0, 0], normal: [0, 1, 0], up: [0, 0, -1], size: [2.5, 2.5], "
          "depth_map: bumps.npy, height: 0.45, albedo: [0.7, 0.6, 0.5], "
          "transform: {rotate: {euler_deg: [10, 30, -5]}, scale: [1.2, 0.9, 1.0], translate: [0.1, -0.2, 0.3]}}")
OTHERS = ("  - {type: plane, center: [0, -0.6, 0], normal: [0, 1, 0], size: 8, segments: 1, albedo: 0.6}\n"
          "  - {type: sphere, center: [1.2, 0.5, -0.8], radius: 0.3, segments: 12}")


def _scene(tmp_path, shadows="map", relief_first=False, overrides=()):
    """A bump field with holes (an alpha channel), rotated, scaled and moved, beside a floor
    and a sphere; its triangles last in the geometry unless `relief_first`."""
    rng = np.random.default_rng(11)
    y, x = np.mgrid[0:40, 0:40] + 0.5
    depth = np.exp(-((x - 14) ** 2 + (y - 22) ** 2) / 60) + 0.3 * rng.random((40, 40))
    alpha = np.ones((40, 40))
    alpha[5:9, 25:33] = 0
    np.save(tmp_path / "bumps.npy", np.stack([depth / depth.max(), alpha], axis=2))
    objects = f"{RELIEF}\n{OTHERS}" if relief_first else f"{OTHERS}\n{RELIEF}"
    path = tmp_path / f"scene_{shadows}_{int(relief_first)}.yaml"
    path.write_text(SCENE.format(shadows=shadows, objects=objects))
    return load_scene(path, list(overrides))


def test_bounds_and_farthest_vertex_come_from_the_texels(tmp_path):
    geometry = _scene(tmp_path).geometry
    assert geometry.reliefs
    vertices = geometry.triangles.reshape(-1, 3)
    lo, hi = geometry.bounds()
    np.testing.assert_allclose(lo, vertices.min(axis=0), rtol=0, atol=1e-12)
    np.testing.assert_allclose(hi, vertices.max(axis=0), rtol=0, atol=1e-12)
    for point in ([2.2, 2.4, 3.0], [0.0, 0.1, 0.0], [-5.0, 1.0, 2.0]):
        expected = np.sqrt(((vertices - point) ** 2).sum(axis=1).max())
        assert geometry.farthest_from(point) == pytest.approx(expected, rel=1e-13)


def test_geometry_digest_follows_the_relief(tmp_path):
    key = lambda scene: digest(*geometry_parts(scene.geometry))  # noqa: E731
    base = key(_scene(tmp_path))
    assert key(_scene(tmp_path)) == base  # loaded again: the same
    assert key(_scene(tmp_path, overrides=["objects.2.transform.translate=[0.1, -0.2, 0.31]"])) != base
    assert key(_scene(tmp_path, overrides=["objects.2.albedo=[0.7, 0.6, 0.6]"])) != base
    assert key(_scene(tmp_path, overrides=["objects.2.height=0.46"])) != base
    assert key(_scene(tmp_path, overrides=["objects.1.radius=0.31"])) != base
    # The stages' key of the triangles alone: a new albedo keeps it, a move does not.
    shape = lambda scene: digest(*geometry_parts(scene.geometry, triangles_only=True))  # noqa: E731
    assert shape(_scene(tmp_path, overrides=["objects.2.albedo=[0.7, 0.6, 0.6]"])) == shape(_scene(tmp_path))
    assert shape(_scene(tmp_path, overrides=["objects.2.transform.translate=[0.1, -0.2, 0.31]"])) \
        != shape(_scene(tmp_path))


@pytest.mark.parametrize("shadows, method, carried", [
    ("map", "raymarch", False), ("pcf", "raymarch", False), ("exact", "raymarch", True),
    ("filtered", "raymarch", True),
    ("map", "minmax", True),  # minmax's walks place the shafts' edges on any triangle (cl/shaft_edges.h)
])
def test_frame_carries_relief_triangles_only_where_read(tmp_path, shadows, method, carried):
    scene = _scene(tmp_path, shadows, overrides=[f"render.method={method}"])
    inputs = frame_inputs(scene)
    relief_rows = sum(r.rows.stop - r.rows.start for r in scene.geometry.reliefs)
    assert inputs.raster_triangles == scene.geometry.count - relief_rows
    assert len(inputs.tri_vertices) // 3 == (scene.geometry.count if carried else inputs.raster_triangles)
    assert len(inputs.tri_normal) == len(inputs.tri_albedo) == scene.geometry.count
    # The reliefs' faces, kept with them, are the triangles' own normals and albedo.
    tris = inputs.scene.geometry.triangles
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    np.testing.assert_allclose(inputs.tri_normal[:, :3], normals, atol=1e-6)
    np.testing.assert_array_equal(inputs.tri_albedo[:, :3], inputs.scene.geometry.albedo.astype(np.float32))


@pytest.mark.parametrize("relief_first", [False, True])
def test_joined_bvh_refits_to_the_same_boxes(tmp_path, relief_first):
    inputs = frame_inputs(_scene(tmp_path, "exact", relief_first))
    topology = geometry_bvh_topology(inputs.scene.geometry)
    assert isinstance(topology, JoinedTopology) and len(topology.reliefs) == 1
    leaves = -topology.children[topology.children < 0] - 1
    np.testing.assert_array_equal(np.sort(leaves), np.arange(inputs.scene.geometry.count))
    ours = refit_frame_bvh(topology, inputs)
    generic = refit_bvh(topology, inputs.tri_vertices[:, :3].reshape(-1, 3, 3))
    np.testing.assert_array_equal(ours.node_bounds, generic.node_bounds)
    np.testing.assert_array_equal(ours.node_children, generic.node_children)
    # A second frame from elsewhere: the kept world boxes, moved, still give the same floats.
    moved = frame_inputs(_scene(tmp_path, "exact", relief_first, ["camera.position=[-1.5, 2.0, 2.5]"]))
    np.testing.assert_array_equal(refit_frame_bvh(geometry_bvh_topology(moved.scene.geometry), moved).node_bounds,
                                  refit_bvh(topology, moved.tri_vertices[:, :3].reshape(-1, 3, 3)).node_bounds)


@pytest.mark.parametrize("shadows", ["map", "exact"])
def test_relief_listed_first_renders_as_listed_last(tmp_path, shadows):
    session = Renderer(reuse=False)
    last = session.render(_scene(tmp_path, shadows), "minmax").image
    first = session.render(_scene(tmp_path, shadows, relief_first=True), "minmax").image
    error = image_error(first, last)
    assert error.pixels > 1000
    assert error.rmse < 1e-5, error


def test_a_pickled_relief_leaves_what_it_keeps_behind(tmp_path):
    """A scene sent to a worker process does not carry the relief's kept points and faces."""
    scene = _scene(tmp_path)
    bounds = scene.geometry.bounds()
    assert scene.geometry.reliefs[0].memo
    copy = pickle.loads(pickle.dumps(scene))
    assert copy.geometry.reliefs[0].memo == {}
    np.testing.assert_array_equal(np.stack(copy.geometry.bounds()), np.stack(bounds))
