"""Work-group shapes on a CPU device: clrays's (clrays.device.spread_local_size) against
the driver's, the two alternating frame by frame in one process, so that the machine's
drift falls on both alike (bench/RESULTS.md, "Where a frame stands: both cores busy, lines
as long as they are"). Prints each scene's stage time and wall time per frame, and the
kernels whose time moved most, as medians over the frames of each shape.

    .venv/bin/python bench/work_groups.py --size 1280x720 --frames 8
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
from clrays.scene.load import load_scene  # noqa: E402
from clrays.session import Renderer  # noqa: E402
from stage_times import check_scenes, frame_arguments  # noqa: E402  (bench/, beside this script)

SHAPES = ("driver's", "clrays's")


def main() -> None:
    args = frame_arguments(__doc__.splitlines()[0], "1280x720", 8).parse_args()
    check_scenes("work_groups.py", args.scenes)
    width, height = (int(v) for v in args.size.split("x"))
    launches: list[tuple[str, object]] = []
    call = device_module._Launcher.__call__

    def timed_call(self, *arguments, **keywords):
        event = call(self, *arguments, **keywords)
        launches.append((self._kernel.function_name, event))
        return event

    device_module._Launcher.__call__ = timed_call
    print(f"{width}×{height}, medians over {args.frames} frames of each shape, alternating\n")
    for name in args.scenes:
        scene = load_scene(REPO / "scenes" / f"{name}.yaml", overrides=[f"image.width={width}", f"image.height={height}"])
        renderer = Renderer(reuse=False)
        device = renderer.device
        if not device._spread:
            sys.exit(f"work_groups.py: {device.name} is no CPU device: its launches keep the driver's shapes")
        kernels = [collections.defaultdict(list), collections.defaultdict(list)]
        walls: list[list[float]] = [[], []]
        for frame in range(2 * (args.frames + 1)):
            shape = frame % 2
            device._spread = bool(shape)
            launches.clear()
            start = time.perf_counter()
            renderer.render(scene)
            wall = (time.perf_counter() - start) * 1e3
            if frame < 2:  # each shape's warm-up: its kernels are built for its work-groups
                continue
            sums: dict[str, float] = collections.defaultdict(float)
            for kernel, event in launches:
                event.wait()
                sums[kernel] += (event.profile.end - event.profile.start) * 1e-6
            for kernel, total in sums.items():
                kernels[shape][kernel].append(total)
            kernels[shape]["(stage time)"].append(sum(sums.values()))
            walls[shape].append(wall)
        device._spread = True
        median = [{k: statistics.median(v) for k, v in per.items()} for per in kernels]
        stage = [m["(stage time)"] for m in median]
        wall = [statistics.median(w) for w in walls]
        moved = sorted((k for k in median[0] if k != "(stage time)" and median[0][k] >= 1.0),
                       key=lambda k: median[1].get(k, 0.0) - median[0][k])[:5]
        print(f"{name}: kernels {stage[0]:.1f} → {stage[1]:.1f} ms ({stage[1] / stage[0]:.2f}), "
              f"wall {wall[0]:.1f} → {wall[1]:.1f} ms ({wall[1] / wall[0]:.2f}); "
              + ", ".join(f"{k} {median[0][k]:.2f} → {median[1].get(k, 0.0):.2f}" for k in moved), flush=True)


if __name__ == "__main__":
    main()
