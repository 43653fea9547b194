"""Per-stage time of frames rendered from scratch (no reuse), median over a few frames
after a warm-up one, for the bench scenes at one image size; prints a markdown table
(bench/RESULTS.md, "Costs that follow the image").

    .venv/bin/python bench/stage_times.py --size 16x9
    .venv/bin/python bench/stage_times.py --size 1280x720 --frames 3 demo behind
    .venv/bin/python bench/stage_times.py --size 16x9 --error     # and the error against exact
    .venv/bin/python bench/stage_times.py --size 320x180 --set render.sampling=pixel demo

With `--error`, the last frame is compared with `exact` at the same size
(`metrics.image_error`, depth edges excluded: relative luminance mean / p99 / RMSE, in %).

Frame time here is stage time: the device time of every stage plus the host-timed
integrand stage, as `clrays render --stats` totals it; start-up and kernel builds are
left out (the warm-up frame builds the kernels). The wall column is the median frame's
wall time, which adds the host's work and the device's waits for it; the CPU column is
the process's CPU time per frame, every thread's.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from arguments import frame_count, image_size  # noqa: E402  (bench/, beside this script)
from clrays.errors import ClraysError  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.session import Renderer  # noqa: E402

SCENES = ("demo", "bunny", "behind", "sun")
STAGES = ("raster", "rectify", "minmax", "integrand", "traverse", "visibility", "bvh", "shade")


def frame_arguments(description: str, size: str, frames: int) -> argparse.ArgumentParser:
    """The arguments every per-frame timing script takes: scenes, image size, frame count."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("scenes", nargs="*", default=SCENES, help="scene names in scenes/ (default: the bench four)")
    parser.add_argument("--size", type=image_size, default=size, help=f"WxH (default {size})")
    parser.add_argument("--frames", type=frame_count, default=frames, help=f"timed frames per scene after the warm-up "
                                                                   f"(default {frames})")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="a scene override, as `clrays render --set` (repeatable)")
    return parser


def check_scenes(script: str, scenes: list[str]) -> None:
    """Exit in one line naming the first of `scenes` that scenes/ does not hold."""
    unknown = sorted(set(scenes) - {path.stem for path in (REPO / "scenes").glob("*.yaml")})
    if unknown:
        sys.exit(f"{script}: scenes: no scenes/{unknown[0]}.yaml")


def timed_frames(name: str, width: int, height: int, frames: int, after_each=None, walls: list | None = None,
                 cpus: list | None = None, overrides: tuple = ()) -> tuple[object, list]:
    """(scene, results): scenes/<name>.yaml at width×height rendered from scratch (no reuse)
    once to build the kernels, then `frames` times. `after_each(timed, result)` runs after
    every frame, the warm-up one (timed False) included; `walls` gets each timed frame's
    wall time (ms: the render call, host work and waits included), `cpus` its CPU time (ms,
    every thread of the process: what other tenants of a shared machine change least).
    `overrides`: more `--set` overrides, after the size. Only the last result keeps its
    image, as a sequence of frames does."""
    try:
        scene = load_scene(REPO / "scenes" / f"{name}.yaml",
                           overrides=[f"image.width={width}", f"image.height={height}", *overrides])
    except ClraysError as exc:  # a bad --set: one line, no traceback
        sys.exit(f"{Path(sys.argv[0]).name}: {exc}")
    renderer = Renderer(reuse=False)
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
            if results:  # only the last frame keeps its image: a kept image holds its device
                results[-1] = replace(results[-1], image=None)  # buffer (mapped on a CPU device),
            results.append(result)  # and the next frames' buffers would come from fresh pages
    return scene, results


def main() -> None:
    parser = frame_arguments(__doc__.splitlines()[0], "16x9", 7)
    parser.add_argument("--error", action="store_true", help="also the error against exact at this size")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    settings = f"; {', '.join(args.overrides)}" if args.overrides else ""
    print(f"{width}×{height}{settings}, median of {args.frames} frames, ms; load average {os.getloadavg()[0]:.1f} "
          f"at start\n")
    error_header = " | error vs exact: mean / p99 / RMSE %" if args.error else ""
    print("| scene | " + " | ".join(STAGES) + " | total (min–max) | wall | CPU | sizes" + error_header + " |")
    print("|---|" + "---|" * (len(STAGES) + 4 + args.error))
    for name in args.scenes:
        walls, cpus = [], []
        scene, runs = timed_frames(name, width, height, args.frames, walls=walls, cpus=cpus, overrides=args.overrides)
        totals = [sum(run.stage_ms.values()) for run in runs]
        cells = [f"{statistics.median(run.stage_ms.get(stage, 0.0) for run in runs):.1f}" for stage in STAGES]
        render = getattr(runs[0], "render", None)  # None: a checkout from before the sizes followed the image
        sizes = (f"map {render.shadow_map}², texture {' '.join(f'{s}×{t}' for s, t in runs[0].textures) or '—'}"
                 if render else "map 1024², texture 1024×1024")
        error = ""
        if args.error:
            from clrays.reference import metrics
            from clrays.reference.exact import render_exact

            reference, edges = render_exact(scene), metrics.depth_edges(metrics.depth_map(scene))
            bright = metrics.luminance(reference) >= 0.01 * metrics.luminance(reference).mean()  # image_error's floor
            kept = "" if (bright & ~edges).any() else " (every lit pixel is on a depth edge: none excluded)"
            e = metrics.image_error(runs[-1].image, reference, edges if not kept else None)
            error = f" | {100 * e.mean:.2f} / {100 * e.p99:.2f} / {100 * e.rmse:.2f}{kept}"
        print(f"| {name} | " + " | ".join(cells) + f" | {statistics.median(totals):.1f} ({min(totals):.1f}–{max(totals):.1f})"
              f" | wall {statistics.median(walls):.1f} | CPU {statistics.median(cpus):.1f} | {sizes}{error} |", flush=True)


if __name__ == "__main__":
    main()
