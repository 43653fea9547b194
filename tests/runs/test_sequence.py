"""`clrays sequence`: numbered frames, resume, animations, bad input, and a run killed
midway (a real process, a real signal) that resumes to the frames of an unbroken run."""
from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from clrays.session import Renderer
from clrays.scene.load import load_scene
from clrays.runs.sequence import check_pattern, parse_frames, render_sequence
from conftest import run_cli as run

SCENE = """\
version: 1
image: {width: 48, height: 32}
camera: {position: [0, 2, 8], look_at: [0, 1.5, 0], far: 30}
lights:
  - {type: point, position: [0.3, 5, -0.5], intensity: 80}
medium: {sigma_s: 0.06, sigma_a: 0.01}
objects:
  - {type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 12, segments: 2}
  - {type: box, min: [-2, 2.5, -3], max: [-1.6, 2.7, 3]}
  - {type: box, min: [0, 2.5, -3], max: [0.4, 2.7, 3]}
  - {type: sphere, center: [1.5, 0.8, 0.5], radius: 0.8, segments: 12}
render: {shadow_map: 256, slices: 128, gamma_samples: 256}
animation:
  fps: 12
  frames: [0, FRAMES]
  camera:
    - {frame: 0, position: [-4, 2, 7]}
    - {frame: FRAMES, position: [4, 3, 7]}
  objects:
    - object: 3
      keys:
        - {frame: 0, translate: [0, 0, 0], easing: ease_in_out}
        - {frame: FRAMES, translate: [-1, 0.5, 0]}
"""


def write_scene(folder: Path, frames: int) -> Path:
    path = folder / "scene.yaml"
    path.write_text(SCENE.replace("FRAMES", str(frames - 1)))
    return path




def frames_in(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.glob("f_*"))


def test_sequence_writes_every_frame_and_a_gif(tmp_path):
    scene = write_scene(tmp_path, 6)
    code, out = run("sequence", scene, "-o", tmp_path / "out" / "f_{:03d}.png", "--video", tmp_path / "a.gif",
                    "--stats", "--no-progress")
    assert code == 0, out
    assert frames_in(tmp_path / "out") == [f"f_{i:03d}.png" for i in range(6)]
    assert "6 frames rendered, 0 already there (of 6)" in out
    assert "frame 1:" in out and "reused:" in out and "raster.camera  computed 6" in out
    with Image.open(tmp_path / "a.gif") as gif:
        assert gif.n_frames == 6 and gif.size == (48, 32) and gif.info["duration"] in (80, 90)  # 1/12 s, in 10 ms
    first = np.asarray(Image.open(tmp_path / "out" / "f_000.png"))
    assert first.shape == (32, 48, 3) and first.max() > 0


def test_rerun_skips_finished_frames(tmp_path):
    scene = write_scene(tmp_path, 5)
    pattern = tmp_path / "f_{:03d}.npy"
    assert run("sequence", scene, "-o", pattern, "--frames", "1:2")[0] == 0
    assert frames_in(tmp_path) == ["f_001.npy", "f_002.npy"]
    before = (tmp_path / "f_001.npy").stat().st_mtime_ns
    code, out = run("sequence", scene, "-o", pattern)
    assert code == 0 and "3 frames rendered, 2 already there (of 5)" in out
    assert (tmp_path / "f_001.npy").stat().st_mtime_ns == before
    code, out = run("sequence", scene, "-o", pattern, "--overwrite", "--frames", "4")
    assert code == 0 and "1 frame rendered, 0 already there (of 1)" in out


def test_python_api_and_reuse_give_the_frames_of_independent_renders(tmp_path, device):
    scene = load_scene(write_scene(tmp_path, 4))
    report = render_sequence(scene, tmp_path / "f_{frame:02d}.npy", renderer=Renderer(device))
    assert report.rendered == [0, 1, 2, 3] and [p.name for p in report.paths] == ["f_00.npy", "f_01.npy",
                                                                                   "f_02.npy", "f_03.npy"]
    assert "raster.shadow" not in report.results[1].reused  # the sphere moves: it is in the light's map
    scratch = Renderer(device, reuse=False)
    for frame, path in zip(scene.animation.frames, report.paths):
        np.testing.assert_array_equal(np.load(path), scratch.render(scene.animation.scene_at(scene, frame)).image)


def test_a_scene_without_animation_is_one_frame(tmp_path):
    scene = tmp_path / "still.yaml"
    scene.write_text(SCENE.split("animation:")[0])
    code, out = run("sequence", scene, "-o", tmp_path / "f_{}.png")
    assert code == 0 and frames_in(tmp_path) == ["f_0.png"]


@pytest.mark.parametrize("args, message", [
    (["--frames", "3:1"], r"--frames 3:1: expected frames 0 <= A <= B <= 4 \(the scene's frames\), got 3:1"),
    (["--frames", "0:9"], r"--frames 0:9: expected frames 0 <= A <= B <= 4"),
    (["--frames", "a:b"], r"--frames a:b: expected A:B, A:, :B or N"),
    (["-o", "OUT/frame.png"], r"frame\.png: expected one \{\} field for the frame number"),
    (["-o", "OUT/f_{}_{}.png"], r"expected one \{\} field for the frame number .* got 2 fields"),
    (["-o", "OUT/f_{x}.png"], r"expected a frame pattern like frames/frame_\{:04d\}\.png"),
    (["-o", "OUT/f_{:04d}.jpg"], r"unknown frame extension '\.jpg'"),
    (["-o", "OUT/blocker/sub/f_{}.png"], r"cannot create folder"),
    (["--video", "OUT/a.mov"], r"a\.mov: unknown video extension '\.mov'; expected one of \.mp4, \.gif, \.webp$"),
    (["--video", "OUT/a.gif", "--crf", "20"], r"a\.gif: --crf and --video-option apply to \.mp4 only"),
    (["--video", "OUT/a.mp4", "--video-option", "preset"], r"--video-option preset: expected KEY=VALUE"),
    (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], r"give either --scheduler ADDRESS or --workers N"),
    (["--set", "animation.frames=[2,1]"], r"--set animation.frames=\[2,1\]: animation\.frames\.1: expected"),
])
def test_bad_input_is_one_line(tmp_path, args, message):
    import re

    scene = write_scene(tmp_path, 5)
    (tmp_path / "blocker").write_text("a file, not a folder")
    args = [a.replace("OUT", str(tmp_path)) for a in args]
    if "-o" not in args:
        args += ["-o", str(tmp_path / "f_{}.png")]
    code, out = run("sequence", scene, *args)
    assert code == 1, out
    assert len(out.strip().splitlines()) == 1 and re.search(message, out), out
    assert not frames_in(tmp_path)


def test_help_has_an_example():
    code, out = run("sequence", "--help")
    assert code == 0 and "clrays sequence scenes/orbit.yaml -o out/orbit/frame_{:04d}.png" in out


def test_parse_frames_and_pattern():
    assert parse_frames("2:", range(0, 10)) == range(2, 10) and parse_frames(":3", range(1, 10)) == range(1, 4)
    assert parse_frames("7", range(0, 10)) == range(7, 8) and parse_frames(None, range(3, 5)) == range(3, 5)
    assert check_pattern("a/{0:05d}.exr") == "a/{0:05d}.exr"


# --------------------------------------------------------------------------- killed midway

FRAMES_KILLED = 30


@pytest.fixture(scope="module")
def unbroken(tmp_path_factory, device):
    """The frames of an uninterrupted run (in this process: the same device and kernels)."""
    folder = tmp_path_factory.mktemp("unbroken")
    scene = write_scene(folder, FRAMES_KILLED)
    render_sequence(load_scene(scene), folder / "f_{:03d}.npy", renderer=Renderer(device))
    return folder


def _sequence_process(scene: Path, pattern: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "clrays.cli", "sequence", str(scene), "-o", str(pattern),
                             "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})


@pytest.mark.parametrize("signum", [signal.SIGKILL, signal.SIGTERM])
def test_killed_sequence_resumes_to_the_frames_of_an_unbroken_run(tmp_path, unbroken, signum):
    scene = write_scene(tmp_path, FRAMES_KILLED)
    pattern = tmp_path / "out" / "f_{:03d}.npy"
    process = _sequence_process(scene, pattern)
    deadline = time.monotonic() + 120
    while len(frames_in(tmp_path / "out") if (tmp_path / "out").exists() else []) < 3:
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, "the sequence did not start"
        time.sleep(0.005)
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=60)
    written = frames_in(tmp_path / "out")
    assert 3 <= len(written) < FRAMES_KILLED, "the run should have been stopped midway"
    if signum == signal.SIGKILL:
        assert process.returncode == -signal.SIGKILL
    else:  # a graceful stop: the half-written frame's temporary file is gone, and a hint says how to resume
        assert process.returncode == 130 and "run the same command again to resume" in stderr, stderr
        assert not list((tmp_path / "out").glob(".f_*")), "a temporary file was left behind"
    for name in written:  # what is there is complete
        np.testing.assert_array_equal(np.load(tmp_path / "out" / name), np.load(unbroken / name))

    # A kill between a frame's write and its manifest line leaves a file no run recorded as
    # finished: rendered again, and said so.
    recorded = set()
    for line in (tmp_path / "out" / ".clrays-frames.jsonl").read_text().splitlines():
        with contextlib.suppress(ValueError):  # a line the kill cut short
            recorded.add(json.loads(line)["file"])
    unrecorded = sorted(set(written) - recorded)
    assert len(unrecorded) <= 1, unrecorded  # only the frame the kill fell on

    resumed = _sequence_process(scene, pattern)
    stdout, stderr = resumed.communicate(timeout=300)
    assert resumed.returncode == 0, stderr
    again = " (1 of them replacing files no run recorded as finished)" if unrecorded else ""
    kept = len(written) - len(unrecorded)
    assert f"{FRAMES_KILLED - kept} frames rendered{again}, {kept} already there" in stdout, stdout
    assert frames_in(tmp_path / "out") == frames_in(unbroken)
    assert not list((tmp_path / "out").glob(".f_*"))
    for name in frames_in(unbroken):
        np.testing.assert_array_equal(np.load(tmp_path / "out" / name), np.load(unbroken / name), err_msg=name)


def test_render_one_frame_of_an_animation(tmp_path, device):
    scene = write_scene(tmp_path, 5)
    code, out = run("render", scene, "-o", tmp_path / "f3.npy", "--frame", "3")
    assert code == 0, out
    loaded = load_scene(scene)
    expected = Renderer(device, reuse=False).render(loaded.animation.scene_at(loaded, 3)).image
    np.testing.assert_array_equal(np.load(tmp_path / "f3.npy"), expected)
    code, out = run("render", scene, "-o", tmp_path / "f9.npy", "--frame", "9")
    assert code == 1 and "--frame 9: expected frames 0 <= A <= B <= 4" in out


def test_a_frame_of_a_still_scene_says_it_has_one(tmp_path):
    demo = Path(__file__).resolve().parents[2] / "scenes" / "demo.yaml"
    code, out = run("render", demo, "-o", tmp_path / "x.png", "--frame", "3")
    assert code == 1 and out.strip().splitlines()[-1].endswith(
        "--frame 3: the scene has no animation, so frame 0 alone; got 3:3")


def test_a_sequence_keeps_no_image_of_its_frames(tmp_path, renderer):
    """The frames are in their files: the report keeps each rendered frame's times and
    reuse, not its pixels, so a long sequence at a large size does not grow in memory."""
    from clrays import load_scene

    scene = load_scene(Path(__file__).resolve().parents[2] / "scenes" / "orbit.yaml", overrides=["image.width=16", "image.height=9"])
    report = render_sequence(scene, tmp_path / "f_{:02d}.npy", range(0, 2), renderer=renderer)
    assert sorted(report.results) == [0, 1]
    assert all(result.image.size == 0 and result.stage_ms for result in report.results.values())
