"""What the maintained benchmarks share: the bench scenes and stages, the arguments they take
(checked so that a bad value is one line from argparse), a scene loaded at a size, frames
timed from scratch, each kernel's device time, a fresh process timed with its peak memory,
runs in turns between two sides, medians and markdown tables.

No clrays import at module level: bench/ab.py imports clrays from another tree after
parsing its arguments, and the functions below that need clrays import it when called.
"""
from __future__ import annotations

import argparse
import collections
import os
import platform
import re
import statistics
import subprocess
import sys
import time
from dataclasses import replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable, Iterable, Sequence

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

#: The four scenes every timing table covers: a point light, a spot light, a directional
#: light behind the camera's subject, a sun through a window.
SCENES = ("demo", "bunny", "behind", "sun")
#: A frame's stages in the order it runs them, as `RenderResult.stage_ms` names them.
STAGES = ("raster", "rectify", "minmax", "integrand", "traverse", "visibility", "bvh", "shade")


# ------------------------------------------------------------------------------ arguments

def image_size(text: str) -> str:
    """`--size`: WxH, both positive integers (argparse prints the error in one line)."""
    parts = text.split("x")
    if len(parts) != 2 or not all(part.isdigit() and int(part) > 0 for part in parts):
        raise argparse.ArgumentTypeError(f"expected WxH, e.g. 1280x720, got {text!r}")
    return text


def image_sizes(text: str) -> list[str]:
    """`--sizes`: comma-separated WxH."""
    return [image_size(part) for part in text.split(",") if part] or [image_size(text)]


def frame_count(text: str) -> int:
    """`--frames`, `--rounds`: a positive integer."""
    if not text.isdigit() or int(text) < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return int(text)


def width_height(size: str) -> tuple[int, int]:
    """(width, height) of a checked WxH."""
    width, height = (int(v) for v in size.split("x"))
    return width, height


def scene_names() -> set[str]:
    """The scenes scenes/ holds, by name."""
    return {path.stem for path in (REPO / "scenes").glob("*.yaml")}


def frame_arguments(description: str, size: str, frames: int) -> argparse.ArgumentParser:
    """The arguments every per-frame timing script takes: scenes, image size, frame count, overrides."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("scenes", nargs="*", default=list(SCENES), help="scene names in scenes/ (default: the bench four)")
    parser.add_argument("--size", type=image_size, default=size, help=f"WxH (default {size})")
    parser.add_argument("--frames", type=frame_count, default=frames,
                        help=f"timed frames per scene after the warm-up (default {frames})")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="a scene override, as `clrays render --set` (repeatable)")
    return parser


def check_scenes(script: str, scenes: Iterable[str]) -> None:
    """Exit in one line naming the first of `scenes` that scenes/ does not hold."""
    unknown = sorted(set(scenes) - scene_names())
    if unknown:
        sys.exit(f"{script}: scenes: no scenes/{unknown[0]}.yaml")


# ------------------------------------------------------------------------------ frames

def load(script: str, name: str, width: int, height: int, overrides: Sequence[str] = ()):
    """scenes/<name>.yaml at width×height with `overrides` after the size; a bad override
    exits in one line naming it, as `clrays render --set` does."""
    from clrays.errors import ClraysError
    from clrays.scene.load import load_scene

    try:
        return load_scene(REPO / "scenes" / f"{name}.yaml",
                          overrides=[f"image.width={width}", f"image.height={height}", *overrides])
    except ClraysError as exc:
        sys.exit(f"{script}: {exc}")


def timed_frames(scene, frames: int, after_each: Callable | None = None, walls: list | None = None,
                 cpus: list | None = None, renderer=None) -> list:
    """The results of `frames` renders of `scene` from scratch (no reuse), after one that
    builds the kernels. `after_each(timed, result)` runs after every frame, the warm-up one
    (timed False) included; `walls` gets each timed frame's wall time (ms: the render call,
    host work and waits included), `cpus` its CPU time (ms, every thread of the process:
    what other tenants of a shared machine change least). Only the last result keeps its
    image: a kept image holds its device buffer (mapped on a CPU device), and the next
    frames' buffers would come from fresh pages."""
    from clrays.session import Renderer

    renderer = renderer or Renderer(reuse=False)
    results = []
    for index in range(frames + 1):
        start, start_cpu = time.perf_counter(), time.process_time()
        result = renderer.render(scene)
        if index > 0 and walls is not None:
            walls.append(1000 * (time.perf_counter() - start))
        if index > 0 and cpus is not None:
            cpus.append(1000 * (time.process_time() - start_cpu))
        if after_each is not None:
            after_each(index > 0, result)
        if index > 0:
            if results:
                results[-1] = replace(results[-1], image=None)
            results.append(result)
    return results


class KernelClock:
    """Each kernel's device time per frame, by the OpenCL profiling event of every launch
    through `Device.kernel` (a kernel launched several times a frame, per light or cube
    face, is summed over the frame). `frame_done()` after each frame files its sums."""

    def __init__(self):
        import clrays.device as device_module

        self.launches: list[tuple[str, object]] = []
        self.per_kernel: dict[str, list[float]] = collections.defaultdict(list)
        kernel, launches = device_module.Device.kernel, self.launches

        def recorded_kernel(device, stage, name, defines=None):
            built = kernel(device, stage, name, defines)

            def launch(*arguments, **keywords):
                event = built(*arguments, **keywords)
                launches.append((name, event))
                return event

            return launch

        device_module.Device.kernel = recorded_kernel

    def frame_done(self, keep: bool = True) -> dict[str, float]:
        """The frame's ms per kernel since the last call, filed in `per_kernel` if `keep`."""
        sums: dict[str, float] = collections.defaultdict(float)
        for name, event in self.launches:
            event.wait()
            sums[name] += (event.profile.end - event.profile.start) * 1e-6
        self.launches.clear()
        if keep:
            for name, total in sums.items():
                self.per_kernel[name].append(total)
        return sums

    def medians(self) -> list[tuple[float, str]]:
        """(median ms, kernel) of every kernel, the largest first; then starts afresh."""
        out = sorted(((statistics.median(v), k) for k, v in self.per_kernel.items()), reverse=True)
        self.per_kernel.clear()
        return out


def timed_process(command: Sequence[str], cwd: Path | None = None, env: dict | None = None
                  ) -> tuple[float, float, str]:
    """(wall seconds, peak RSS in MiB, stdout + stderr) of `command` in a fresh process under
    GNU time; a failure exits in one line with the command's last lines."""
    started = time.perf_counter()
    done = subprocess.run(["/usr/bin/time", "-f", "peak-kib %M", *command], capture_output=True, text=True,
                          cwd=cwd, env={**os.environ, **(env or {})})
    seconds = time.perf_counter() - started
    peak = re.findall(r"^peak-kib (\d+)$", done.stderr, re.M)
    if done.returncode != 0 or not peak:
        last = "\n".join(done.stderr.strip().splitlines()[-5:]) or "no output"
        sys.exit(f"{Path(sys.argv[0]).name}: {' '.join(map(str, command))} failed:\n{last}")
    return seconds, int(peak[-1]) / 1024, done.stdout + done.stderr


def tree_python(tree: Path) -> dict:
    """The environment in which `python -m clrays.cli` runs `tree`'s clrays."""
    return {"PYTHONPATH": str(Path(tree).resolve())}


# ------------------------------------------------------------------------------ turns and figures

def in_turns(rounds: int, sides: Sequence, run_once: Callable, label: str = "") -> list[list]:
    """For each side, the results of `run_once(side)` over `rounds` rounds, each round
    running every side once, one after the other, so that a load that comes and goes falls
    on all of them alike."""
    results: list[list] = [[] for _ in sides]
    for number in range(rounds):
        for index, side in enumerate(sides):
            results[index].append(run_once(side))
        print(f"{label}round {number + 1} of {rounds}, load {os.getloadavg()[0]:.1f}", file=sys.stderr, flush=True)
    return results


def median_range(values: Sequence[float], digits: int = 1) -> str:
    """`median (min–max)` of `values`."""
    return f"{statistics.median(values):.{digits}f} ({min(values):.{digits}f}–{max(values):.{digits}f})"


def markdown_table(header: Sequence[str], rows: Iterable[Sequence], right: Sequence[int] = ()) -> str:
    """A markdown table; columns whose index is in `right` are right-aligned."""
    lines = ["| " + " | ".join(map(str, header)) + " |",
             "|" + "".join("---:|" if index in right else "---|" for index in range(len(header)))]
    lines += ["| " + " | ".join(map(str, row)) + " |" for row in rows]
    return "\n".join(lines)


def machine() -> str:
    """This machine in a few words: its CPU model, core count and the load average now."""
    model = platform.processor() or platform.machine()
    try:
        names = re.findall(r"^model name\s*:\s*(.*)$", Path("/proc/cpuinfo").read_text(), re.M)
        model = names[0].strip() if names else model
    except OSError:
        pass
    return f"{os.cpu_count()}-core {model}, load average {os.getloadavg()[0]:.1f}"


def today() -> str:
    """The date and time in UTC, as the tables are stamped."""
    return datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
