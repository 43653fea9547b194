"""The host's steps whose cost follows the triangle count (clrays/scene/host_steps.py):
welding vertices by position, the shading normals, spatial order, closed solids and the
edge links, each what it was and no worse than n log n; and `--stats` lists them."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from clrays.scene import geometry as primitives
from clrays.scene.geometry import closed_outward, smooth_normals, spatial_order, weld
from clrays.scene.model import Geometry
from clrays.stages.shaft_edges import edge_neighbours, edge_windings
from conftest import run_cli


def _corners(count: int, seed: int = 0) -> np.ndarray:
    """`count` rows drawn from a few hundred points of half-integers, some with −0."""
    rng = np.random.default_rng(seed)
    points = rng.integers(-4, 4, (max(count // 5, 1), 3)).astype(float) / 2
    points[rng.random(points.shape) < 0.2] = -0.0
    return points[rng.integers(0, len(points), count)]


@pytest.mark.parametrize("count", [0, 1, 2, 17, 5000])
def test_welded_in_order_is_what_unique_rows_give(count):
    corners = _corners(count)
    ids, distinct = weld(corners, ordered=True)
    if count == 0:
        assert distinct == 0 and ids.shape == (0,)
        return
    rows, inverse = np.unique(corners + 0.0, axis=0, return_inverse=True)
    assert distinct == len(rows)
    np.testing.assert_array_equal(ids, inverse.ravel())


def test_welded_unordered_joins_exactly_the_equal_rows():
    corners = _corners(5000, seed=3)
    ids, distinct = weld(corners)
    _, inverse = np.unique(corners + 0.0, axis=0, return_inverse=True)
    pairs = set(zip(ids.tolist(), inverse.ravel().tolist()))
    assert len(pairs) == distinct == len(set(inverse.ravel().tolist()))  # one id per distinct row, both ways


def test_a_hash_that_collides_still_welds_exactly(monkeypatch):
    # Every row hashed to one key: the rows themselves are sorted instead.
    monkeypatch.setattr(primitives, "_WELD_MIX", (np.uint64(0),) * 3)
    corners = _corners(2000, seed=5)
    ids, distinct = weld(corners, ordered=True)
    rows, inverse = np.unique(corners + 0.0, axis=0, return_inverse=True)
    assert distinct == len(rows)
    np.testing.assert_array_equal(ids, inverse.ravel())


def test_smooth_normals_keep_the_sums_of_adding_corner_by_corner():
    rng = np.random.default_rng(7)
    vertices = rng.normal(size=(400, 3))
    faces = rng.integers(0, 400, (1500, 3))
    cross = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    summed = np.zeros_like(vertices)
    for corner in range(3):  # the order the sums were taken in before
        np.add.at(summed, faces[:, corner], cross)
    length = np.linalg.norm(summed, axis=1, keepdims=True)
    expected = (summed / np.where(length > 0, length, 1.0))[faces]
    got = smooth_normals(vertices, faces)
    used = np.linalg.norm(expected, axis=2) > 0
    assert np.array_equal(got[used], expected[used])  # the same bits


def _boxes(count: int) -> tuple[np.ndarray, np.ndarray]:
    """A row of `count` closed boxes, 12 triangles each: (vertices, faces)."""
    box = primitives.box_triangles(np.zeros(3), np.ones(3) * 0.5)
    triangles = box[None] + (np.arange(count)[:, None, None, None] * np.array([1.0, 0.0, 0.0]))
    vertices = triangles.reshape(-1, 3)
    return vertices, np.arange(len(vertices)).reshape(-1, 3)


def _edge_links(vertices, faces):
    triangles = vertices[faces]
    geometry = Geometry(triangles=triangles, albedo=np.ones((len(faces), 3)),
                        object_id=np.zeros(len(faces), np.int32))
    return edge_neighbours(geometry), edge_windings(geometry)


def test_the_edge_links_of_closed_boxes_pair_every_edge():
    vertices, faces = _boxes(3)
    neighbours, windings = _edge_links(vertices, faces)
    assert np.all(neighbours >= 0)  # every edge of a closed box has its other face
    assert np.all(neighbours // 12 == (np.arange(len(faces)) // 12)[:, None])  # within its own box
    assert not windings.any()  # consistently wound
    assert closed_outward(vertices, faces) != 0


STEPS = {
    "weld": lambda v, f: weld(v[f].reshape(-1, 3)),
    "smooth normals": smooth_normals,
    "spatial order": lambda v, f: spatial_order(v[f]),
    "solids": closed_outward,
    "edge links": _edge_links,
}


@pytest.mark.slow  # timed: half a minute of work, and a loaded machine's noise
@pytest.mark.parametrize("step", list(STEPS))
def test_a_host_step_grows_no_faster_than_n_log_n(step):
    """Best of five runs at n and 8n triangles, taken in turns (a machine's load then falls
    on both): the ratio stays within twice what n log n allows (8 × log 8n / log n); a
    step quadratic in n would take 64 times as long."""
    run = STEPS[step]
    sizes = (40000, 320000)  # both past the caches, whose edge would add its own step
    meshes = [_boxes(n // 12) for n in sizes]
    best = [math.inf, math.inf]
    run(*meshes[0])  # warm-up
    for _ in range(5):
        for k, mesh in enumerate(meshes):
            start = time.perf_counter()
            run(*mesh)
            best[k] = min(best[k], time.perf_counter() - start)
    ratio = best[1] / best[0]
    n_log_n = (sizes[1] * math.log(sizes[1])) / (sizes[0] * math.log(sizes[0]))
    assert ratio <= 2 * n_log_n, f"{step}: {ratio:.1f}× for 8× the triangles (n log n: {n_log_n:.1f}×)"


def test_stats_list_the_host_steps(tmp_path):
    vertices, faces = _boxes(4)
    mesh = tmp_path / "boxes.obj"
    mesh.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in vertices)
                    + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces))
    scene = tmp_path / "boxes.yaml"
    scene.write_text(
        "version: 1\nimage: {width: 16, height: 9}\n"
        "camera: {position: [1, 1, 6], look_at: [1, 0.3, 0], fov_deg: 50}\n"
        "lights: [{type: point, position: [1, 3, 1], intensity: [10, 10, 10]}]\n"
        "medium: {sigma_s: 0.05, sigma_a: 0.0}\n"
        "objects:\n  - {type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 10}\n"
        "  - {type: mesh, file: boxes.obj}\n")
    code, output = run_cli("render", scene, "-o", tmp_path / "b.png", "--stats")
    assert code == 0, output
    line = next(line for line in output.splitlines() if line.startswith("  host steps "))
    for step in ("load", "spatial order", "solids", "edge links"):
        assert f"{step} " in line and " ms" in line, line
