"""The visibility stage's share of the frame at one image size, with the stage split into
its bound-map kernels and the rest (prepare, mark, classify and shadow rays; `clrays
render --stats` shows them together as `visibility`): median of a few frames rendered
from scratch after a warm-up one (bench/RESULTS.md, "The visibility stage at 1280×720").

    .venv/bin/python bench/visibility_share.py                      # the bench four, 1280×720
    .venv/bin/python bench/visibility_share.py demo --frames 5 --save /tmp/after   # and the images

Frame time is stage time, as `--stats` totals it (device time of every stage plus the
host-timed ones); the shares are visibility / frame (what `--stats` shows as the stage)
and (visibility + bvh) / frame (with the BVH's host build, once per geometry and eye
position in a session).
"""
from __future__ import annotations

import os
import statistics
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from clrays import session as session_module  # noqa: E402
from stage_times import frame_arguments, timed_frames  # noqa: E402  (bench/, beside this script)


class _Relabel:
    """A StageTimer seen through one stage: its `visibility` events filed as `label`."""

    def __init__(self, timer, label):
        self._timer, self._label = timer, label

    def add(self, label, event):
        self._timer.add(self._label if label == "visibility" else label, event)

    def __getattr__(self, name):
        return getattr(self._timer, name)


def _split_bound_map_time() -> None:
    """File the bound map's kernels under `visibility.bound` instead of `visibility`."""
    bound = session_module.visibility_bound
    session_module.visibility_bound = lambda device, buffers, index, timer, *rest: bound(
        device, buffers, index, _Relabel(timer, "visibility.bound"), *rest)


def main() -> None:
    parser = frame_arguments(__doc__.splitlines()[0], "1280x720", 3)
    parser.add_argument("--save", metavar="DIR", help="also write each scene's last image to DIR/<scene>.npy")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    _split_bound_map_time()
    print(f"{width}×{height}, median of {args.frames} frames, ms; load average {os.getloadavg()[0]:.1f} at start\n")
    print("| scene | bound map | rest (prepare, classify + rays) | bvh | frame | visibility / frame "
          "| (visibility + bvh) / frame |")
    print("|---|---|---|---|---|---|---|")
    for name in args.scenes:
        _, runs = timed_frames(name, width, height, args.frames, overrides=args.overrides)

        def median(stage):
            return statistics.median(run.stage_ms.get(stage, 0.0) for run in runs)

        if args.save:
            Path(args.save).mkdir(parents=True, exist_ok=True)
            np.save(Path(args.save) / f"{name}.npy", runs[-1].image)
        frame = statistics.median(sum(run.stage_ms.values()) for run in runs)

        def share(*stages):
            return 100 * statistics.median(sum(run.stage_ms.get(stage, 0.0) for stage in stages)
                                           / sum(run.stage_ms.values()) for run in runs)

        print(f"| {name} | {median('visibility.bound'):.1f} | {median('visibility'):.1f} | {median('bvh'):.1f} "
              f"| {frame:.1f} | {share('visibility.bound', 'visibility'):.1f} % "
              f"| {share('visibility.bound', 'visibility', 'bvh'):.1f} % |", flush=True)
    print(f"\nload average {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
