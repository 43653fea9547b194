"""Render passes on the command line: `--aov` and `render.aovs` write one multi-layer EXR
(R, G, B; `<pass>.R/.G/.B`; `depth.Z`) or, for .png and .npy, `<stem>.<pass>.<ext>` beside
the image, for `render` and `sequence`; without passes nothing else is written."""
import numpy as np
import OpenEXR
import pytest
from PIL import Image

from conftest import run_cli as run

SCENE = """version: 1
image: {width: 24, height: 16}
camera: {position: [0, 2, 8], look_at: [0, 1, 0], fov_deg: 50, far: 30}
lights:
  - {type: point, position: [0, 4, 0], intensity: 30}
  - {type: directional, direction: [0.3, -1, 0.2], irradiance: 0.5}
medium: {sigma_s: 0.05, sigma_a: 0.01}
objects:
  - {type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 10, segments: 2}
  - {type: box, min: [-1, 2, -1], max: [1, 2.2, 1]}
render: {method: minmax, shadow_map: 64}
"""
PASSES = "in_scatter,in_scatter_light0,in_scatter_light1,transmittance,surface,depth"


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_text(SCENE)
    return path


def test_exr_layers(scene_file, tmp_path):
    code, out = run("render", scene_file, "-o", tmp_path / "a.exr", "--aov", PASSES)
    assert code == 0, out
    assert run("render", scene_file, "-o", tmp_path / "a.npy", "--aov", PASSES)[0] == 0
    with OpenEXR.File(str(tmp_path / "a.exr"), separate_channels=True) as exr:
        channels = {name: np.asarray(channel.pixels) for name, channel in exr.channels().items()}
    layers = [f"{name}.{c}" for name in PASSES.split(",") if name != "depth" for c in "RGB"]
    assert sorted(channels) == sorted(["R", "G", "B", "depth.Z", *layers])
    beauty = np.load(tmp_path / "a.npy")
    np.testing.assert_array_equal(np.stack([channels[c] for c in "RGB"], axis=-1), beauty)
    for name in PASSES.split(","):
        stored = np.load(tmp_path / f"a.{name}.npy")
        got = channels["depth.Z"] if name == "depth" else np.stack([channels[f"{name}.{c}"] for c in "RGB"], -1)
        np.testing.assert_array_equal(got, stored)
    depth = channels["depth.Z"]
    assert np.isinf(depth).any() and np.isfinite(depth).any() and depth.shape == (16, 24)
    assert not (tmp_path / "a.in_scatter.exr").exists()


def test_png_and_npy_files(scene_file, tmp_path):
    code, out = run("render", scene_file, "-o", tmp_path / "b.png", "--aov", "in_scatter,depth")
    assert code == 0, out
    assert sorted(p.name for p in tmp_path.glob("b*.png")) == ["b.depth.png", "b.in_scatter.png", "b.png"]
    depth = np.asarray(Image.open(tmp_path / "b.depth.png"))
    assert depth.shape == (16, 24, 3) and depth.max() == 255 and depth.min() < 255  # white: no surface
    # The scene's own render.aovs, no --aov
    scene_file.write_text(SCENE.replace("render: {", "render: {aovs: [transmittance], "))
    assert run("render", scene_file, "-o", tmp_path / "c.npy")[0] == 0
    assert sorted(p.name for p in tmp_path.glob("c*.npy")) == ["c.npy", "c.transmittance.npy"]
    transmittance = np.load(tmp_path / "c.transmittance.npy")
    assert transmittance.shape == (16, 24, 3) and np.all((transmittance > 0) & (transmittance <= 1))


def test_no_pass_writes_only_the_image(scene_file, tmp_path):
    assert run("render", scene_file, "-o", tmp_path / "d.npy")[0] == 0
    assert [p.name for p in tmp_path.glob("d*")] == ["d.npy"]


def test_sequence_passes(tmp_path):
    scene = tmp_path / "orbit.yaml"
    scene.write_text(SCENE + "animation:\n  fps: 2\n  frames: [0, 2]\n  camera:\n"
                             "    - {frame: 0, position: [0, 2, 8]}\n    - {frame: 2, position: [2, 2, 8]}\n")
    code, out = run("sequence", scene, "-o", tmp_path / "f_{:02d}.npy", "--aov", "in_scatter,depth")
    assert code == 0, out
    names = sorted(p.name for p in tmp_path.glob("f_*"))
    assert names == sorted(f"f_{i:02d}{part}.npy" for i in range(3) for part in ("", ".in_scatter", ".depth"))


def test_a_resumed_sequence_keeps_each_frames_passes_its_own(tmp_path):
    """Run again with other passes, a frame is rendered again and its old pass files go with
    it (they were of another scene); a frame whose pass file is gone is rendered again."""
    scene = tmp_path / "orbit.yaml"
    scene.write_text(SCENE + "animation:\n  fps: 2\n  frames: [0, 1]\n  camera:\n"
                             "    - {frame: 0, position: [0, 2, 8]}\n    - {frame: 1, position: [2, 2, 8]}\n")
    pattern = tmp_path / "f_{:02d}.npy"
    assert run("sequence", scene, "-o", pattern, "--aov", "in_scatter")[0] == 0
    code, out = run("sequence", scene, "-o", pattern, "--aov", "depth")
    assert code == 0 and "2 frames rendered" in out, out
    assert sorted(p.name for p in tmp_path.glob("f_*")) == ["f_00.depth.npy", "f_00.npy", "f_01.depth.npy", "f_01.npy"]
    (tmp_path / "f_01.depth.npy").unlink()
    code, out = run("sequence", scene, "-o", pattern, "--aov", "depth")
    assert code == 0 and "1 frame rendered" in out and (tmp_path / "f_01.depth.npy").exists(), out
