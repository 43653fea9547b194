"""What a hostile or careless user can do to the outputs of sequences, sweeps and the
other writers, and what clrays answers: frame patterns checked before they are formatted,
one run per output folder, frames tied to the bytes of their scene, manifests and CSVs
read as scene files are, a manifest that grows a line a frame, sweeps loaded a point at a
time and bounded, explicit `--set` keys, cached references that heal, full disks and
Ctrl-C that leave no temporary behind."""
from __future__ import annotations

import errno
import json
import os
import re
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from clrays.errors import ClraysError, OutputError
from conftest import run_cli as run

REPO = Path(__file__).resolve().parents[2]

ANIMATED = """\
version: 1
image: {width: WIDTH, height: HEIGHT}
camera: {position: [0, 2, 8], look_at: [0, 1.5, 0], far: 30}
lights:
  - {type: point, position: [0.3, 5, -0.5], intensity: 80}
medium: {sigma_s: 0.06, sigma_a: 0.01}
objects:
  - {type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 12, segments: 2}
  - {type: box, min: [-2, 2.5, -3], max: [-1.6, 2.7, 3]}
render: {shadow_map: 64, slices: 32, gamma_samples: 32, steps: 16}
animation:
  fps: 12
  frames: [0, LAST]
  camera:
    - {frame: 0, position: [-4, 2, 7]}
    - {frame: LAST, position: [4, 3, 7]}
"""


def animated(folder: Path, frames: int, width: int = 12, height: int = 8) -> Path:
    """A scene of `frames` frames; one frame: a still scene (no animation block)."""
    path = folder / f"anim_{frames}.yaml"
    text = ANIMATED if frames > 1 else ANIMATED[:ANIMATED.index("animation:")]
    path.write_text(text.replace("LAST", str(frames - 1)).replace("WIDTH", str(width)).replace("HEIGHT", str(height)))
    return path


def one_line(out: str) -> str:
    lines = out.strip().splitlines()
    assert len(lines) == 1, out
    return lines[0]


def temporaries(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if ".clrays-" in p.name and p.name not in (".clrays-lock",
                                                                                     ".clrays-frames.jsonl")]


_FRESH = """
import json, sys, time
from click.testing import CliRunner
from clrays.cli import main

start = time.perf_counter()
result = CliRunner().invoke(main, json.loads(sys.argv[1]))
seconds = time.perf_counter() - start
with open("/proc/self/status") as status:
    peak = next(int(line.split()[1]) for line in status if line.startswith("VmHWM:")) / 1024
print(json.dumps([result.exit_code, result.output, seconds, peak]))
"""


def fresh(*args, timeout: float = 120) -> tuple[int, str, float, float]:
    """The command line in a fresh process: (exit code, output, seconds, peak MB)."""
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    done = subprocess.run([sys.executable, "-c", _FRESH, json.dumps([str(a) for a in args])], capture_output=True,
                          text=True, env=env, timeout=timeout, cwd=REPO)
    assert done.returncode == 0, done.stderr[-2000:]
    code, out, seconds, peak = json.loads(done.stdout.strip().splitlines()[-1])
    return code, out, seconds, peak


# --------------------------------------------------------------------------- frame patterns


def test_a_huge_field_width_is_refused_before_formatting(tmp_path):
    # It made Python build a 1 GB file name: 4.8 GB and 25 s before "file name too long".
    code, out, seconds, peak = fresh("sequence", "scenes/demo.yaml", "-o", tmp_path / "x_{:0999999999d}.png")
    assert code == 1
    assert one_line(out) == (f"clrays: error: {tmp_path}/x_{{:0999999999d}}.png: field '{{:0999999999d}}': "
                             f"expected a width of at most 32, got 999999999")
    assert seconds < 20 and peak < 2000, (seconds, peak)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("field", ["{:c}", "{!r}", "{!s:>4}", "{:.3}", "{:{}}", "{0[0]}", "{frame.real}",
                                   "{:e}", "{:%}", "{:/>4}"])
def test_a_field_that_is_no_integer_format_is_one_line(tmp_path, field):
    # `{:c}` made frame 0 a NUL: `internal error: ValueError: embedded null byte`.
    code, out = run("sequence", "scenes/demo.yaml", "-o", tmp_path / f"x_{field}.png")
    assert code == 1
    assert re.fullmatch(r"clrays: error: .*: field '.*': expected a frame pattern like frames/frame_\{:04d\}\.png: "
                        r"its one field \{\}, \{0\} or \{frame\}, in an integer format .*", one_line(out)), out
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("name", ["x\x01{}.png", "x{}\x1b.png", "x{}\x7f.png"])
def test_control_characters_in_a_pattern_are_one_line(tmp_path, name):
    code, out = run("sequence", "scenes/demo.yaml", "-o", tmp_path / name)
    assert code == 1 and "expected no NUL or control characters in a frame pattern" in one_line(out)


@pytest.mark.parametrize("pattern, frame, name", [
    ("f_{}.png", 7, "f_7.png"), ("f_{:04d}.png", 7, "f_0007.png"), ("f_{frame:x>4}.png", 7, "f_xxx7.png"),
    ("f_{0:X}.png", 255, "f_FF.png"), ("f_{:_b}.png", 5, "f_101.png"), ("{:032d}.npy", 1, "0" * 31 + "1.npy"),
])
def test_integer_formats_of_the_frame_stand(pattern, frame, name):
    from clrays.runs.sequence import check_pattern, frame_path

    assert frame_path(check_pattern(pattern), frame).name == name


# --------------------------------------------------------------------------- one run per folder


_HOLD_LOCK = """
import sys, time
from clrays.image_io import folder_lock
with folder_lock(sys.argv[1]):
    print("locked", flush=True)
    time.sleep(120)
"""


@pytest.fixture
def held_lock(tmp_path):
    """A process holding the lock of tmp_path/out, as a running sequence or sweep does."""
    folder = tmp_path / "out"
    folder.mkdir()
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    holder = subprocess.Popen([sys.executable, "-c", _HOLD_LOCK, str(folder)], stdout=subprocess.PIPE, text=True,
                              env=env)
    assert holder.stdout.readline().strip() == "locked"
    yield folder, holder.pid
    holder.kill()
    holder.wait()


def test_a_second_sequence_into_a_folder_in_use_is_one_line(tmp_path, held_lock):
    folder, pid = held_lock
    code, out = run("sequence", animated(tmp_path, 3), "-o", folder / "f_{}.png", "--no-progress")
    assert code == 1
    assert re.fullmatch(rf"clrays: error: {re.escape(str(folder))}: in use by another clrays run \(pid {pid} on "
                        rf"\S+: clrays .*\); wait for it to end, or write elsewhere", one_line(out)), out
    assert not list(folder.glob("f_*"))


def test_a_second_sweep_into_a_folder_in_use_is_one_line(tmp_path, held_lock):
    folder, pid = held_lock
    code, out = run("sweep", animated(tmp_path, 1), "--set", "medium.sigma_s=0.02,0.05", "-o", folder)
    assert code == 1
    assert f"in use by another clrays run (pid {pid} on " in one_line(out), out
    assert not list(folder.glob("*.png"))


def test_two_sequences_into_one_folder_leave_each_frame_its_scenes(tmp_path):
    """Run A, and run B with another --set into the same folder while A runs: B stops at
    once naming A; after A is stopped, B's frames are B's, as rendered on their own."""
    scene = animated(tmp_path, 400, 24, 16)
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    shared, alone = tmp_path / "shared" / "f_{:03d}.npy", tmp_path / "alone" / "f_{:03d}.npy"
    a = subprocess.Popen([sys.executable, "-m", "clrays.cli", "sequence", str(scene), "-o", str(shared),
                          "--no-progress"], stderr=subprocess.PIPE, text=True, env=env, cwd=REPO)
    try:
        start = time.perf_counter()
        first = tmp_path / "shared" / "f_000.npy"
        while not first.exists() and a.poll() is None and time.perf_counter() - start < 60:
            time.sleep(0.05)
        code, out = run("sequence", scene, "-o", shared, "--no-progress", "--set", "medium.sigma_s=0.3",
                        "--frames", "0:3")
        assert a.poll() is None, "run A ended before run B started: make it longer"
        assert code == 1 and f"in use by another clrays run (pid {a.pid} on " in one_line(out), out
    finally:
        a.send_signal(signal.SIGINT)
        a.communicate(timeout=60)
    b = ["--no-progress", "--set", "medium.sigma_s=0.3", "--frames", "0:3"]
    code, out = run("sequence", scene, "-o", shared, *b)
    # A's frames there (as many as it wrote) are replaced, none is kept.
    assert code == 0 and re.search(r"4 frames rendered( \(\d of them replacing frames of a changed scene\))?, "
                                   r"0 already there", out), out
    assert run("sequence", scene, "-o", alone, *b)[0] == 0
    for frame in range(4):
        np.testing.assert_array_equal(np.load(str(shared).format(frame)), np.load(str(alone).format(frame)))


def test_a_folder_named_with_literal_braces_is_the_one_locked():
    """`{{1}}` in a pattern is a folder named `{1}`, not the frame's field: the run locks it,
    not the folder above it."""
    from clrays.runs.sequence import frame_path, lock_folder

    assert lock_folder("out{{1}}/f_{:03d}.png") == Path("out{1}") == frame_path("out{{1}}/f_{:03d}.png", 7).parent
    assert lock_folder("out/{:04d}/beauty.png") == Path("out") and lock_folder("f_{}.png") == Path(".")


def test_frames_in_folders_of_their_own_lock_the_folder_above(tmp_path):
    from clrays.image_io import folder_lock

    pattern = tmp_path / "out" / "{:02d}" / "beauty.npy"
    code, out = run("sequence", animated(tmp_path, 3), "-o", pattern, "--no-progress")
    assert code == 0, out
    assert sorted(p.parent.name for p in (tmp_path / "out").glob("*/beauty.npy")) == ["00", "01", "02"]
    assert all((tmp_path / "out" / f"{n:02d}" / ".clrays-frames.jsonl").exists() for n in range(3))
    with folder_lock(tmp_path / "out"):
        code, out = run("sequence", animated(tmp_path, 3), "-o", pattern, "--no-progress")
        assert code == 1 and "in use by another clrays run" in one_line(out)


def test_the_lock_is_released_when_the_run_ends(tmp_path):
    from clrays.image_io import folder_lock

    with folder_lock(tmp_path):
        with pytest.raises(OutputError, match=r"in use by another clrays run \(pid \d+"):
            with folder_lock(tmp_path):
                pass
    with folder_lock(tmp_path):  # free again
        pass


def test_frames_of_another_scene_are_never_kept(tmp_path):
    """Two runs that wrote into one folder left run A's images under run B's digests, and
    B's rerun said "0 frames rendered, 60 already there". A frame now counts as finished
    only when its bytes are those its scene's run wrote."""
    scene = animated(tmp_path, 4)
    a, b = tmp_path / "a", tmp_path / "b"
    assert run("sequence", scene, "-o", a / "f_{}.npy", "--no-progress")[0] == 0
    assert run("sequence", scene, "-o", b / "f_{}.npy", "--no-progress", "--set", "medium.sigma_s=0.3")[0] == 0
    # What an interleaving of A and B could leave: B's manifest, A's images.
    for frame in range(4):
        (b / f"f_{frame}.npy").write_bytes((a / f"f_{frame}.npy").read_bytes())
    code, out = run("sequence", scene, "-o", b / "f_{}.npy", "--no-progress", "--set", "medium.sigma_s=0.3")
    assert code == 0 and "4 frames rendered (4 of them replacing frames of a changed scene), 0 already there" in out
    for frame in range(4):
        assert not np.array_equal(np.load(b / f"f_{frame}.npy"), np.load(a / f"f_{frame}.npy"))
    code, out = run("sequence", scene, "-o", b / "f_{}.npy", "--no-progress", "--set", "medium.sigma_s=0.3")
    assert code == 0 and "0 frames rendered, 4 already there" in out


def test_the_points_of_a_sweep_are_tied_to_their_images(tmp_path):
    scene = animated(tmp_path, 1)
    args = ["sweep", scene, "--set", "medium.sigma_s=0.02,0.3", "-o", tmp_path / "out", "--format", "npy"]
    assert run(*args)[0] == 0
    (tmp_path / "out" / "001.npy").write_bytes((tmp_path / "out" / "000.npy").read_bytes())  # another run's image
    code, out = run(*args)
    assert code == 0 and "1 point rendered, 1 kept from an earlier run" in out
    assert not np.array_equal(np.load(tmp_path / "out" / "001.npy"), np.load(tmp_path / "out" / "000.npy"))


# --------------------------------------------------------------------------- manifests and CSVs


def _fifo(path: Path) -> None:
    os.mkfifo(path)


def _zero(path: Path) -> None:
    path.symlink_to("/dev/zero")


#: What a manifest or a results.csv that is no regular file is said to be: a link (even to
#: /dev/zero) is not followed (clrays.outputs).
NO_REGULAR_FILE = [(_fifo, "not a regular file (a FIFO)"), (_zero, "a symbolic link, which clrays does not follow here")]


@pytest.mark.parametrize("make, kind", NO_REGULAR_FILE)
def test_a_manifest_that_is_no_regular_file_is_one_line(tmp_path, make, kind):
    # A FIFO hung the run; a link to /dev/zero took 7.5 GB, then `internal error`.
    (tmp_path / "out").mkdir()
    make(tmp_path / "out" / ".clrays-frames.jsonl")
    code, out, seconds, peak = fresh("sequence", animated(tmp_path, 2), "-o", tmp_path / "out" / "f_{}.png",
                                     "--no-progress", timeout=60)
    assert code == 1
    assert one_line(out) == (f"clrays: error: {tmp_path}/out/.clrays-frames.jsonl: cannot read the frame manifest: "
                             f"{kind}; remove it (its frames are rendered again)")
    assert seconds < 20 and peak < 2000, (seconds, peak)


@pytest.mark.parametrize("make, kind", NO_REGULAR_FILE)
def test_a_results_csv_that_is_no_regular_file_is_one_line(tmp_path, make, kind):
    (tmp_path / "out").mkdir()
    make(tmp_path / "out" / "results.csv")
    code, out, seconds, peak = fresh("sweep", animated(tmp_path, 1), "--set", "medium.sigma_s=0.02,0.05", "-o",
                                     tmp_path / "out", "--no-progress", timeout=60)
    assert code == 1
    assert one_line(out) == (f"clrays: error: {tmp_path}/out/results.csv: cannot read the results of an earlier run: "
                             f"{kind}; remove it (its points are rendered again)")
    assert seconds < 20 and peak < 2000, (seconds, peak)


def test_a_torn_manifest_line_costs_its_frame_alone(tmp_path):
    scene = animated(tmp_path, 3)
    args = ["sequence", scene, "-o", tmp_path / "out" / "f_{}.npy", "--no-progress"]
    assert run(*args)[0] == 0
    manifest = tmp_path / "out" / ".clrays-frames.jsonl"
    lines = manifest.read_text().splitlines()
    assert len(lines) == 3 and all(json.loads(line)["file"] == f"f_{n}.npy" for n, line in enumerate(lines))
    manifest.write_text("\n".join(lines[:2]) + "\n" + lines[2][:20])  # a crash in the middle of the last append
    code, out = run(*args)
    assert code == 0 and "1 frame rendered (1 of them replacing files no run recorded as finished), 2 already there" in out
    assert manifest.read_text().endswith("\n") and len(manifest.read_text().splitlines()) == 3


# --------------------------------------------------------------------------- an incremental manifest


def test_recording_a_frame_costs_the_same_however_many_came_before(tmp_path):
    """The manifest was rewritten whole for every frame: 20 000 frames rendered nothing in
    120 s. A frame now appends one line."""
    from clrays.runs.frame_manifest import FrameManifest

    def seconds_per_record(before: int) -> float:
        folder = tmp_path / str(before)
        folder.mkdir()
        (folder / ".clrays-frames.jsonl").write_text("".join(
            json.dumps({"file": f"g_{n}.png", "digest": "d" * 32, "content": "c" * 32}) + "\n" for n in range(before)))
        manifest = FrameManifest(folder)
        assert len(manifest.entries) == before
        start = time.perf_counter()
        for n in range(300):
            manifest.record(folder / f"f_{n}.png", "d" * 32, "c" * 32)
        return (time.perf_counter() - start) / 300

    small, large = seconds_per_record(0), seconds_per_record(20_000)
    assert large < 5 * small + 1e-4, (small, large)
    assert len((tmp_path / "20000" / ".clrays-frames.jsonl").read_text().splitlines()) == 20_300


def test_a_sequence_of_20000_frames_starts_at_once(tmp_path):
    scene = animated(tmp_path, 20_000, width=1, height=1)
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    out = tmp_path / "out"
    start = time.perf_counter()
    process = subprocess.Popen([sys.executable, "-m", "clrays.cli", "sequence", str(scene), "-o",
                                str(out / "f_{:05d}.png"), "--no-progress"], stderr=subprocess.PIPE, text=True,
                               env=env, cwd=REPO)
    try:
        while not (out / "f_00000.png").exists() and process.poll() is None and time.perf_counter() - start < 60:
            time.sleep(0.05)
        first = time.perf_counter() - start
    finally:
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=60)
    assert (out / "f_00000.png").exists(), stderr
    # Start-up (imports, device, kernels from the cache) included; the whole manifest was
    # rewritten for every frame before the first rendered.
    assert first < 20, f"{first:.1f} s to the first frame"
    assert process.returncode == 130 and "clrays: interrupted after" in stderr, stderr


@pytest.mark.slow
def test_a_sequence_runs_in_linear_time(tmp_path, renderer):
    """5000 frames at 1×1: the first comes at once (the whole manifest used to be written
    once per frame before any render: about 875 MB of JSON here), and the last frames
    cost what the first ones did."""
    from clrays.runs.sequence import render_sequence
    from clrays.scene.load import load_scene

    scene = load_scene(animated(tmp_path, 5000, width=1, height=1))
    render_sequence(scene, tmp_path / "warm" / "f_{}.png", range(0, 2), renderer=renderer)  # kernels built
    times = []
    start = time.perf_counter()
    render_sequence(scene, tmp_path / "out" / "f_{}.png", renderer=renderer,
                    on_frame=lambda frame, path, result: times.append(time.perf_counter()))
    assert len(times) == 5000
    assert times[0] - start < 2.0, f"{times[0] - start:.1f} s to the first frame"
    per_frame = np.diff(times)
    early, late = np.median(per_frame[100:600]), np.median(per_frame[-500:])
    assert late < 2 * early, (early, late)


# --------------------------------------------------------------------------- sweeps


def test_a_sweep_of_a_million_points_is_one_line(tmp_path):
    # Three axes of 100 values rendered nothing in 120 s while memory grew.
    values = ",".join(str(0.01 + n / 1000) for n in range(100))
    code, out, seconds, peak = fresh("sweep", animated(tmp_path, 1), "--set", f"medium.sigma_s={values}",
                                     "--set", f"medium.sigma_a={values}", "--set", f"lights.0.intensity={values}",
                                     "-o", tmp_path / "out")
    assert code == 1
    assert one_line(out) == ("clrays: error: --set: 100 × 100 × 100 = 1000000 points, more than the limit of 10000; "
                             "sweep fewer values (docs/limits.md)")
    assert seconds < 20 and peak < 2000, (seconds, peak)
    assert not (tmp_path / "out").exists()


def test_a_large_sweep_starts_at_once(tmp_path):
    """Every point's scene used to be loaded (twice) before the first rendered."""
    scene = animated(tmp_path, 1, width=1, height=1)
    values = ",".join(str(0.01 + n / 1000) for n in range(100))
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    out = tmp_path / "out"
    start = time.perf_counter()
    process = subprocess.Popen([sys.executable, "-m", "clrays.cli", "sweep", str(scene), "--set",
                                f"medium.sigma_s={values}", "--set", "lights.0.position=[0.3, 5, -0.5],[0.4, 5, -0.5]",
                                "--set", "medium.sigma_a=" + ",".join(str(0.001 * n) for n in range(1, 11)),
                                "-o", str(out), "--no-progress"],
                               stderr=subprocess.PIPE, text=True, env=env, cwd=REPO)
    images = lambda: [p for p in out.glob("[0-9]*.png")]  # noqa: E731 - not a temporary (.NAME.clrays-...)
    try:
        while not images() and process.poll() is None and time.perf_counter() - start < 60:
            time.sleep(0.05)
        first = time.perf_counter() - start
    finally:
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=60)
    assert images(), stderr
    assert first < 20, f"{first:.1f} s to the first point of {100 * 2 * 10}"
    assert process.returncode == 130 and "clrays: interrupted after" in stderr, stderr


def test_the_axis_order_matches_the_order_of_loaded_scenes(tmp_path):
    from clrays.runs.sweep import (Axis, axes_execution_order, check_values, execution_order, sweep_points)
    from clrays.scene.load import load_scene

    scene = animated(tmp_path, 1)
    axes = [Axis("medium.sigma_s", ("0.02", "0.05", "0.02")), Axis("camera.fov_deg", ("40", "50")),
            Axis("lights.0.position", ("[0, 5, 0]", "[1, 5, 0]"))]
    points = sweep_points(axes)
    loaded = execution_order(points, [load_scene(scene, point.overrides) for point in points])
    assert [p.index for p in axes_execution_order(points, axes, check_values(scene, axes))] == \
           [p.index for p in loaded]
    # The light's position (the shadow maps) varies slowest, then the camera; sigma_s last.
    assert [p.index for p in loaded][:3] == [0, 4, 8]


@pytest.mark.parametrize("settings, message", [
    (["medium.sigma_s=0.3,0.4", "medium={sigma_a: 0.2},{sigma_a: 0.1}"],
     "--set medium={sigma_a: 0.2},{sigma_a: 0.1}: medium sets the key holding --set medium.sigma_s=0.3,0.4; "
     "the later would replace the earlier: give each key once"),
    (["k=0.9", "k=0.3,0.4"], "--set k=0.3,0.4: k sets the same key as --set k=0.9; the later would replace the "
                             "earlier: give each key once"),
    (["medium={sigma_a: 0.2}", "medium.sigma_s=0.3"], "--set medium.sigma_s=0.3: medium.sigma_s sets a key inside "
                                                      "--set medium={sigma_a: 0.2}"),
    (["lights.0.intensity=1,2", "lights.00.intensity=3"], "lights.0.intensity sets the same key as"),
])
def test_overlapping_keys_of_a_sweep_are_one_line(tmp_path, settings, message):
    # The first axis was silently dropped, and results.csv labelled identical renders with
    # different sigma_s; `k=0.9` was silently ignored.
    args = [a for setting in settings for a in ("--set", setting)]
    code, out = run("sweep", animated(tmp_path, 1), *args, "-o", tmp_path / "out")
    assert code == 1 and message in one_line(out), out
    assert not (tmp_path / "out").exists()
    from clrays.runs.sweep import parse_settings

    with pytest.raises(ClraysError, match=re.escape(message)):
        parse_settings(settings)


def test_overrides_and_axes_of_the_python_api_overlap_too(tmp_path):
    from clrays.runs.sweep import sweep_scenes

    with pytest.raises(ClraysError, match="medium.sigma_s sets the same key as --set medium.sigma_s=0.1"):
        list(sweep_scenes(animated(tmp_path, 1), {"medium.sigma_s": [0.02, 0.05]}, overrides=["medium.sigma_s=0.1"]))


# --------------------------------------------------------------------------- cached references


@pytest.mark.parametrize("damage", ["garbage", "truncated", "shape", "pickle"])  # a FIFO: test_hostile_writes.py
def test_a_corrupted_reference_is_rendered_again(tmp_path, damage):
    # `internal error`, and the run did not recover.
    scene = animated(tmp_path, 1)
    args = ["sweep", scene, "--set", "medium.sigma_s=0.02,0.05", "--reference", "raymarch:8", "-o", tmp_path / "out",
            "--no-progress", "--format", "npy"]
    code, out = run(*args)
    assert code == 0, out
    cached = sorted((tmp_path / "out" / ".references").glob("raymarch8-*.npy"))
    assert len(cached) == 2
    good = np.load(cached[0])
    if damage == "garbage":
        cached[0].write_bytes(b"\x93NUMPY garbage" * 10)
    elif damage == "truncated":
        cached[0].write_bytes(cached[0].read_bytes()[:200])
    elif damage == "shape":
        np.save(cached[0], good[:2])
    else:
        np.save(cached[0], np.array([{"a": 1}], dtype=object), allow_pickle=True)
    code, out = run(*args, "--overwrite")
    assert code == 0, out
    notices = [line for line in out.splitlines() if "unreadable cached reference" in line]
    assert len(notices) == 1, out
    assert notices[0].startswith(f"clrays: notice: {cached[0]}: unreadable cached reference ("), out
    assert notices[0].endswith("computing it again"), out
    np.testing.assert_array_equal(np.load(cached[0]), good)  # replaced by the reference, as rendered again
    assert "internal error" not in out


# --------------------------------------------------------------------------- full disks


@pytest.mark.parametrize("suffix", [".png", ".npy", ".exr"])
def test_a_full_disk_is_one_line_and_leaves_no_temporary(tmp_path, monkeypatch, suffix):
    # An .exr onto a full disk: `internal error: RuntimeError … No space left`.
    import OpenEXR
    from PIL import Image

    from clrays.image_io import write_image

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Image.Image, "save", full)
    monkeypatch.setattr(np, "save", full)
    monkeypatch.setattr(OpenEXR, "File", FullExrFile)
    with pytest.raises(OutputError) as caught:
        write_image(tmp_path / f"a{suffix}", np.ones((4, 6, 3), np.float32))
    assert str(caught.value) == f"{tmp_path}/a{suffix}: cannot write: No space left on device"
    assert not list(tmp_path.iterdir())


class FullExrFile:
    """OpenEXR.File on a full disk: it writes part of the file, then reports the failure
    as OpenEXR does (a RuntimeError naming the file)."""

    def __init__(self, *args):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc_info):
        return False

    def write(self, name):
        Path(name).write_bytes(b"partial")
        raise RuntimeError(f'Failed to write pixel data to image file "{name}". No space left on device')


def _limit_file_size(limit: int):
    """A process's file-size limit: a write past it fails with EFBIG, as one past a full
    disk fails with ENOSPC (SIGXFSZ ignored so that the write fails rather than the process)."""
    def apply() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


def _limited(args: list, limit: int) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.run([sys.executable, "-m", "clrays.cli", *map(str, args)], capture_output=True, text=True,
                          env=env, cwd=REPO, timeout=120, preexec_fn=_limit_file_size(limit))


@pytest.mark.parametrize("suffix", [".ply", ".obj", ".stl"])
def test_relief_to_mesh_onto_a_full_disk_leaves_nothing(tmp_path, suffix):
    # It left a partial file and `internal error: OSError`.
    out = tmp_path / f"lattice{suffix}"
    done = _limited(["relief-to-mesh", "scenes/lattice.yaml", "-o", out], 4096)
    assert done.returncode == 1, done.stderr
    assert one_line(done.stderr) == f"clrays: error: {out}: cannot write: File too large"
    assert not list(tmp_path.iterdir())


def test_a_sequence_onto_a_full_disk_leaves_nothing(tmp_path, monkeypatch):
    # In this process: a file-size limit would stop the OpenCL compiler's cache as well.
    import OpenEXR

    monkeypatch.setattr(OpenEXR, "File", FullExrFile)
    code, out = run("sequence", animated(tmp_path, 2), "-o", tmp_path / "out" / "f_{}.exr", "--no-progress")
    assert code == 1
    assert one_line(out) == f"clrays: error: {tmp_path}/out/f_0.exr: cannot write: No space left on device"
    assert not temporaries(tmp_path) and not list((tmp_path / "out").glob("f_*"))


# --------------------------------------------------------------------------- Ctrl-C


def _interrupt_sequence(tmp_path: Path, delay: float, index: int) -> None:
    """Start a sequence, wait for its first frame, then SIGINT `delay` s later: one line,
    exit 130, no temporary, and every frame file there is of the manifest's bytes."""
    from clrays.image_io import file_digest

    scene = animated(tmp_path, 200, 96, 64)
    out = tmp_path / f"out{index}"
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    process = subprocess.Popen([sys.executable, "-m", "clrays.cli", "sequence", str(scene), "-o",
                                str(out / "f_{:03d}.exr"), "--no-progress"], stderr=subprocess.PIPE, text=True,
                               env=env, cwd=REPO)
    start = time.perf_counter()
    while not (out / "f_000.exr").exists() and process.poll() is None and time.perf_counter() - start < 60:
        time.sleep(0.01)
    time.sleep(delay)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    assert re.fullmatch(r"clrays: interrupted after \d+ new frames?; run the same command again to resume",
                        stderr.strip().splitlines()[-1]), stderr
    assert not temporaries(out), temporaries(out)
    entries = [json.loads(line) for line in (out / ".clrays-frames.jsonl").read_text().splitlines()]
    for entry in entries:
        assert file_digest(out / entry["file"]) == entry["content"]


@pytest.mark.parametrize("delay", [0.0, 0.13])
def test_ctrl_c_during_a_sequence_leaves_no_temporary(tmp_path, delay):
    _interrupt_sequence(tmp_path, delay, 0)


@pytest.mark.slow
def test_ctrl_c_at_many_moments_leaves_no_temporary(tmp_path):
    # A 0-byte temporary was left in 3 of 27 tries, and the line was missing in those.
    for index, delay in enumerate(np.linspace(0.0, 0.5, 16)):
        _interrupt_sequence(tmp_path, float(delay), index)


@pytest.mark.parametrize("command", ["sequence", "sweep"])
def test_an_interrupt_after_one_frame_or_point_says_it_in_the_singular(tmp_path, monkeypatch, command):
    # It said "interrupted after 1 new frames".
    from types import SimpleNamespace

    import clrays.cli as cli

    def one_then_interrupt(*args, on_frame=None, on_point=None, **kwargs):
        if on_frame:
            on_frame(0, tmp_path / "f_0.png", SimpleNamespace(wall_ms=1.0))
        else:
            on_point(SimpleNamespace(index=0, label="medium.sigma_s=0.02"), {"wall_ms": "1"})
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "render_sequence" if command == "sequence" else "run_sweep", one_then_interrupt)
    scene = animated(tmp_path, 2)
    args = ["-o", tmp_path / "f_{}.png"] if command == "sequence" else ["--set", "medium.sigma_s=0.02,0.05", "-o",
                                                                        tmp_path / "out"]
    code, out = run(command, scene, *args, "--no-progress")
    noun = "new frame" if command == "sequence" else "point"
    assert code == 130 and out.strip().splitlines()[-1] == (f"clrays: interrupted after 1 {noun}; run the same command "
                                                            f"again to resume"), out


def test_an_interrupt_while_the_temporary_is_created_leaves_nothing(tmp_path, monkeypatch):
    import clrays.image_io as image_io

    real_create = image_io._create

    def create_then_interrupt(temporary):
        real_create(temporary)
        raise KeyboardInterrupt  # after the file exists, before write_atomic has seen it returned

    monkeypatch.setattr(image_io, "_create", create_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        image_io.write_image(tmp_path / "a.png", np.ones((2, 2, 3), np.float32))
    assert not list(tmp_path.iterdir())


# --------------------------------------------------------------------------- folders and times


def test_render_creates_its_output_folder(tmp_path):
    out = tmp_path / "new" / "deeper" / "a.npy"
    code, out_text = run("render", animated(tmp_path, 1), "-o", out)
    assert code == 0, out_text
    assert np.load(out).shape == (8, 12, 3)
    mesh = tmp_path / "meshes" / "lattice.ply"
    code, out_text = run("relief-to-mesh", "scenes/lattice.yaml", "-o", mesh)
    assert code == 0 and mesh.stat().st_size > 0, out_text


def test_a_bad_render_creates_no_folder(tmp_path):
    code, out = run("render", tmp_path / "missing.yaml", "-o", tmp_path / "new" / "a.png")
    assert code == 1 and not (tmp_path / "new").exists(), out


def test_a_points_wall_time_leaves_out_kernel_builds(tmp_path, monkeypatch):
    """wall_ms jumped for some points where the warm-up's kinds did not cover a program
    the point needed; a build during the render is now build_ms, left out of wall_ms."""
    import clrays.runs.point as point
    from clrays.scene.load import load_scene
    from clrays.session import Renderer

    scene = load_scene(animated(tmp_path, 1))
    renderer = Renderer()  # a device of its own: it builds every program
    monkeypatch.setattr(point, "_warm_up", lambda *args: 0.0)  # a kind the warm-up missed
    start = time.perf_counter()
    row = point.render_point(renderer, None, None, point.SweepPoint(0, ()), scene, tmp_path, "000.npy", "d", 0.0,
                             set())
    elapsed_ms = (time.perf_counter() - start) * 1e3
    assert float(row["build_ms"]) > 0 and 0 < float(row["wall_ms"]) < elapsed_ms - float(row["build_ms"])
    again = point.render_point(renderer, None, None, point.SweepPoint(1, ()), scene, tmp_path, "001.npy", "d", 0.0,
                               set())
    assert float(again["build_ms"]) == 0.0


def test_the_warm_up_covers_each_size_on_a_cpu_device(tmp_path, renderer):
    """On a CPU device PoCL compiles a kernel for each new work-group size, which follow
    the render's sizes: a first point at 1024 slices took 0.9 s against 0.1 s."""
    from clrays.runs.point import _warm_up
    from clrays.scene.load import load_scene

    scene = animated(tmp_path, 1)
    warmed: set = set()
    assert _warm_up(renderer, load_scene(scene), warmed) > 0
    assert _warm_up(renderer, load_scene(scene, ["medium.sigma_s=0.3"]), warmed) == 0.0
    again = _warm_up(renderer, load_scene(scene, ["render.slices=64"]), warmed)
    assert (again > 0) == renderer.device.is_cpu


def test_counted_launches_use_few_work_group_sizes(device):
    """The fix-up walks' count follows the scene; a work-group dividing it was a new size
    (and a PoCL compile of about 450 ms) at nearly every point of a sweep."""
    launches = [device.counted_launch(count) for count in range(1, 30_000, 7)]
    assert all(size[0] >= count for size, count in zip((g for g, _ in launches), range(1, 30_000, 7)))
    if device.is_cpu:
        groups = {local for _, local in launches}
        assert len(groups) <= 13 and all(g[0] & (g[0] - 1) == 0 for g in groups)
        assert all(size[0] % local[0] == 0 for size, local in launches)
