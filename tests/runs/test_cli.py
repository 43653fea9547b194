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
    ("blocker/out.png", "cannot create the output folder"),  # a missing folder is created; a file is in the way
    (".", "is a folder"),
])
def test_bad_output_path(scene_file, tmp_path, target, message):
    (tmp_path / "blocker").write_text("a file, not a folder")
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


@pytest.mark.parametrize("command", [["render"], ["sequence"], ["sweep"], ["bench"]])
def test_a_folder_as_the_scene_is_one_line(tmp_path, command):
    out = tmp_path / ("o.png" if command == ["render"] else "o")
    extra = {"render": ["-o", out], "sequence": ["-o", tmp_path / "f_{:02d}.png"], "sweep": ["-o", out],
             "bench": ["--out", out, "--cache", tmp_path / "cache"]}[command[0]]
    code, output = run(*command, tmp_path, *extra)
    assert code == 1
    assert output.strip().count("\n") == 0 and "a directory" in output, output


def test_usage_error_exits_2(scene_file):
    assert run("render", scene_file)[0] == 2  # missing -o


@pytest.mark.parametrize("place", ["group", "command"])
def test_debug_shows_the_traceback_before_the_line(scene_file, tmp_path, place):
    scene_file.write_text(SCENE.replace("fov_deg: 50", "fov_deg: 190"))
    command = ["render", scene_file, "-o", tmp_path / "a.png"]
    code, out = run(*(["--debug", *command] if place == "group" else [*command, "--debug"]))
    assert code == 1 and "Traceback" in out and "SceneError" in out
    assert out.strip().splitlines()[-1].startswith("clrays: error: ")


def test_an_unexpected_failure_is_an_internal_error(scene_file, tmp_path, monkeypatch):
    def fail(*args, **kwargs):
        raise RuntimeError("boom")

    monkeypatch.setattr("clrays.cli.load_scene", fail)
    code, out = run("render", scene_file, "-o", tmp_path / "a.png")
    assert code == 1
    assert out.strip() == "clrays: internal error: RuntimeError: boom (run with --debug for the traceback)"


def test_a_reader_that_left_ends_the_run_quietly(scene_file, tmp_path, monkeypatch):
    def reader_left(*args, **kwargs):
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr("clrays.cli.load_scene", reader_left)
    code, out = run("render", scene_file, "-o", tmp_path / "a.png")
    assert code == 1 and "error" not in out


def test_info_lists_every_device_when_clrays_device_matches_none():
    from clrays.device import list_devices

    code, out = run("info", env={"CLRAYS_DEVICE": "no-such-device"})
    assert code == 0, out
    lines = out.strip().splitlines()
    assert len(lines) == len(list_devices()) + 1 and "*" not in out
    assert lines[-1].startswith("CLRAYS_DEVICE='no-such-device' matches none of these devices")
    code, out = run("info", "--device", "97:3")
    assert code == 0 and out.strip().splitlines()[-1].startswith("--device='97:3' matches none")


def test_stats_marks_the_host_stages(scene_file, tmp_path):
    code, out = run("render", scene_file, "-o", tmp_path / "a.npy", "--method", "minmax", "--stats")
    assert code == 0, out
    assert re.search(r"^ +integrand +[\d.]+ ms \(host\)", out, re.M), out
    assert re.search(r"^ +traverse +[\d.]+ ms \(device\)", out, re.M), out
    assert re.search(r"^ +shadows +\d+ shadow rays \(", out, re.M), out  # exact surface shadows, the default


def test_help_groups_options_and_commands():
    code, out = run("render", "--help")
    assert code == 0
    sections = [line for line in out.splitlines() if re.fullmatch(r"[A-Z]\w+:", line)]
    assert sections == ["Scene:", "Output:", "Run:", "Device:", "Other:"], sections
    assert "clrays render scenes/demo.yaml -o out/demo.png" in out
    code, out = run("--help")
    assert [line for line in out.splitlines() if line in ("Render:", "Study:", "Tools:")] == \
        ["Render:", "Study:", "Tools:"]


def test_method_choices_are_the_scene_models(scene_file, tmp_path):
    from clrays.scene.model import METHODS

    code, out = run("render", scene_file, "-o", tmp_path / "a.png", "--method", "fastest")
    assert code == 2 and all(method in out for method in METHODS)


def test_every_format_reads_back_as_the_png_it_would_have_been(tmp_path):
    from clrays.image_io import read_srgb8, write_image

    radiance = np.random.default_rng(7).uniform(0, 0.7, (5, 6, 3)).astype(np.float32)
    for name in ("a.png", "a.npy", "a.exr"):
        write_image(tmp_path / name, radiance, exposure=0.5)
    png = read_srgb8(tmp_path / "a.png")
    assert png.shape == (5, 6, 3) and png.dtype == np.uint8
    np.testing.assert_array_equal(read_srgb8(tmp_path / "a.npy", 0.5), png)
    np.testing.assert_array_equal(read_srgb8(tmp_path / "a.exr", 0.5), png)


def test_non_finite_render_and_unmakeable_folder_are_errors(tmp_path):
    from clrays.errors import ClraysError, OutputError
    from clrays.image_io import check_finite, make_folder

    with pytest.raises(ClraysError, match=r"^frame 3: the render produced non-finite values"):
        check_finite(np.array([[[0.0, np.nan, 1.0]]]), "frame 3")
    (tmp_path / "file").write_text("not a folder")
    with pytest.raises(OutputError, match=r"file/sub: cannot create the sweep folder: "):
        make_folder(tmp_path / "file" / "sub", "the sweep folder")
    assert make_folder(tmp_path / "a" / "b").is_dir()
