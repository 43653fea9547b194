"""Where a frame's wall time goes besides its kernels: the device's idle time between the
commands of a frame (the host's work and its waits), the time of the large fills, and
the largest gaps, median over frames after a warm-up one (bench/RESULTS.md, "Fewer waits,
parallel fills").

    .venv/bin/python bench/device_idle.py --size 1280x720 --frames 5 demo bunny

Every kernel launch (`Device.kernel`) and fill (`Device.fill`) is timed by its OpenCL
profiling event; a gap is the time from one command's end to the next one's start,
read and write transfers being part of the gaps.
"""
from __future__ import annotations

import collections
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import clrays.device as device_module  # noqa: E402
from kernel_times import record_launches  # noqa: E402  (bench/, beside this script)
from stage_times import check_scenes, frame_arguments, timed_frames  # noqa: E402

LARGE_FILL_BYTES = 1 << 20

def main() -> None:
    args = frame_arguments(__doc__.splitlines()[0], "1280x720", 5).parse_args()
    check_scenes("device_idle.py", args.scenes)
    width, height = (int(v) for v in args.size.split("x"))
    commands: list[tuple[str, object]] = []  # (name, event) in enqueue order
    fills: list[tuple[int, object]] = []  # (bytes, the event Device.fill returned)
    record_launches(commands)
    fill = device_module.Device.fill

    def timed_fill(self, buffer, value, nbytes, timer=None, label="fill"):
        event = fill(self, buffer, value, nbytes, timer, label)
        commands.append(("fill", event))
        fills.append((nbytes, event))
        return event

    device_module.Device.fill = timed_fill
    print(f"{width}×{height}, ms per frame, median of {args.frames} frames\n")
    print("| scene | wall | first command to last | busy | idle between commands | large fills | largest gaps |")
    print("|---|---|---|---|---|---|---|")
    for name in args.scenes:
        measures = collections.defaultdict(list)
        gaps = collections.defaultdict(list)
        started = [0.0]

        def before_each():
            commands.clear()
            fills.clear()
            started[0] = time.perf_counter()

        def after_each(timed, _result):
            wall = 1000 * (time.perf_counter() - started[0])
            seen, spans = set(), []
            for label, event in commands:
                if event.int_ptr not in seen:  # (a fill kernel is both a launch and a fill's event)
                    seen.add(event.int_ptr)
                    event.wait()
                    spans.append((event.profile.start, event.profile.end, label))
            spans.sort()
            frame_gaps = collections.defaultdict(float)
            for (_, end, before), (start, _, after) in zip(spans, spans[1:]):
                frame_gaps[f"{before} → {after}"] += max(start - end, 0) * 1e-6
            large = sum((e.profile.end - e.profile.start) * 1e-6 for size, e in fills if size >= LARGE_FILL_BYTES)
            if timed:
                measures["wall"].append(wall)
                measures["span"].append((spans[-1][1] - spans[0][0]) * 1e-6)
                measures["busy"].append(sum(end - start for start, end, _ in spans) * 1e-6)
                measures["idle"].append(sum(frame_gaps.values()))
                measures["fills"].append(large)
                for key in set(gaps) | set(frame_gaps):
                    gaps[key].append(frame_gaps.get(key, 0.0))
            before_each()

        before_each()
        timed_frames(name, width, height, args.frames, after_each=after_each, overrides=args.overrides)
        top = sorted(((statistics.median(v), k) for k, v in gaps.items()), reverse=True)[:3]
        cells = " | ".join(f"{statistics.median(measures[key]):.1f}" for key in ("wall", "span", "busy", "idle", "fills"))
        print(f"| {name} | {cells} | " + "; ".join(f"{k} {v:.2f}" for v, k in top) + " |", flush=True)

if __name__ == "__main__":
    main()
