"""Every reproduction of the second and third hostile-input probes, each run by the command line in a
fresh process against the clrays of a given tree: exit code, lines of output, the last
line, wall seconds and peak resident memory, as a markdown table.

    .venv/bin/python bench/hostile.py                      # this tree's clrays
    .venv/bin/python bench/hostile.py --repo /other/tree   # another tree's, same inputs
    .venv/bin/python bench/hostile.py --only scheduler --out /tmp/hostile

A case is flagged when its output holds `internal error` or a `Traceback`, when it ends
in more than one line or exits 0 where an error is expected (or exits non-zero where a
valid render is expected), or when it takes more than 20 s or 2 GB. The inputs are built
in a temporary folder (or --out, which is kept) by the builders of the tests that hold
the same reproductions (tests/scene/test_hostile.py and its neighbours), from this
script's tree; only the clrays that runs them comes from --repo.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

HERE = Path(__file__).resolve().parents[1]
_ENVIRONMENT = dict(os.environ)  # before the tests' conftest pins CLRAYS_DEVICE for its own session
for folder in ("tests/runs", "tests/scene", "tests", ""):
    sys.path.insert(0, str(HERE / folder))

import numpy as np  # noqa: E402

import test_hostile as scene_inputs  # noqa: E402  (tests/scene/)
from test_confine import FIELDS, outside_names, write_asset  # noqa: E402
from test_distributed import Listener  # noqa: E402  (tests/runs/)
from test_hostile_outputs import animated  # noqa: E402  (tests/runs/)
from test_sequence import write_scene  # noqa: E402
import test_gltf  # noqa: E402  (tests/scene/)
import test_gltf_budget as gltf_inputs  # noqa: E402  (tests/scene/)

SECONDS = 20.0
PEAK_MB = 2000.0
TIMEOUT_S = 60.0  # a case still running then is killed (and flagged by its time)
TIME = shutil.which("time", path="/usr/bin") or None  # GNU time: the child's peak RSS, %M in KB
#: Lines a command may print besides its one error line, each labelled as such.
LABELLED = re.compile(r"^clrays: (notice: |exact: \d+% |exact on .*\(estimate\)$|frame \d+: |point \d+: )")
HUNDRED_VALUES = ",".join(str(0.01 + n / 1000) for n in range(100))
#: A count of one with its noun in the plural ("1 frames rendered", "after 1 new frames").
ONE_IN_THE_PLURAL = re.compile(r"(?<![\d.,])1 (new )?(frames|points)\b")

# Run the child by a wrapper that reports its peak RSS where GNU time is missing.
_RUSAGE_WRAPPER = """
import resource, signal, subprocess, sys
signal.signal(signal.SIGINT, lambda *_: None)  # Ctrl-C is the child's (a handler, unlike SIG_IGN, is not inherited)
code = subprocess.call(sys.argv[2:])
with open(sys.argv[1], "w") as f:
    f.write(str(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss))
sys.exit(code if code >= 0 else 128 - code)
"""


@dataclass
class Result:
    code: int
    output: str
    seconds: float
    peak_mb: float
    problems: list[str] = field(default_factory=list)
    note: str = ""


@dataclass
class Case:
    name: str
    build: Callable[[Path], list]  # the case's folder -> the command line's arguments
    expect: str = "error"  # error | ok | recover | interrupted
    env: dict | None = None
    check: Callable[[Path, Result], list[str]] | None = None  # further problems, from the folder's contents
    run: Callable[["Probe", Path], Result] | None = None  # a case of several processes runs itself
    limit_file_bytes: int | None = None


class Process:
    """The command line in a new process (its own process group), timed, its peak RSS
    measured by GNU time or the rusage wrapper."""

    def __init__(self, probe: "Probe", args: list, cwd: Path, env: dict | None = None,
                 limit_file_bytes: int | None = None):
        self.peak_file = Path(tempfile.mkstemp(prefix="peak-", dir=probe.times)[1])
        command = [sys.executable, "-m", "clrays.cli", *map(str, args)]
        if TIME:
            command = [TIME, "-f", "%M", "-o", str(self.peak_file), *command]
        else:
            command = [sys.executable, "-c", _RUSAGE_WRAPPER, str(self.peak_file), *command]
        self.start = time.perf_counter()
        self.popen = subprocess.Popen(command, cwd=cwd, env={**probe.env, **(env or {})}, stdout=subprocess.PIPE,
                                      stderr=subprocess.STDOUT, text=True, errors="replace", start_new_session=True,
                                      preexec_fn=_limit_file_size(limit_file_bytes) if limit_file_bytes else None)

    def signal(self, number: int) -> None:
        # The group: GNU time ignores SIGINT while it waits, the clrays process beneath it takes it.
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.popen.pid, number)

    def finish(self, timeout: float = TIMEOUT_S) -> Result:
        try:
            output, _ = self.popen.communicate(timeout=max(1.0, timeout - (time.perf_counter() - self.start)))
            timed_out = False
        except subprocess.TimeoutExpired:
            self.signal(signal.SIGKILL)
            output, _ = self.popen.communicate()
            timed_out = True
        seconds = time.perf_counter() - self.start
        numbers = [line for line in self.peak_file.read_text().splitlines() if line.strip().isdigit()]
        peak = int(numbers[-1]) / 1024 if numbers else float("nan")
        self.peak_file.unlink()
        result = Result(self.popen.returncode, output, seconds, peak)
        if timed_out:
            result.problems.append(f"killed after {timeout:g} s")
        return result


def _limit_file_size(limit: int):
    """A write past `limit` bytes fails with EFBIG, as one onto a full disk fails with ENOSPC."""
    def apply() -> None:
        import resource

        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


class Probe:
    def __init__(self, tree: Path, out: Path):
        self.tree, self.out = tree, out
        self.times = out / ".peaks"
        self.times.mkdir(parents=True, exist_ok=True)
        self.env = {**_ENVIRONMENT, "PYTHONPATH": str(tree), "PYTHONUNBUFFERED": "1"}

    def spawn(self, args: list, cwd: Path, **options) -> Process:
        return Process(self, args, cwd, **options)

    def run(self, args: list, cwd: Path, **options) -> Result:
        timeout = options.pop("timeout", TIMEOUT_S)
        return self.spawn(args, cwd, **options).finish(timeout)


#: The running probe (main): the builders' tree and environment.
PROBE: Probe | None = None


# --------------------------------------------------------------------------- inputs


def png_of_zeros(path: Path, width: int, height: int, channels: int = 4) -> Path:
    """A real PNG of width × height zero texels (RGBA or grey), compressed a row at a time:
    13000² RGBA is the probe's 657 KB file, which decodes to 676 MB."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    compressor, row = zlib.compressobj(9), bytes(1 + width * channels)
    data = b"".join([compressor.compress(row) for _ in range(height)] + [compressor.flush()])
    color = {1: 0, 4: 6}[channels]
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, color, 0, 0, 0))
                     + chunk(b"IDAT", data) + chunk(b"IEND", b""))
    return path


def grid_png(path: Path) -> Path:
    """A 4096² grey PNG of a grid of lines (27 KB), the gobo of sixteen_gobo_lights."""
    from PIL import Image

    pixels = np.zeros((4096, 4096), np.uint8)
    pixels[::64], pixels[:, ::64] = 255, 255
    Image.fromarray(pixels).save(path)
    return path


def render(build: Callable[[Path], tuple]) -> Callable[[Path], list]:
    """`render SCENE -o out.png EXTRA` of a builder of test_hostile.CASES: (scene, extra)."""
    def args(d: Path) -> list:
        scene, extra = build(d)
        return ["render", scene, "-o", d / "out.png", *extra]
    return args


def from_tests(name: str) -> Callable[[Path], list]:
    builders = {case[0]: case[1] for case in scene_inputs.CASES}
    return render(builders[name])


def demo(probe: Probe) -> Path:
    return probe.tree / "scenes" / "demo.yaml"


def nothing_written(*names: str) -> Callable[[Path, Result], list[str]]:
    def check(d: Path, result: Result) -> list[str]:
        return [f"{name} written" for name in names if list(d.glob(name))]
    return check


# --------------------------------------------------------------------------- servers for --scheduler


def closed_port() -> str:
    with socket.create_server(("127.0.0.1", 0)) as free:
        return f"tcp://127.0.0.1:{free.getsockname()[1]}"  # nothing listens once closed


def scheduler_case(name: str, address: Callable[[], tuple[str, Listener | None]]) -> Case:
    def run(probe: Probe, d: Path) -> Result:
        target, listener = address()
        try:
            return probe.run(["sweep", write_scene(d, 2), "--set", "render.slices=32,64", "--scheduler", target,
                              "-o", d / "sweep"], d)
        finally:
            if listener:
                listener.close()
    return Case(name, lambda d: [], run=run)


def listening(greeting: bytes | None) -> Callable[[], tuple[str, Listener]]:
    def start() -> tuple[str, Listener]:
        listener = Listener(greeting)
        return listener.address, listener
    return start


# --------------------------------------------------------------------------- cases of several processes


def two_runs_in_one_folder(simultaneous: bool) -> Callable[[Probe, Path], Result]:
    """Run A, and run B with another --set into the same folder, B once A has written a
    frame or both at the same moment: one of them fails in one line naming the other. Once
    the other is stopped, it run again over the frames it wrote renders none: every frame
    there is its scene's. The row is the failing run's."""
    def run(probe: Probe, d: Path) -> Result:
        scene = animated(d, 400, 24, 16)
        shared = d / "shared" / "f_{:03d}.npy"
        commands = {"A": ["sequence", scene, "-o", shared, "--no-progress"],
                    "B": ["sequence", scene, "-o", shared, "--no-progress", "--set", "medium.sigma_s=0.3"]}
        runs = {"A": probe.spawn(commands["A"], d)}
        start = time.perf_counter()
        while not simultaneous and not (d / "shared" / "f_000.npy").exists() and runs["A"].popen.poll() is None \
                and time.perf_counter() - start < 30:
            time.sleep(0.05)
        runs["B"] = probe.spawn(commands["B"], d)
        while all(process.popen.poll() is None for process in runs.values()) and time.perf_counter() - start < 30:
            time.sleep(0.05)
        loser = "B" if runs["B"].popen.poll() is not None else "A"
        winner = "A" if loser == "B" else "B"
        group = _group(runs[winner].popen.pid)
        result = runs[loser].finish()
        while not (d / "shared" / "f_000.npy").exists() and runs[winner].popen.poll() is None \
                and time.perf_counter() - start < 30:
            time.sleep(0.05)
        runs[winner].signal(signal.SIGINT)
        stopped = runs[winner].finish()
        if stopped.code != 130:
            result.problems.append(f"run {winner}: exit {stopped.code} on SIGINT: {stopped.output.strip()[-300:]}")
        if not simultaneous and loser != "B":
            result.problems.append("run A failed, not B")
        pid = re.search(r"in use by another clrays run \(pid (\d+)", result.output)
        if not pid:
            result.problems.append(f"run {loser} does not say the folder is in use by another run")
        elif int(pid.group(1)) not in group:
            result.problems.append(f"run {loser} names pid {pid.group(1)}, not run {winner}'s")
        written = sorted(int(p.stem[2:]) for p in (d / "shared").glob("f_*.npy"))
        if not written or written != list(range(len(written))):
            result.problems.append(f"frames written: {written[:10]}")
            return result
        again = probe.run([*commands[winner], "--frames", f"0:{len(written) - 1}"], d)
        expected = f"0 frames rendered, {len(written)} already there"
        if again.code != 0 or expected not in again.output:
            result.problems.append(f"{winner} again: exit {again.code}, expected {expected!r}: "
                                   f"{again.output.strip()[-300:]}")
        result.note = (f"{loser} failed; {winner} wrote {len(written)} frames; "
                       f"{winner} again: {_last_line(again.output)}")
        return result
    return run


def _group(pid: int) -> set[int]:
    """The process `pid` and its children (GNU time's child is the clrays process)."""
    found = {pid}
    with contextlib.suppress(OSError):
        found |= {int(child) for child in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()}
    return found


def twenty_thousand_frames(probe: Probe, d: Path) -> Result:
    """A sequence of 20 000 frames at 1×1 writes its first frame within 5 s (the whole
    manifest was written for every frame before any render): stopped at its first frame."""
    scene = animated(d, 20_000, width=1, height=1)
    process = probe.spawn(["sequence", scene, "-o", d / "out" / "f_{:05d}.png", "--no-progress"], d)
    first = d / "out" / "f_00000.png"
    while not first.exists() and process.popen.poll() is None and time.perf_counter() - process.start < 30:
        time.sleep(0.02)
    to_first = time.perf_counter() - process.start
    process.signal(signal.SIGINT)
    result = process.finish()
    if not first.exists():
        result.problems.append("no first frame")
    elif to_first > 5.0:
        result.problems.append(f"first frame after {to_first:.1f} s (> 5 s)")
    if result.code != 130 or "clrays: interrupted after" not in result.output:
        result.problems.append("no 'interrupted after' line on SIGINT, exit 130")
    result.note = f"first frame after {to_first:.1f} s"
    return result


def interrupted_sequence(delay: float) -> Callable[[Probe, Path], Result]:
    """SIGINT `delay` s after a sequence's first frame: exit 130, the "interrupted after N"
    line, no temporary left, every frame file of its manifest's bytes."""
    def run(probe: Probe, d: Path) -> Result:
        scene = animated(d, 200, 96, 64)
        out = d / "out"
        process = probe.spawn(["sequence", scene, "-o", out / "f_{:03d}.exr", "--no-progress"], d)
        while not (out / "f_000.exr").exists() and process.popen.poll() is None and \
                time.perf_counter() - process.start < 30:
            time.sleep(0.01)
        time.sleep(delay)
        process.signal(signal.SIGINT)
        result = process.finish()
        if not re.fullmatch(r"clrays: interrupted after \d+ new frames?; run the same command again to resume",
                            _last_line(result.output)):
            result.problems.append("the last line is not 'interrupted after N new frames'")
        left = [p.name for p in out.rglob("*") if ".clrays-" in p.name and p.name not in (".clrays-lock",
                                                                                         ".clrays-frames.jsonl")]
        if left:
            result.problems.append(f"temporaries left: {left}")
        manifest = out / ".clrays-frames.jsonl"
        if manifest.exists():
            from clrays.image_io import file_digest

            for line in manifest.read_text().splitlines():
                entry = json.loads(line)
                if file_digest(out / entry["file"]) != entry["content"]:
                    result.problems.append(f"{entry['file']}: not its manifest's bytes")
        return result
    return run


def damaged_reference(d: Path) -> list:
    """A sweep with a cached reference, then the cache's first file replaced by garbage."""
    scene = animated(d, 1)
    args = ["sweep", scene, "--set", "medium.sigma_s=0.02,0.05", "--reference", "raymarch:8", "-o", d / "out",
            "--no-progress", "--format", "npy"]
    subprocess.run([sys.executable, "-m", "clrays.cli", *map(str, args)], cwd=d, env=PROBE.env, capture_output=True,
                   timeout=TIMEOUT_S)
    cached = sorted((d / "out" / ".references").glob("*.npy"))
    if cached:
        cached[0].write_bytes(b"\x93NUMPY garbage" * 10)
    return [*args, "--overwrite"]


def exr_onto_a_full_disk(probe: Probe, d: Path) -> Result:
    """A 160×90 .exr (about 100 KB) rendered into a 64 KiB tmpfs (mounting one needs root):
    one line, and nothing left in it."""
    full = d / "full"
    full.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(full)], capture_output=True,
                             text=True)
    if mounted.returncode != 0:
        return Result(-1, f"probe: cannot mount a tmpfs: {mounted.stderr.strip()}", 0.0, float("nan"),
                      ["not run (mounting a tmpfs needs root)"])
    try:
        result = probe.run(["render", demo(probe), "-o", full / "a.exr", "--set", "image.width=160", "--set",
                            "image.height=90"], d)
        left = [p.name for p in full.iterdir()]
        if left:
            result.problems.append(f"left on the full disk: {left}")
        return result
    finally:
        subprocess.run(["umount", str(full)], capture_output=True)


def exr_under_a_file_limit(d: Path) -> list:
    """The same render under a 16 KiB file-size limit (EFBIG, as ENOSPC), once it has run
    without it so that its kernels are in the OpenCL compiler's cache."""
    args = ["render", demo(PROBE), "-o", d / "a.exr", "--set", "image.width=160", "--set", "image.height=90"]
    subprocess.run([sys.executable, "-m", "clrays.cli", *map(str, args)], cwd=d, env=PROBE.env, capture_output=True,
                   timeout=TIMEOUT_S)
    size = (d / "a.exr").stat().st_size
    if size <= 16384:
        raise RuntimeError(f"the unlimited render wrote {size} bytes, within the limit")
    (d / "a.exr").unlink()
    return args


def manifest_fifo(d: Path) -> list:
    (d / "out").mkdir()
    os.mkfifo(d / "out" / ".clrays-frames.jsonl")
    return ["sequence", animated(d, 2), "-o", d / "out" / "f_{}.png", "--no-progress"]


def manifest_zero(d: Path) -> list:
    (d / "out").mkdir()
    (d / "out" / ".clrays-frames.jsonl").symlink_to("/dev/zero")
    return ["sequence", animated(d, 2), "-o", d / "out" / "f_{}.png", "--no-progress"]


def results_fifo(d: Path) -> list:
    (d / "out").mkdir()
    os.mkfifo(d / "out" / "results.csv")
    return ["sweep", animated(d, 1), "--set", "medium.sigma_s=0.02,0.05", "-o", d / "out", "--no-progress"]


def results_zero(d: Path) -> list:
    (d / "out").mkdir()
    (d / "out" / "results.csv").symlink_to("/dev/zero")
    return ["sweep", animated(d, 1), "--set", "medium.sigma_s=0.02,0.05", "-o", d / "out", "--no-progress"]


def confined(field_name: str, how: str, via_environment: bool = False) -> Case:
    """A scene in service/scenes/ naming a file outside its folder (`..`, absolute, a link
    inside pointing out) in `field_name`, rendered with --confine or CLRAYS_CONFINE=1."""
    def build(d: Path) -> list:
        scenes, secret = d / "service" / "scenes", d / "secret"
        scenes.mkdir(parents=True)
        write_asset(scenes / "d.npy")
        text, suffix = FIELDS[field_name]
        name = outside_names(scenes, secret, suffix)[how] if how != "root" else "../../../../../../anything" + suffix
        (scenes / "scene.yaml").write_text(text.replace("FILE", name))
        return ["render", scenes / "scene.yaml", "-o", d / "out.png", *([] if via_environment else ["--confine"])]
    by = "CLRAYS_CONFINE=1" if via_environment else "--confine"
    return Case(f"{by}: {field_name} {how}", build, env={"CLRAYS_CONFINE": "1"} if via_environment else None,
                check=nothing_written("out.png"))


def video(option: str) -> Case:
    def build(d: Path) -> list:
        return ["sequence", write_scene(d, 2), "-o", d / "f_{}.png", "--video", d / "a.mp4", "--video-option",
                option.format(elsewhere=d / "elsewhere.mp4")]
    return Case(f"--video-option {option.format(elsewhere='PATH')}", build,
                check=nothing_written("a.mp4", "elsewhere.mp4", "f_*.png"))


def says(*wanted: str, never: tuple[str, ...] = ()) -> Callable[[Path, Result], list[str]]:
    def check(d: Path, result: Result) -> list[str]:
        return [f"no {text!r}" for text in wanted if text not in result.output] + \
               [f"says {text!r}" for text in never if text in result.output]
    return check


# --------------------------------------------------------------------------- round three: glTF


def gltf_file(make: Callable[[Path], "test_gltf.GltfBuilder | bytes"], name: str = "scene.glb"):
    """`render` of the glTF file `make` builds (a lit GltfBuilder, or a file's bytes), small."""
    def args(d: Path) -> list:
        made = make(d)
        path = d / name
        path.write_bytes(made if isinstance(made, bytes) else made.glb())
        return ["render", path, "-o", d / "out.png", "--set", "image.width=32", "--set", "image.height=18"]
    return args


def accessors_without_views(d: Path):
    b = test_gltf._lit(test_gltf.GltfBuilder())
    indices = b.accessor([0, 1, 2], 5125)
    for _ in range(24):
        gltf_inputs._triangle_on(b, gltf_inputs._zeros(b), indices)
    return b


def one_accessor_many_primitives(d: Path):
    b = test_gltf._lit(test_gltf.GltfBuilder())
    shared = gltf_inputs._zeros(b)
    b.doc["accessors"][shared]["sparse"] = {
        "count": 3, "indices": {"bufferView": b.doc["accessors"][b.accessor([5, 70, 900], 5125)]["bufferView"],
                                "componentType": 5125},
        "values": {"bufferView": b.doc["accessors"][b.accessor(test_gltf.TRIANGLE)]["bufferView"]}}
    indices = b.accessor([5, 70, 900], 5125)
    for _ in range(24):
        gltf_inputs._triangle_on(b, shared, indices)
        gltf_inputs._triangle_on(b, shared, indices, mode=0)
    return b


def many_nodes_and_keys(d: Path):
    b, first, _ = test_gltf.deep_chain()  # lit already
    times = np.linspace(0.0, 4.0, 400)
    for k in range(40):
        b.animate(first + k * 1000, "translation", times,
                  np.stack([np.full(400, 0.001), 0.01 * np.sin(times * (k + 1)), np.zeros(400)], axis=1))
    return b


def one_png_many_images(d: Path):
    b = test_gltf._lit(test_gltf.GltfBuilder())
    (d / "texture.png").write_bytes(gltf_inputs._png())
    gltf_inputs._textured(b, [{"uri": "texture.png"}] * 200)
    return b


def many_decoded_images(d: Path):
    data = gltf_inputs._png()
    b = test_gltf._lit(test_gltf.GltfBuilder())
    b.doc["bufferViews"] += [{"buffer": 0, "byteOffset": len(b.binary), "byteLength": len(data)}] * 200
    b.binary += data
    gltf_inputs._textured(b, [{"bufferView": k, "mimeType": "image/png"} for k in range(200)])
    return b


def empty_chunks(d: Path) -> bytes:
    b = test_gltf._lit(test_gltf.GltfBuilder())
    b.mesh(test_gltf.TRIANGLE, [[0, 1, 2]])
    b.node(mesh=0)
    return gltf_inputs._glb_with_chunks(b, struct.pack("<II", 0, 0x58595A57) * 19_000_000)


# --------------------------------------------------------------------------- round three: writes through links


VICTIM_TEXT = "the victim's own bytes\n"


def linked_manifest(d: Path) -> list:
    """out/.clrays-frames.jsonl -> ../victim.txt: the manifest's read and append."""
    (d / "victim.txt").write_text(VICTIM_TEXT)
    (d / "out").mkdir()
    (d / "out" / ".clrays-frames.jsonl").symlink_to("../victim.txt")
    return ["sequence", animated(d, 2), "-o", d / "out" / "f_{}.png", "--no-progress"]


def linked_references(d: Path) -> list:
    """out/.references -> ../elsewhere: a sweep's reference caches."""
    (d / "out").mkdir()
    (d / "elsewhere").mkdir()
    (d / "out" / ".references").symlink_to("../elsewhere")
    return ["sweep", animated(d, 1), "--set", "medium.sigma_s=0.02,0.05", "--reference", "raymarch:8", "-o",
            d / "out", "--no-progress"]


def victim_untouched(d: Path, result: Result) -> list[str]:
    victim = d / "victim.txt"
    problems = ["victim.txt changed"] if victim.exists() and victim.read_text() != VICTIM_TEXT else []
    return problems + (["elsewhere/ written"] if (d / "elsewhere").exists() and any((d / "elsewhere").iterdir())
                       else [])


def target_error_scene(d: Path) -> Path:
    """A 32×18 animated scene that asks for render.target_error: 0.5."""
    scene = animated(d, 1)
    scene.write_text(scene.read_text().replace("steps: 16}", "steps: 16, target_error: 0.5}"))
    return scene


def nothing_in_the_working_folder(d: Path, result: Result) -> list[str]:
    """The case's folder is the process's working directory: no cache appears there."""
    return [".cache written in the working directory"] if (d / ".cache").exists() else []


def written(*names: str) -> Callable[[Path, Result], list[str]]:
    """The case's folder holds each of `names` (globs)."""
    def check(d: Path, result: Result) -> list[str]:
        return [f"no {name}" for name in names if not list(d.glob(name))]
    return check


# --------------------------------------------------------------------------- the cases


def cases() -> list[Case]:
    HEAD, write, relief = scene_inputs.HEAD, scene_inputs.write, scene_inputs.relief
    gobo_light = scene_inputs.gobo_light
    return [
        # Limits not checked before allocation
        Case("13000² PNG of zeros (657 KB) as a depth map",
             render(lambda d: (png_of_zeros(d / "big.png", 13000, 13000) and relief(d, "big.png"), []))),
        Case("30000² PNG of zeros as a depth map",
             render(lambda d: (png_of_zeros(d / "huge.png", 30000, 30000, 1) and relief(d, "huge.png"), []))),
        Case("30000² PNG of zeros as a gobo",
             render(lambda d: (png_of_zeros(d / "huge.png", 30000, 30000, 1) and write(d, gobo_light("huge.png")),
                               []))),
        Case("16k² EXR (header) as a depth map", from_tests("a 16k² EXR as a depth map")),
        Case("16k² EXR (header) as a gobo", from_tests("a 16k² EXR as a gobo")),
        Case("200-byte .npy claiming 4.9e9 elements as a gobo",
             from_tests("a 200-byte .npy claiming 4.9e9 elements as a gobo")),
        Case(".npy claiming 4.9e9 elements as a depth map",
             from_tests("a .npy claiming 4.9e9 elements as a depth map")),
        Case("16 spot lights sharing one 4096² PNG gobo", render(lambda d: (scene_inputs.sixteen_gobo_lights(d), [])),
             expect="ok", check=lambda d, r: [] if (d / "out.png").exists() else ["no out.png"]),
        Case("point light's cube of six 4096² PNG faces", render(lambda d: (grid_png(d / "gobo.png") and write(
            d, HEAD.replace("intensity: 100}", "intensity: 100, texture: [" + ", ".join(["gobo.png"] * 6) + "]}")),
            []))),
        Case("22 MB OBJ, one face of 11 M triangles",
             from_tests("a 22 MB OBJ whose one face fans out to 11 M triangles")),
        Case("sequence -o x_{:0999999999d}.png", lambda d: ["sequence", demo(PROBE), "-o", d / "x_{:0999999999d}.png"],
             check=nothing_written("x_*")),
        Case("sequence -o x_{:c}.png", lambda d: ["sequence", demo(PROBE), "-o", d / "x_{:c}.png"],
             check=nothing_written("x_*")),
        Case("directional texture_size 1e-6, --method exact",
             from_tests("a directional texture_size of 1e-6 with exact")),
        # Values finite in float64 that overflow in float32
        Case("mesh vertex at 1e39", from_tests("a mesh vertex at 1e39")),
        Case("scale: 1e300", from_tests("scale: 1e300")),
        Case("relief height: 1e300", from_tests("relief height: 1e300")),
        Case("animated translate of 1e39", from_tests("an animated translate of 1e39")),
        Case("relief size: [1e300, 1e300]", from_tests("relief size: [1e300, 1e300]")),
        Case("relief center: [1e30, 0, 0]", from_tests("relief center: [1e30, 0, 0]")),
        Case("relief albedo_map of 1e6", from_tests("relief albedo_map of 1e6")),
        Case("relief albedo_map of -1000", from_tests("relief albedo_map of -1000")),
        Case("2e37 texel at intensity 1e30", from_tests("a 2e37 texel at intensity 1e30")),
        Case("JPEG named .png as a depth map", from_tests("a JPEG named .png as a depth map")),
        Case("GIF named .png as a depth map", from_tests("a GIF named .png as a depth map")),
        Case("NaN TIFF named .png as a depth map", from_tests("a NaN TIFF named .png as a depth map")),
        Case("binary STL whose header count lies", render(lambda d: (scene_inputs.stl(
            d / "lie.stl", 2, claimed=1000) and write(d, HEAD + "objects: [{type: mesh, file: lie.stl}]\n"), [])),
             expect="ok", check=lambda d, r: [] if (d / "out.png").exists() else ["no out.png"]),
        # Sequences, sweeps, outputs
        Case("two sequences into one folder, B after A's first frame", lambda d: [],
             run=two_runs_in_one_folder(simultaneous=False)),
        Case("two sequences into one folder, started together", lambda d: [],
             run=two_runs_in_one_folder(simultaneous=True)),
        Case("frame manifest a FIFO", manifest_fifo),
        Case("frame manifest a link to /dev/zero", manifest_zero),
        Case("results.csv a FIFO", results_fifo),
        Case("results.csv a link to /dev/zero", results_zero),
        Case("sequence of 20 000 frames at 1×1 (stopped at its first)", lambda d: [], expect="interrupted",
             run=twenty_thousand_frames),
        Case("sweep of three axes of 100 values", lambda d: [
            "sweep", animated(d, 1), *[a for key in ("medium.sigma_s", "medium.sigma_a", "lights.0.intensity")
                                       for a in ("--set", f"{key}=" + HUNDRED_VALUES)], "-o", d / "out"],
             check=nothing_written("out")),
        Case("--set sigma_s=0.3,0.4 --set 'medium={sigma_a: ...},{...}'", lambda d: [
            "sweep", animated(d, 1), "--set", "medium.sigma_s=0.3,0.4", "--set",
            "medium={sigma_a: 0.2},{sigma_a: 0.1}", "-o", d / "out"], check=nothing_written("out")),
        Case("--set sigma_s=0.9 --set sigma_s=0.3,0.4", lambda d: [
            "sweep", animated(d, 1), "--set", "medium.sigma_s=0.9", "--set", "medium.sigma_s=0.3,0.4", "-o", d / "out"],
             check=nothing_written("out")),
        Case("corrupted .references/*.npy (recovers)", damaged_reference, expect="recover",
             check=says("unreadable cached reference")),
        Case("relief-to-mesh onto a full disk (4 KiB file limit)", lambda d: [
            "relief-to-mesh", PROBE.tree / "scenes" / "lattice.yaml", "-o", d / "lattice.ply"],
             limit_file_bytes=4096, check=nothing_written("*.ply", ".*")),
        Case("render .exr onto a full disk (a 64 KiB tmpfs)", lambda d: [], run=exr_onto_a_full_disk),
        # PoCL writes each program's preprocessed source into its cache before it looks the
        # binary up, so a full disk under ~/.cache fails the kernel build as well.
        Case("render .exr under a 16 KiB file-size limit (kernel cache warm)", exr_under_a_file_limit,
             limit_file_bytes=16384, check=nothing_written("a.exr", ".*")),
        Case("Ctrl-C at a sequence's first frame", lambda d: [], expect="interrupted", run=interrupted_sequence(0.0)),
        Case("Ctrl-C 0.13 s after a sequence's first frame", lambda d: [], expect="interrupted",
             run=interrupted_sequence(0.13)),
        # Dask, devices, video
        scheduler_case("--scheduler tcp://127.0.0.1:CLOSED", lambda: (closed_port(), None)),
        scheduler_case("--scheduler, an endpoint that accepts and stays silent", listening(None)),
        scheduler_case("--scheduler, an endpoint that sends 8 bytes of 0xff", listening(b"\xff" * 8)),
        scheduler_case("--scheduler garbage", lambda: ("garbage", None)),
        scheduler_case("--scheduler tcp://", lambda: ("tcp://", None)),
        Case("--workers 32", lambda d: ["sweep", demo(PROBE), "--set", "render.slices=32,64", "--workers", "32", "-o",
                                        d / "sweep"]),
        Case("--workers 256", lambda d: ["sweep", demo(PROBE), "--set", "render.slices=32,64", "--workers", "256",
                                         "-o", d / "sweep"]),
        Case("--device ²:0", lambda d: ["render", demo(PROBE), "-o", d / "x.png", "--device", "²:0"]),
        Case("CLRAYS_DEVICE=0:²", lambda d: ["render", demo(PROBE), "-o", d / "x.png"], env={"CLRAYS_DEVICE": "0:²"}),
        Case("--set lights.²=1", lambda d: ["render", demo(PROBE), "-o", d / "x.png", "--set", "lights.²=1"]),
        Case("--reference raymarch:²", lambda d: ["sweep", animated(d, 1), "--set", "medium.sigma_s=0.02,0.05",
                                                  "--reference", "raymarch:²", "-o", d / "out"]),
        video("f=null"),
        video("y={elsewhere}"),
        video("an={elsewhere}"),
        video("vstats_file={elsewhere}"),
        # Files a scene may read
        confined("objects.0.file", "dot-dot"),
        confined("objects.0.file", "root"),
        confined("objects.0.depth_map", "absolute"),
        confined("objects.0.albedo_map", "symlink"),
        confined("lights.0.texture", "absolute"),
        confined("lights.0.texture", "dot-dot", via_environment=True),
        # What a newcomer met, on the command line
        Case("sequence of one frame: '1 frame rendered'", lambda d: [
            "sequence", animated(d, 1), "-o", d / "f_{}.png", "--no-progress"], expect="ok",
             check=says("1 frame rendered", never=("1 frames",))),
        Case("sweep of one point: '1 point rendered'", lambda d: [
            "sweep", animated(d, 1), "--set", "medium.sigma_s=0.05", "-o", d / "out", "--no-progress"], expect="ok",
             check=says("1 point rendered", never=("1 points",))),
        Case("--frame 3 on a still scene", lambda d: ["render", animated(d, 1), "-o", d / "a.png", "--frame", "3"],
             check=says(never=("0 <= A <= B <= 0",))),
        Case("render -o into a missing folder", lambda d: ["render", animated(d, 1), "-o", d / "new" / "a.png"],
             expect="ok", check=lambda d, r: [] if (d / "new" / "a.png").exists() else ["no new/a.png"]),
        # Round three: small glTF files that cost minutes or gigabytes
        Case("glTF: 24 accessors without a view, 128 MiB each", gltf_file(accessors_without_views),
             check=nothing_written("out.png")),
        Case("glTF: one 128 MiB accessor named by 48 primitives", gltf_file(one_accessor_many_primitives),
             expect="ok", check=written("out.png")),
        Case("glTF: 65 536 nodes, 40 channels of 400 keys", gltf_file(many_nodes_and_keys), expect="ok",
             check=written("out.png")),
        Case("glTF: one 4096² PNG named by 200 images", gltf_file(one_png_many_images), expect="ok",
             check=written("out.png")),
        Case("glTF: 200 views of a 4096² PNG (12.8 GB decoded)", gltf_file(many_decoded_images),
             check=nothing_written("out.png")),
        Case("GLB: 19 M empty chunks after BIN (152 MB)", gltf_file(empty_chunks), check=nothing_written("out.png")),
        # Round three: numbers and outputs
        Case("YAML 1.2 floats: intensity [2.6e2, 2.3e2, 1.9e2], --set 6.02e-2", lambda d: [
            "render", animated(d, 1), "-o", d / "a.png", "--set", "lights.0.intensity=[2.6e2, 2.3e2, 1.9e2]",
            "--set", "medium.sigma_s=6.02e-2"], expect="ok", check=written("a.png")),
        # Round three: writes that follow links, and caches
        Case("out/.clrays-frames.jsonl -> ../victim.txt (sequence)", linked_manifest, check=victim_untouched),
        Case("out/.references -> ../elsewhere (sweep --reference)", linked_references, check=victim_untouched),
        Case("render.target_error in the scene, no consent (32×18)", lambda d: [
            "render", target_error_scene(d), "-o", d / "t.png"], env={"CLRAYS_CACHE": ""},
             check=lambda d, r: nothing_in_the_working_folder(d, r) + nothing_written("t.png")(d, r)),
        Case("tune -o out/t.png (a YAML file named .png)", lambda d: [
            "tune", animated(d, 1), "--target-error", "5", "-o", d / "out" / "t.png"],
             check=nothing_written("out")),
    ]


# --------------------------------------------------------------------------- running and reporting


def _last_line(output: str) -> str:
    lines = output.strip().splitlines()
    return lines[-1] if lines else ""


def judge(case: Case, result: Result, d: Path) -> None:
    lines = [line for line in result.output.strip().splitlines() if not LABELLED.match(line)]
    if "internal error" in result.output:
        result.problems.append("internal error")
    if "Traceback" in result.output:
        result.problems.append("Traceback")
    if ONE_IN_THE_PLURAL.search(result.output):
        result.problems.append(f"says {ONE_IN_THE_PLURAL.search(result.output).group()!r}")
    if case.expect == "error":
        if result.code == 0:
            result.problems.append("exit 0 where an error is expected")
        if len(lines) != 1:
            result.problems.append(f"{len(lines)} lines")
        elif not lines[0].startswith("clrays: error: "):
            result.problems.append("not a 'clrays: error:' line")
    elif case.expect in ("ok", "recover") and result.code != 0:
        result.problems.append(f"exit {result.code} where a valid run is expected")
    elif case.expect == "interrupted" and result.code != 130:
        result.problems.append(f"exit {result.code} where 130 (interrupted) is expected")
    if result.seconds > SECONDS:
        result.problems.append(f"{result.seconds:.1f} s > {SECONDS:g} s")
    if not result.peak_mb <= PEAK_MB:
        result.problems.append(f"peak {result.peak_mb:.0f} MB > {PEAK_MB:g} MB")
    if case.check:
        result.problems += case.check(d, result)


def run_case(probe: Probe, case: Case, index: int) -> tuple[Result, int]:
    d = probe.out / f"{index:02d}-{re.sub(r'[^A-Za-z0-9]+', '-', case.name).strip('-')[:48]}"
    d.mkdir(parents=True)
    try:
        if case.run:
            result = case.run(probe, d)
        else:
            result = probe.run(case.build(d), d, env=case.env, limit_file_bytes=case.limit_file_bytes)
    except Exception as error:  # the probe's own failure: reported as the case's
        result = Result(-1, f"probe: {type(error).__name__}: {error}", 0.0, float("nan"), ["the probe failed"])
    judge(case, result, d)
    shown = [line for line in result.output.strip().splitlines() if not LABELLED.match(line)]
    result.output = result.output.replace(str(d), "D")
    return result, len(shown)


def cell(text: str, width: int = 170) -> str:
    text = text if len(text) <= width else text[:width - 1] + "…"
    return text.replace("|", "\\|").replace("\n", " ")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repo", type=Path, default=HERE, help="the tree whose clrays runs the cases (default: this "
                                                                "script's)")
    parser.add_argument("--only", default="", metavar="SUBSTRING", help="run the cases whose name contains it")
    parser.add_argument("--out", type=Path, help="build the inputs here and keep them (default: a temporary folder)")
    parser.add_argument("--summary", action="store_true", help="list only the flagged cases and the slowest and "
                                                               "largest three (bench/RESULTS.md's table)")
    args = parser.parse_args()
    global PROBE
    out = args.out or Path(tempfile.mkdtemp(prefix="clrays-hostile-"))
    if args.out and out.exists():
        shutil.rmtree(out)
    PROBE = Probe(args.repo.resolve(), out)
    imported = subprocess.run([sys.executable, "-c", "import clrays; print(clrays.__file__)"], env=PROBE.env,
                              capture_output=True, text=True, cwd=out).stdout.strip()
    chosen = [case for case in cases() if args.only.lower() in case.name.lower()]
    print(f"clrays from {imported}; {len(chosen)} cases; peak RSS by {TIME or 'RUSAGE_CHILDREN'}\n", file=sys.stderr)
    print("| case | exit | lines | last line | s | peak MB | flags |")
    print("|---|---:|---:|---|---:|---:|---|")
    results, rows = [], []
    started = time.perf_counter()
    try:
        for index, case in enumerate(chosen):
            result, lines = run_case(PROBE, case, index)
            results.append((case, result))
            flags = ("; ".join(result.problems) or "ok") + (f" ({result.note})" if result.note else "")
            rows.append(f"| {cell(case.name, 80)} | {result.code} | {lines} | "
                        f"{cell(_last_line(result.output), 100 if args.summary else 170)} | "
                        f"{result.seconds:.1f} | {result.peak_mb:.0f} | {cell(flags, 200)} |")
            if not args.summary:
                print(rows[-1], flush=True)
    finally:
        if not args.out:
            shutil.rmtree(out, ignore_errors=True)
    if args.summary:  # the flagged cases, then the three slowest and the three largest, in run order
        by = lambda key: sorted(range(len(results)), key=lambda i: -key(results[i][1]))[:3]  # noqa: E731
        shown = {i for i, (_, r) in enumerate(results) if r.problems} | set(by(lambda r: r.seconds)) | \
            set(by(lambda r: r.peak_mb))
        print("\n".join(rows[i] for i in sorted(shown)), flush=True)
    failed = [(case, result) for case, result in results if result.problems]
    errors = [result for case, result in results if case.expect == "error"]
    print(f"\n{len(results)} cases in {time.perf_counter() - started:.0f} s: {len(failed)} flagged; "
          f"{sum(r.code != 0 for r in errors)} of {len(errors)} expected errors non-zero; "
          f"max {max((r.seconds for _, r in results), default=0):.1f} s, "
          f"max peak {max((r.peak_mb for _, r in results), default=0):.0f} MB")
    for case, result in failed:
        print(f"\n### {case.name}: {'; '.join(result.problems)}\n\n```\n" +
              "\n".join(result.output.strip().splitlines()[-40:]) + "\n```")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
