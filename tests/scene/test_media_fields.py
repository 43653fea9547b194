"""`medium.bounds` and `medium.density` (docs/scene-format.md, "Bounds and density"): what they
load into (clrays/scene/model.py: Box, HeightDensity, GridDensity), an animated grid or noise
offset, a glTF scene's default fog placed by YAML, and every bad input as one line."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from clrays.errors import ClraysError, SceneError
from clrays.scene import density_sources
from clrays.scene.animation import scene_at
from clrays.scene.gltf import default_medium, mesh_bounds
from clrays.scene.load import load_scene, parse_scene
from clrays.scene.model import Box, GridDensity, HeightDensity
from conftest import run_cli

ROOT = Path(__file__).resolve().parents[2]
HEAD = """version: 1
image: {width: 16, height: 8}
camera: {position: [0, 1, 5], look_at: [0, 1, 0], up: [0, 1, 0]}
lights: [{type: directional, direction: [0.2, -1, 0.1], irradiance: 2}]
"""


def _scene(tmp_path: Path, medium: str, extra: str = "", grid: np.ndarray | None = None):
    if grid is not None:
        np.save(tmp_path / "fog.npy", grid)
    path = tmp_path / "fog.yaml"
    path.write_text(HEAD + "medium:\n" + "".join(f"  {line}\n" for line in medium.strip().splitlines()) + extra)
    return load_scene(path)


def _fails(tmp_path, medium: str, match: str, grid=None, error=SceneError):
    with pytest.raises(error, match=match) as caught:
        _scene(tmp_path, medium, grid=grid)
    assert "\n" not in str(caught.value)
    return str(caught.value)


def test_a_medium_without_bounds_or_density_is_homogeneous(tmp_path):
    medium = _scene(tmp_path, "sigma_s: 0.1").medium
    assert medium.bounds is None and medium.density is None and medium.homogeneous


def test_bounds_and_height_density_load_into_the_model(tmp_path):
    medium = _scene(tmp_path, """
sigma_s: 0.1
bounds: {min: [-20, 0, -20], max: [20, 40, 20]}
density: {type: height, base: 1.5, scale_height: 2.5}
""").medium
    assert isinstance(medium.bounds, Box) and not medium.homogeneous
    np.testing.assert_array_equal(medium.bounds.min, [-20, 0, -20])
    np.testing.assert_array_equal(medium.bounds.max, [20, 40, 20])
    assert medium.density == HeightDensity(base=1.5, scale_height=2.5)


def test_a_grid_loads_from_its_file_moved_by_its_offset(tmp_path):
    values = np.random.default_rng(3).random((2, 3, 4)).astype(np.float32)
    medium = _scene(tmp_path, """
sigma_s: 0.1
density: {type: grid, file: fog.npy, bounds: {min: [-1, 0, -1], max: [1, 2, 1]}, offset: [0.5, 1, 0]}
""", grid=values).medium
    assert isinstance(medium.density, GridDensity)
    np.testing.assert_array_equal(medium.density.values, values)
    assert medium.density.values.dtype == np.float32 and medium.density.values.flags.c_contiguous
    np.testing.assert_array_equal(medium.density.bounds.min, [-0.5, 1, -1])
    np.testing.assert_array_equal(medium.density.bounds.max, [1.5, 3, 1])


def test_an_animated_grid_offset_moves_the_grid_each_frame(tmp_path):
    scene = _scene(tmp_path, """
sigma_s: 0.1
density: {type: grid, file: fog.npy, bounds: {min: [0, 0, 0], max: [1, 1, 1]}}
""", "animation:\n  frames: [0, 4]\n  medium: [{frame: 0, offset: [0, 0, 0]}, {frame: 4, offset: [2, 0, 0]}]\n",
        grid=np.ones((2, 2, 2), np.float32))
    for frame, x in ((0, 0.0), (2, 1.0), (4, 2.0)):
        bounds = scene_at(scene, frame).medium.density.bounds
        np.testing.assert_allclose(bounds.min, [x, 0, 0])
        np.testing.assert_allclose(bounds.max, [x + 1, 1, 1])


def test_noise_is_baked_by_the_sources_module_again_for_each_frame(tmp_path, monkeypatch):
    calls = []

    def bake(frequency, octaves, seed, offset, bounds, resolution, where):
        calls.append((frequency, octaves, seed, tuple(offset), tuple(resolution), where))
        nx, ny, nz = resolution
        return np.full((nz, ny, nx), float(offset[0]), np.float32)

    monkeypatch.setattr(density_sources, "bake_noise", bake)
    scene = _scene(tmp_path, """
sigma_s: 0.1
density: {type: noise, frequency: 0.5, octaves: 3, seed: 9, bounds: {min: [0, 0, 0], max: [4, 2, 4]},
          resolution: [8, 4, 6]}
""", "animation:\n  frames: [0, 2]\n  medium: [{frame: 0, offset: [0, 0, 0]}, {frame: 2, offset: [3, 0, 0]}]\n")
    density = scene.medium.density
    assert density.values.shape == (6, 4, 8)
    np.testing.assert_array_equal(density.bounds.max, [4, 2, 4])
    assert calls[0][:5] == (0.5, 3, 9, (0.0, 0.0, 0.0), (8, 4, 6)) and "medium.density" in calls[0][5]
    assert scene_at(scene, 1).medium.density.values[0, 0, 0] == pytest.approx(1.5)
    assert calls[-1][3] == (1.5, 0.0, 0.0)


def test_noise_without_its_extra_is_one_line_naming_it(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyfastnoiselite.pyfastnoiselite", None)  # as if not installed
    _fails(tmp_path, "density: {type: noise, bounds: {min: [0, 0, 0], max: [1, 1, 1]}}", r"`noise` extra",
           error=ClraysError)


def test_yaml_bounds_over_a_gltf_scene_keep_its_default_fog(tmp_path):
    path = tmp_path / "g.yaml"
    path.write_text(f"version: 1\nimage: {{width: 16, height: 8}}\ngltf: {{file: {ROOT / 'scenes' / 'colonnade.glb'}}}\n"
                    "medium: {bounds: {min: [-1, 0, -1], max: [1, 1, 1]}, density: {type: height, base: 0, "
                    "scale_height: 1}}\n")
    scene = load_scene(path)
    plain = load_scene(ROOT / "scenes" / "colonnade.glb")
    np.testing.assert_array_equal(scene.medium.sigma_s, plain.medium.sigma_s)
    np.testing.assert_array_equal(scene.medium.bounds.max, [1, 1, 1])
    assert scene.medium.density == HeightDensity(0.0, 1.0)
    # A medium with its own σ is the scene's own, as before.
    own = load_scene(path, ["medium.sigma_s=0.2"])
    np.testing.assert_array_equal(own.medium.sigma_s, [0.2, 0.2, 0.2])


# ------------------------------------------------------------------------- bad input


def test_bounds_with_min_above_max_name_the_axis_and_values(tmp_path):
    message = _fails(tmp_path, "bounds: {min: [0, 3, 0], max: [1, 1, 1]}", r"medium\.bounds: expected max > min")
    assert "y: min 3, max 1" in message and "fog.yaml:" in message


def test_a_grid_bounds_with_min_above_max_fails(tmp_path):
    _fails(tmp_path, "density: {type: grid, file: fog.npy, bounds: {min: [2, 0, 0], max: [1, 1, 1]}}",
           r"medium\.density\.bounds: expected max > min on every axis, got x: min 2, max 1",
           grid=np.ones((2, 2, 2), np.float32))


@pytest.mark.parametrize("height", ["0", "-1"])
def test_a_scale_height_not_above_zero_fails(tmp_path, height):
    _fails(tmp_path, f"density: {{type: height, base: 0, scale_height: {height}}}",
           r"medium\.density\.scale_height: expected a number > 0")


@pytest.mark.parametrize("medium, field", [
    ("bounds: {min: [0, .nan, 0], max: [1, 1, 1]}", r"medium\.bounds\.min\.1"),
    ("bounds: {min: [0, 0, 0], max: [1, .inf, 1]}", r"medium\.bounds\.max\.1"),
    ("density: {type: height, base: .nan, scale_height: 1}", r"medium\.density\.base"),
    ("density: {type: height, base: 0, scale_height: .inf}", r"medium\.density\.scale_height"),
])
def test_non_finite_numbers_fail(tmp_path, medium, field):
    _fails(tmp_path, medium, field + r": expected a finite number")


def test_an_unknown_density_type_fails(tmp_path):
    _fails(tmp_path, "density: {type: fractal}", r"medium\.density\.type: expected one of 'height', 'grid', 'noise'")


def test_a_key_of_another_density_type_fails(tmp_path):
    _fails(tmp_path, "density: {type: height, base: 0, scale_height: 1, file: x.npy}", r"medium\.density.*file")


@pytest.mark.parametrize("values, match", [
    (np.array([[[0.5, np.nan]]], np.float32), r"expected finite densities, got 1 NaN"),
    (np.array([[[0.5, -0.25]]], np.float32), r"expected densities ≥ 0, got -0.25"),
    (np.ones((4, 4), np.float32), r"expected a 3D grid \(axes z, y, x\), got shape \(4, 4\)"),
])
def test_a_bad_grid_file_is_one_line_naming_the_file_and_field(tmp_path, values, match):
    message = _fails(tmp_path, "density: {type: grid, file: fog.npy, bounds: {min: [0, 0, 0], max: [1, 1, 1]}}",
                     match, grid=values, error=ClraysError)
    assert "fog.yaml:" in message and "medium.density.file" in message


def test_an_absurd_grid_is_counted_from_its_header_before_reading(tmp_path):
    """A header announcing 4096³ floats over 80 bytes of file: refused by its count, not by a
    failed read or an allocation."""
    with open(tmp_path / "fog.npy", "wb") as file:
        np.lib.format.write_array_header_1_0(file, {"descr": "<f4", "fortran_order": False,
                                                    "shape": (4096, 4096, 4096)})
    _fails(tmp_path, "density: {type: grid, file: fog.npy, bounds: {min: [0, 0, 0], max: [1, 1, 1]}}",
           rf"expected at most {density_sources.GRID_VOXELS_MAX} voxels, got 68719476736", error=ClraysError)


def test_an_absurd_noise_resolution_is_refused_before_baking(tmp_path, monkeypatch):
    monkeypatch.setattr(density_sources, "bake_noise", lambda *a: pytest.fail("baked"))
    _fails(tmp_path, "density: {type: noise, bounds: {min: [0, 0, 0], max: [1, 1, 1]}, resolution: [4096, 4096, 4096]}",
           r"medium\.density\.resolution: expected at most \d+ voxels in all, got 4096 × 4096 × 4096")


def test_an_offset_track_without_a_grid_fails(tmp_path):
    with pytest.raises(SceneError, match=r"expected a medium with a grid or noise density"):
        _scene(tmp_path, "sigma_s: 0.1", "animation:\n  frames: [0, 1]\n  medium: [{frame: 0, offset: [0, 0, 0]}]\n")


def test_the_command_line_says_a_bad_grid_in_one_line(tmp_path):
    np.save(tmp_path / "fog.npy", np.array([[[1.0, -2.0]]], np.float32))
    path = tmp_path / "fog.yaml"
    path.write_text(HEAD + "medium: {sigma_s: 0.1, density: {type: grid, file: fog.npy, "
                           "bounds: {min: [0, 0, 0], max: [1, 1, 1]}}}\n")
    code, out = run_cli("render", path, "-o", tmp_path / "x.npy")
    assert code == 1
    assert out.strip().count("\n") == 0 and "medium.density.file: expected densities ≥ 0, got -2" in out
    assert not (tmp_path / "x.npy").exists()


def test_parse_scene_reads_the_density_relative_to_the_working_directory(tmp_path, monkeypatch):
    np.save(tmp_path / "fog.npy", np.ones((1, 1, 2), np.float32))
    monkeypatch.chdir(tmp_path)
    scene = parse_scene(HEAD + "medium: {density: {type: grid, file: fog.npy, bounds: {min: [0, 0, 0], "
                               "max: [1, 1, 1]}}}\n")
    assert scene.medium.density.values.shape == (1, 1, 2)


def test_a_grid_file_that_is_not_a_regular_file_is_refused(tmp_path):
    (tmp_path / "fog.npy").mkdir()
    _fails(tmp_path, "density: {type: grid, file: fog.npy, bounds: {min: [0, 0, 0], max: [1, 1, 1]}}",
           r"medium\.density\.file: .*fog\.npy: not a regular file", error=ClraysError)
