"""The command line: outputs in each format, and bad input as one line with exit code 1."""
import os
import re

import numpy as np
import pytest
from PIL import Image

from conftest import run_cli as run

SCENE = """version: 1
image: {width: 24, height: 16}
camera: {position: [0, 2, 8], look_at: [0, 1, 0], fov_deg: 50, far: 30}
lights:
  - {type: point, position: [0, 4, 0], intensity: 30}
medium: {sigma_s: 0.05, sigma_a: 0.01}
objects:
  - {type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 10, segments: 2}
  - {type: box, min: [-1, 2, -1], max: [1, 2.2, 1]}
render: {method: raymarch, steps: 64, shadow_map: 64}
"""


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_text(SCENE)
    return path




def test_render_writes_each_format(scene_file, tmp_path):
    code, out = run("render", scene_file, "-o", tmp_path / "a.npy")
    assert code == 0, out
    linear = np.load(tmp_path / "a.npy")
    assert linear.shape == (16, 24, 3) and linear.dtype == np.float32
    assert np.isfinite(linear).all() and linear.max() > 0

    assert run("render", scene_file, "-o", tmp_path / "a.png")[0] == 0
    png = np.asarray(Image.open(tmp_path / "a.png"))
    assert png.shape == (16, 24, 3) and png.dtype == np.uint8

    assert run("render", scene_file, "-o", tmp_path / "a.exr")[0] == 0
    import OpenEXR

    with OpenEXR.File(str(tmp_path / "a.exr")) as exr:
        np.testing.assert_array_equal(exr.channels()["RGB"].pixels, linear)


def test_png_is_srgb_encoded_with_exposure(scene_file, tmp_path):
    run("render", scene_file, "-o", tmp_path / "a.npy")
    run("render", scene_file, "-o", tmp_path / "b.png", "--exposure", "1")
    linear = np.clip(np.load(tmp_path / "a.npy") * 2.0, 0, 1)
    srgb = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
    png = np.asarray(Image.open(tmp_path / "b.png")).astype(float) / 255
    assert np.abs(png - srgb).max() <= 0.5 / 255 + 1e-6


def test_set_overrides_a_field_and_stats_prints_stages(scene_file, tmp_path):
    code, out = run("render", scene_file, "-o", tmp_path / "a.npy", "--set", "medium.sigma_s=0", "--stats")
    assert code == 0, out
    assert "raster" in out and "shade" in out and "device memory" in out
    assert re.search(r"^ +raymarch +- +skipped$", out, re.M), out  # sigma_s = 0: no volume stage ran
    clear = np.load(tmp_path / "a.npy")
    run("render", scene_file, "-o", tmp_path / "b.npy")
    foggy = np.load(tmp_path / "b.npy")
    # Sky pixels (nothing hit, black background) carry only in-scattered light.
    sky = foggy[0]
    assert (clear[0] == 0).all() and (sky > 0).all()


def test_info_lists_a_device():
    code, out = run("info")
    assert code == 0 and "*" in out


@pytest.mark.parametrize("edit, message", [
    (lambda s: s.replace("fov_deg: 50", "fov_deg: 190"), r"scene.yaml:3:\d+: camera.fov_deg: expected"),
    (lambda s: s.replace("intensity: 30", "intensity: -1"), r"lights.0.intensity"),
    (lambda s: s.replace("width: 24", "width: 0"), r"image.width"),
    (lambda s: s.replace("image:", "imagee:"), r"imagee"),
    (lambda s: s.replace("render:", "  - {type: mesh, file: missing.obj}\nrender:"), r"missing.obj"),
    (lambda s: s.replace("{width: 24", "{width: [24"), r"scene.yaml:\d+:\d+"),
])
def test_bad_scene_is_one_line_exit_1_and_no_output(scene_file, tmp_path, edit, message):
    import re

    scene_file.write_text(edit(SCENE))
    target = tmp_path / "out.png"
    code, out = run("render", scene_file, "-o", target)
    assert code == 1
    lines = out.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("clrays: error:"), out
    assert re.search(message, lines[0]), lines[0]
    assert "Traceback" not in out
    assert not target.exists()


@pytest.mark.parametrize("target, message", [
    ("out.jpg", "unknown output extension"),
    ("missing/out.png", "does not exist"),
    (".", "is a folder"),
])
def test_bad_output_path(scene_file, tmp_path, target, message):
    code, out = run("render", scene_file, "-o", tmp_path / target)
    assert code == 1 and message in out and len(out.strip().splitlines()) == 1


@pytest.mark.skipif(os.geteuid() == 0, reason="root can write anywhere")
def test_unwritable_output_folder(scene_file, tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    code, out = run("render", scene_file, "-o", locked / "a.png")
    assert code == 1 and "not writable" in out


def test_missing_scene_file(tmp_path):
    code, out = run("render", tmp_path / "nope.yaml", "-o", tmp_path / "a.png")
    assert code == 1 and "nope.yaml" in out


def test_usage_error_exits_2(scene_file):
    assert run("render", scene_file)[0] == 2  # missing -o
