"""Relief objects: the loader (images, holes, colours, one-line errors) and the mesh that
`clrays relief-to-mesh` writes (docs/design.md, "Relief objects")."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from clrays.errors import ClraysError, SceneError
from clrays.scene.load import load_scene
from clrays.runs.relief_mesh import relief_to_mesh

SCENE = """version: 1
image: {{width: 16, height: 12}}
camera: {{position: [0, 0, 5], look_at: [0, 0, 0]}}
lights: [{{type: point, position: [0, 3, 3], intensity: 10}}]
objects:
  - {{type: relief, center: [0, 0, 0], normal: [0, 0, 1], up: [0, 1, 0], size: [2, 1], depth_map: {depth},
     height: 0.5{extra}}}
"""


def _bump(rows=6, cols=8):
    y, x = np.mgrid[0:rows, 0:cols]
    return np.exp(-((x - cols / 2) ** 2 + (y - rows / 2) ** 2) / 4)


def _scene(tmp_path, depth="bump.npy", extra="", overrides=()):
    np.save(tmp_path / "bump.npy", _bump())
    path = tmp_path / "relief.yaml"
    path.write_text(SCENE.format(depth=depth, extra=extra))
    return load_scene(path, overrides)


def test_triangles_of_a_relief(tmp_path):
    geometry = _scene(tmp_path).geometry
    assert geometry.count == 2 * 5 * 7
    points = geometry.triangles.reshape(-1, 3)
    # Texel centres: a 2 × 1 rectangle of 8 × 6 texels, displaced along +z by 0.5 · depth.
    assert np.allclose(points[:, 0].min(), -1 + 1 / 8) and np.allclose(points[:, 1].max(), 0.5 - 1 / 12)
    assert np.isclose(points[:, 2].max(), 0.5 * _bump().max())
    assert (geometry.normals[:, 0, 2] > 0).all()  # faces along the normal


def test_row_zero_is_the_top_and_columns_run_right(tmp_path):
    depth = np.zeros((4, 4))
    depth[0, 3] = 1.0  # the top right texel
    np.save(tmp_path / "corner.npy", depth)
    geometry = _scene(tmp_path, "corner.npy").geometry
    top = geometry.triangles.reshape(-1, 3)[np.argmax(geometry.triangles.reshape(-1, 3)[:, 2])]
    assert top[0] > 0 and top[1] > 0


def test_png_8_and_16_bit_agree_with_npy(tmp_path):
    depth = _bump()
    Image.fromarray(np.round(depth * 65535).astype(np.uint16)).save(tmp_path / "d16.png")
    Image.fromarray(np.round(depth * 255).astype(np.uint8)).save(tmp_path / "d8.png")
    reference = _scene(tmp_path).geometry.triangles
    assert np.abs(_scene(tmp_path, "d16.png").geometry.triangles - reference).max() < 0.5 / 65535 + 1e-12
    assert np.abs(_scene(tmp_path, "d8.png").geometry.triangles - reference).max() < 0.5 / 255 + 1e-12


def test_alpha_zero_cuts_holes(tmp_path):
    depth = (_bump() * 255).astype(np.uint8)
    alpha = np.full_like(depth, 255)
    alpha[2, 3] = 0  # one texel: the four cells around it go
    Image.fromarray(np.dstack([depth, alpha]), "LA").save(tmp_path / "holes.png")
    assert _scene(tmp_path, "holes.png").geometry.count == 2 * 5 * 7 - 2 * 4


def test_albedo_map_colours_each_cell(tmp_path):
    colours = np.zeros((6, 8, 3))
    colours[:, :4] = [1.0, 0.0, 0.0]
    colours[:, 4:] = [0.0, 0.0, 1.0]
    np.save(tmp_path / "colours.npy", colours)
    geometry = _scene(tmp_path, extra=", albedo_map: colours.npy").geometry
    centroid_x = geometry.triangles[:, :, 0].mean(axis=1)
    assert np.allclose(geometry.albedo[centroid_x < -0.2], [1, 0, 0])
    assert np.allclose(geometry.albedo[centroid_x > 0.2], [0, 0, 1])


def test_height_zero_is_a_flat_quad(tmp_path):
    geometry = _scene(tmp_path, overrides=["objects.0.height=0"]).geometry
    assert geometry.count == 70 and np.abs(geometry.triangles[..., 2]).max() == 0


def test_transform_applies(tmp_path):
    moved = _scene(tmp_path, extra=", transform: {translate: [1, 2, 3]}").geometry.triangles
    assert np.allclose(moved - _scene(tmp_path).geometry.triangles, [1, 2, 3])


@pytest.mark.parametrize("override, message", [
    ("objects.0.depth_map=missing.png", r"objects\.0\.depth_map: expected a readable 2D image .*no such file"),
    ("objects.0.depth_map=bad.png", r"objects\.0\.depth_map: .*not a readable PNG image \(it does not start as one\)"),
    ("objects.0.depth_map=line.npy", r"objects\.0\.depth_map: .*not a 2D image \(an array of shape \(5,\)"),
    ("objects.0.depth_map=cube.npy", r"objects\.0\.depth_map: .*not a 2D image \(an array of shape \(3, 3, 3, 3\)"),
    ("objects.0.depth_map=depth.txt", r"objects\.0\.depth_map: .*unsupported image format '\.txt'"),
    ("objects.0.size=[0, 1]", r"objects\.0\.size\.0: expected a number > 0, got 0"),
    ("objects.0.size=[1, -2]", r"objects\.0\.size\.1: expected a number > 0, got -2"),
    ("objects.0.height=-0.1", r"objects\.0\.height: expected a number >= 0, got -0\.1"),
    ("objects.0.up=[0, 0, 3]", r"objects\.0\.up: expected a direction not parallel to normal"),
    ("objects.0.albedo_map=small.npy", r"objects\.0\.albedo_map: expected an image of the depth map's size, 8 × 6"),
])
def test_bad_relief_is_one_line(tmp_path, override, message):
    (tmp_path / "bad.png").write_bytes(b"not a png")
    (tmp_path / "depth.txt").write_text("1 2 3")
    np.save(tmp_path / "line.npy", np.zeros(5))
    np.save(tmp_path / "cube.npy", np.zeros((3, 3, 3, 3)))
    np.save(tmp_path / "small.npy", np.zeros((2, 2, 3)))
    with pytest.raises(SceneError, match=message) as caught:
        _scene(tmp_path, overrides=[override])
    assert "\n" not in str(caught.value)


def test_every_cell_a_hole_is_refused(tmp_path):
    np.save(tmp_path / "empty.npy", np.dstack([_bump(), np.zeros((6, 8))]))
    with pytest.raises(SceneError, match=r"objects\.0\.depth_map: .*every cell is a hole"):
        _scene(tmp_path, "empty.npy")


def test_relief_to_mesh_round_trip(tmp_path):
    scene = _scene(tmp_path, extra=", transform: {rotate: {axis: [0, 1, 0], angle_deg: 30}}")
    index, count = relief_to_mesh(tmp_path / "relief.yaml", tmp_path / "relief.ply")
    assert (index, count) == (0, scene.geometry.count)
    (tmp_path / "mesh.yaml").write_text(SCENE.format(depth="bump.npy", extra="").replace(
        "{type: relief, center: [0, 0, 0], normal: [0, 0, 1], up: [0, 1, 0], size: [2, 1], depth_map: bump.npy,\n"
        "     height: 0.5}", "{type: mesh, file: relief.ply, normals: flat}"))
    mesh = load_scene(tmp_path / "mesh.yaml").geometry
    # the same triangles, each matched by its centroid (a mesh file's are put in spatial order)
    centroids = mesh.triangles.mean(axis=1)[:, None] - scene.geometry.triangles.mean(axis=1)[None]
    match = np.linalg.norm(centroids, axis=2).argmin(axis=1)
    assert sorted(match.tolist()) == list(range(scene.geometry.count))
    assert np.abs(mesh.triangles - scene.geometry.triangles[match]).max() < 1e-6  # float32 in the PLY


def test_relief_to_mesh_refuses_a_scene_without_relief(tmp_path):
    (tmp_path / "plain.yaml").write_text(SCENE.format(depth="bump.npy", extra="").split("objects:")[0])
    with pytest.raises(ClraysError, match="expected at least one object of type relief"):
        relief_to_mesh(tmp_path / "plain.yaml", tmp_path / "x.ply")


def test_relief_to_mesh_command(tmp_path):
    _scene(tmp_path)
    run = lambda *args: subprocess.run([sys.executable, "-c", "import sys; from clrays.cli import main; sys.exit(main())",
                                        "relief-to-mesh", str(tmp_path / "relief.yaml"), *args],
                                       capture_output=True, text=True)
    done = run("-o", str(tmp_path / "r.obj"))
    assert done.returncode == 0 and "70 triangles" in done.stdout and (tmp_path / "r.obj").exists()
    refused = run("-o", str(tmp_path / "r.obj"), "--object", "3")
    assert refused.returncode == 1 and refused.stderr.count("\n") == 1 and "objects.3" in refused.stderr
