"""Dense scenes and many lights.

Lights below the error budget (clrays/light_skip.py): the bound holds a light's own image
from above, a negligible light is left out of a frame of lights in turn within the budget
and `--stats` says so, a guess that fails the check after the frame renders the light after
all, and what no bound covers is never left out.

The host steps of a dense mesh: a binary PLY of triangles read in numpy as trimesh reads it
(clrays/scene/ply.py), anything else left to trimesh; the Morton code's bit spread and the
smooth normals' flat fallback the same as before, and the farthest vertex found through
boxes the same as through every vertex."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from clrays import light_skip
from clrays.scene import geometry as geometry_module
from clrays.scene.geometry import MORTON_BITS, flat_normals, load_mesh, smooth_normals
from clrays.light_skip import SKIP_BUDGET, candidates, contribution_bound, mean_luminance
from clrays.scene.load import load_scene
from clrays.scene.model import DirectionalLight, PointLight, _farthest_squared
from clrays.scene.ply import read_binary_triangles
from clrays.session import Renderer
from conftest import run_cli

#: The demo's room at 64×36: its light over the roof, and a dim one behind the camera.
SCENE = """version: 1
image: {width: 64, height: 36, spp: 1}
camera: {position: [0, 2.0, 9.5], look_at: [0, 2.4, 0], up: [0, 1, 0], fov_deg: 55, far: 40}
lights:
  - {type: point, position: [0.3, 7.5, -1.0], intensity: [260, 230, 190]}
  - {type: point, position: [0, 3, 30], intensity: [0.01, 0.01, 0.01]}
medium: {sigma_s: 0.08, sigma_a: 0.01, phase: {type: hg, g: 0.5}}
background: 0
objects:
  - {type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 30, albedo: 0.5}
  - {type: sphere, center: [1.6, 1.0, 0.5], radius: 1.0, albedo: [0.8, 0.5, 0.3]}
  - {type: box, min: [-3.0, 0, -1.5], max: [-1.8, 2.4, -0.3], albedo: 0.7}
  - {type: box, min: [-1.0, 4.6, -4.5], max: [-0.55, 4.8, 2.5], albedo: 0.6}
"""


@pytest.fixture(scope="module")
def scene_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("skip") / "dim.yaml"
    path.write_text(SCENE)
    return path


@pytest.fixture(scope="module")
def scene(scene_path):
    return load_scene(scene_path)


def _luminance(image: np.ndarray) -> np.ndarray:
    return np.asarray(image, np.float64) @ light_skip.LUMINANCE


def test_the_bound_holds_the_lights_own_image_from_above(device, scene):
    for index, light in enumerate(scene.lights):
        alone = replace(scene, lights=(light,))
        image = Renderer(device).render(alone).image
        bound = contribution_bound(scene, index)
        assert 0 < _luminance(image).max() <= bound, (index, _luminance(image).max(), bound)


def test_a_negligible_light_is_skipped_within_the_budget(device, scene):
    skipped = Renderer(device).render(scene)
    whole = Renderer(device, skip_lights=False).render(scene)
    assert skipped.skipped_lights is not None and skipped.skipped_lights.indices == (1,)
    assert whole.skipped_lights is None
    difference = np.abs(_luminance(skipped.image) - _luminance(whole.image))
    assert difference.max() <= SKIP_BUDGET * mean_luminance(whole.image)
    assert skipped.skipped_lights.bound <= skipped.skipped_lights.allowed
    # the dim light does add light: the skipped image is not the whole one
    assert not np.array_equal(skipped.image, whole.image)


def test_stats_list_the_skipped_light(scene_path, tmp_path):
    code, output = run_cli("render", scene_path, "-o", tmp_path / "dim.npy", "--stats")
    assert code == 0, output
    assert "1 of 2 lights below the error budget, skipped" in output


def test_a_guess_over_the_budget_renders_the_light_after_all(device, scene, monkeypatch):
    # every light but the brightest a candidate: the check after the frame finds the
    # skipped light's bound far over the budget and renders the frame again with it
    bright = replace(scene, lights=(scene.lights[0], replace(scene.lights[0], position=np.array([-0.3, 7.5, -1.0]))))
    monkeypatch.setattr(light_skip, "CHOOSE_FRACTION", 1e9)
    assert candidates(bright)[0] == (0,) or candidates(bright)[0] == (1,)
    guessed = Renderer(device).render(bright)
    monkeypatch.undo()
    whole = Renderer(device, skip_lights=False).render(bright)
    assert guessed.skipped_lights is None
    np.testing.assert_array_equal(guessed.image, whole.image)  # the frame again, every light in its turn


def test_what_no_bound_covers_is_never_skipped(scene):
    sun = DirectionalLight(direction=np.array([0.0, -1.0, 0.0]), irradiance=np.full(3, 1e-9))
    assert contribution_bound(replace(scene, lights=(scene.lights[0], sun)), 1) == math.inf
    assert candidates(replace(scene, lights=(sun, sun))) == ((), 0.0)
    # a light in the view: the lamp's ball bounds its in-scattering, finite but large
    seen = PointLight(position=np.array([0.0, 2.4, 0.0]), intensity=np.full(3, 0.01))
    assert 1e3 * contribution_bound(scene, 1) < contribution_bound(replace(scene, lights=(scene.lights[0], seen)), 1)
    dark = PointLight(position=np.array([0.0, 3.0, 30.0]), intensity=np.zeros(3))
    assert contribution_bound(replace(scene, lights=(scene.lights[0], dark)), 1) == 0.0
    assert candidates(scene, enabled=False) == ((), 0.0)
    assert candidates(replace(scene, lights=scene.lights[1:])) == ((), 0.0)  # one light is never left out


def test_the_luminance_is_the_one_the_error_is_measured_in():
    from clrays.reference import metrics

    np.testing.assert_array_equal(light_skip.LUMINANCE, metrics._LUMINANCE)


# ---------------------------------------------------------------- the host steps of a dense mesh

def _ply(vertices: np.ndarray, faces: np.ndarray, order: str = "<", vertex_extra: str = "", counts=None) -> bytes:
    """A binary PLY file: float x y z (and a uchar `vertex_extra` property set to 7), faces as
    lists of `counts` (default 3) int corners."""
    form = {"<": "binary_little_endian", ">": "binary_big_endian"}[order]
    fields = [("x", order + "f4"), ("y", order + "f4"), ("z", order + "f4")] + ([(vertex_extra, "u1")] if vertex_extra else [])
    points = np.zeros(len(vertices), fields)
    for axis, name in enumerate("xyz"):
        points[name] = vertices[:, axis]
    if vertex_extra:
        points[vertex_extra] = 7
    rows = np.zeros(len(faces), [("n", "u1"), ("v", order + "i4", faces.shape[1])])
    rows["n"], rows["v"] = faces.shape[1] if counts is None else counts, faces
    header = (f"ply\nformat {form} 1.0\ncomment made by a test\nelement vertex {len(vertices)}\nproperty float x\n"
              f"property float y\nproperty float z\n" + (f"property uchar {vertex_extra}\n" if vertex_extra else "")
              + f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    return header.encode() + points.tobytes() + rows.tobytes()


def _trimesh_read(data: bytes):
    import io

    import trimesh

    mesh = trimesh.load(io.BytesIO(data), file_type="ply", process=False)
    return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)


@pytest.mark.parametrize("order, extra", [("<", ""), (">", ""), ("<", "red")])
def test_a_binary_ply_of_triangles_reads_as_trimesh_reads_it(order, extra):
    rng = np.random.default_rng(11)
    vertices, faces = rng.normal(size=(50, 3)), rng.integers(0, 50, (80, 3))
    data = _ply(vertices, faces, order, extra)
    read = read_binary_triangles(data)
    assert read is not None
    for got, expected in zip(read, _trimesh_read(data)):
        assert got.dtype == expected.dtype
        np.testing.assert_array_equal(got, expected)


def test_a_mesh_file_loads_the_same_without_trimesh(tmp_path, monkeypatch):
    vertices, faces = _boxes(5)
    path = tmp_path / "boxes.ply"
    path.write_bytes(_ply(vertices, faces))
    fast = load_mesh(path)
    monkeypatch.setattr(geometry_module, "read_binary_triangles", lambda data: None)
    slow = load_mesh(path)
    assert fast[2] == slow[2] != 0  # closed boxes
    for got, expected in zip(fast[:2], slow[:2]):
        np.testing.assert_array_equal(got, expected)


def test_other_ply_files_are_left_to_trimesh():
    vertices, faces = _boxes(1)
    whole = _ply(vertices, faces)
    assert read_binary_triangles(whole) is not None
    assert read_binary_triangles(whole + b"\0") is None  # bytes left over
    assert read_binary_triangles(whole[:-1]) is None  # bytes missing
    assert read_binary_triangles(_ply(vertices, faces, counts=4)) is None  # a face that says 4 corners
    quads = np.concatenate([faces[:2], faces[:2, :1]], axis=1)
    assert read_binary_triangles(_ply(vertices, quads)) is None
    assert read_binary_triangles(_ply(vertices, faces, vertex_extra="nx")) is None  # vertex normals: trimesh's
    assert read_binary_triangles(whole.replace(b"binary_little_endian", b"ascii", 1)) is None
    assert read_binary_triangles(b"solid x\n") is None


def test_the_morton_spread_puts_bit_i_at_bit_3i():
    cells = np.random.default_rng(3).integers(0, 1 << MORTON_BITS, 5000).astype(np.uint64)
    expected = np.zeros_like(cells)
    for bit in range(MORTON_BITS):
        expected |= ((cells >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit)
    np.testing.assert_array_equal(geometry_module._every_third_bit(cells), expected)


def test_smooth_normals_take_the_face_normal_only_where_a_corner_has_none():
    # two faces wound opposite ways over vertices 0, 1, 2: their sums cancel at vertex 2
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    faces = np.array([[0, 1, 2], [0, 2, 1], [0, 1, 3]])
    normals = smooth_normals(vertices, faces)
    flat = flat_normals(vertices[faces])
    np.testing.assert_array_equal(normals[0, 2], flat[0, 2])  # vertex 2 of each cancelling face: its own
    np.testing.assert_array_equal(normals[1, 1], flat[1, 1])
    # vertex 0: the third face's normal, on the cancelling faces too (not their own)
    np.testing.assert_array_equal(normals[0, 0], flat[2, 0])
    assert not np.array_equal(normals[0, 0], flat[0, 0])


def _boxes(count: int) -> tuple[np.ndarray, np.ndarray]:
    """A row of `count` closed boxes, 12 triangles each, sharing no vertex: (vertices, faces)."""
    from clrays.scene.geometry import box_triangles

    triangles = box_triangles(np.zeros(3), np.ones(3) * 0.5)[None] + np.arange(count)[:, None, None, None] * [1.0, 0, 0]
    vertices = triangles.reshape(-1, 3)
    return vertices, np.arange(len(vertices)).reshape(-1, 3)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_farthest_vertex_by_boxes_is_the_farthest_of_every_vertex(seed):
    rng = np.random.default_rng(seed)
    corners = rng.normal(size=(64 * 100 + 17, 3))
    corners[rng.integers(len(corners))] *= 50  # one far vertex, anywhere in its block
    kept = {}
    for point in (np.zeros(3), rng.normal(size=3) * 10, corners[5]):
        expected = ((corners - point) ** 2).sum(axis=1).max()
        assert _farthest_squared(corners, point, lambda key, compute: kept.setdefault(key, compute())) == expected
