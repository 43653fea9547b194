"""Per-stage time of frames rendered from scratch (no reuse), median over a few frames
after a warm-up one, for the bench scenes at one image size; prints a markdown table
(bench/RESULTS.md, "Stage times"). With `--kernels`, each kernel's device time too.

    .venv/bin/python bench/stage_times.py --size 16x9
    .venv/bin/python bench/stage_times.py --size 1280x720 --frames 3 demo behind
    .venv/bin/python bench/stage_times.py --size 16x9 --error     # and the error against exact
    .venv/bin/python bench/stage_times.py --size 320x180 --set render.sampling=pixel demo
    .venv/bin/python bench/stage_times.py --size 1280x720 --frames 5 --kernels demo bunny

With `--error`, the last frame is compared with `exact` at the same size
(`metrics.image_error`, depth edges excluded: relative luminance mean / p99 / RMSE, in %).

Frame time here is stage time: the device time of every stage plus the host-timed
integrand stage, as `clrays render --stats` totals it; start-up and kernel builds are
left out (the warm-up frame builds the kernels). The wall column is the median frame's
wall time, which adds the host's work and the device's waits for it; the CPU column is
the process's CPU time per frame, every thread's.

`--kernels` times each launch by its OpenCL profiling event (a kernel launched several
times a frame, per light or cube face, summed over the frame) and prints, after the
table, one line per scene: `scene: stage total T ms; kernel ms, ...` (kernels under
0.3 ms left out), the form bench/ab.py's `kernels` reads.
"""
from __future__ import annotations

import os
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import (STAGES, KernelClock, check_scenes, frame_arguments, load, markdown_table,  # noqa: E402
                     timed_frames, width_height)


def error_cell(scene, image) -> str:
    """` | mean / p99 / RMSE` % of `image` against `exact` at the same size, depth edges out."""
    from clrays.reference import metrics
    from clrays.reference.exact import render_exact

    reference, edges = render_exact(scene), metrics.depth_edges(metrics.depth_map(scene))
    bright = metrics.luminance(reference) >= 0.01 * metrics.luminance(reference).mean()  # image_error's floor
    kept = "" if (bright & ~edges).any() else " (every lit pixel is on a depth edge: none excluded)"
    e = metrics.image_error(image, reference, edges if not kept else None)
    return f"{100 * e.mean:.2f} / {100 * e.p99:.2f} / {100 * e.rmse:.2f}{kept}"


def main() -> None:
    parser = frame_arguments(__doc__.splitlines()[0], "16x9", 7)
    parser.add_argument("--error", action="store_true", help="also the error against exact at this size")
    parser.add_argument("--kernels", action="store_true", help="also each kernel's device time")
    args = parser.parse_args()
    check_scenes("stage_times.py", args.scenes)
    width, height = width_height(args.size)
    clock = KernelClock() if args.kernels else None
    settings = f"; {', '.join(args.overrides)}" if args.overrides else ""
    print(f"{width}×{height}{settings}, median of {args.frames} frames, ms; load average {os.getloadavg()[0]:.1f} "
          f"at start\n")
    header = ["scene", *STAGES, "total (min–max)", "wall", "CPU", "sizes"] + \
        (["error vs exact: mean / p99 / RMSE %"] if args.error else [])
    print(markdown_table(header, []), flush=True)
    kernel_lines = []
    for name in args.scenes:
        walls, cpus = [], []
        scene = load("stage_times.py", name, width, height, args.overrides)
        runs = timed_frames(scene, args.frames, walls=walls, cpus=cpus,
                            after_each=(lambda timed, _: clock.frame_done(timed)) if clock else None)
        totals = [sum(run.stage_ms.values()) for run in runs]
        cells = [f"{statistics.median(run.stage_ms.get(stage, 0.0) for run in runs):.1f}" for stage in STAGES]
        render = runs[0].render
        sizes = f"map {render.shadow_map}², texture {' '.join(f'{s}×{t}' for s, t in runs[0].textures) or '—'}"
        row = [name, *cells, f"{statistics.median(totals):.1f} ({min(totals):.1f}–{max(totals):.1f})",
               f"wall {statistics.median(walls):.1f}", f"CPU {statistics.median(cpus):.1f}", sizes]
        if args.error:
            row.append(error_cell(scene, runs[-1].image))
        print("| " + " | ".join(row) + " |", flush=True)
        if clock:
            kernel_lines.append(f"{name}: stage total {statistics.median(totals):.1f} ms; "
                                + ", ".join(f"{k} {m:.2f}" for m, k in clock.medians() if m >= 0.3))
    if kernel_lines:
        print(f"\ndevice ms per kernel, median of {args.frames} frames\n\n" + "\n".join(kernel_lines))


if __name__ == "__main__":
    main()
