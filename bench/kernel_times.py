"""Device time of every kernel of a frame, median over frames after a warm-up one, for the
bench scenes at one image size (bench/RESULTS.md, the per-kernel figures of "Where a frame
stands: prepare in lanes, rows owned, the table on the device").

    .venv/bin/python bench/kernel_times.py --size 1280x720 --frames 5 demo bunny

Each launch of a kernel is timed by its OpenCL profiling event (a wrapper of
`Device.kernel`); a kernel launched several times a frame (per light, per cube face) is
summed over the frame. Kernels under 0.3 ms are left out of the listing.
"""
from __future__ import annotations

import collections
import statistics
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import clrays.device as device_module  # noqa: E402
from stage_times import check_scenes, frame_arguments, timed_frames  # noqa: E402  (bench/, beside this script)


def record_launches(launches: list) -> None:
    """From now on every kernel launch through `Device.kernel` appends (kernel name, its
    event) to `launches`."""
    kernel = device_module.Device.kernel

    def recorded_kernel(self, stage, name, defines=None):
        built = kernel(self, stage, name, defines)

        def launch(*arguments, **keywords):
            event = built(*arguments, **keywords)
            launches.append((name, event))
            return event

        return launch

    device_module.Device.kernel = recorded_kernel


def main() -> None:
    args = frame_arguments(__doc__.splitlines()[0], "1280x720", 5).parse_args()
    check_scenes("kernel_times.py", args.scenes)
    width, height = (int(v) for v in args.size.split("x"))
    launches: list[tuple[str, object]] = []
    record_launches(launches)
    print(f"{width}×{height}, device ms per kernel, median of {args.frames} frames\n")
    for name in args.scenes:
        per_kernel = collections.defaultdict(list)

        def record(timed, _result):
            sums = collections.defaultdict(float)
            for kernel_name, event in launches:
                event.wait()
                sums[kernel_name] += (event.profile.end - event.profile.start) * 1e-6
            launches.clear()
            for kernel_name, total in sums.items():
                if timed:
                    per_kernel[kernel_name].append(total)

        _, runs = timed_frames(name, width, height, args.frames, after_each=record, overrides=args.overrides)
        totals = [sum(run.stage_ms.values()) for run in runs]
        medians = sorted(((statistics.median(v), k) for k, v in per_kernel.items()), reverse=True)
        print(f"{name}: stage total {statistics.median(totals):.1f} ms; "
              + ", ".join(f"{k} {m:.2f}" for m, k in medians if m >= 0.3), flush=True)


if __name__ == "__main__":
    main()
