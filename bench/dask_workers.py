"""Sequences on dask workers: the wall time of a 24-frame 640×360 orbit on 1 and on 2
local workers, each worker pinned to its own core (bench/RESULTS.md, "Dask workers").

    .venv/bin/python bench/dask_workers.py                  # scenes/orbit.yaml, frames 0:23, 3 repeats
    .venv/bin/python bench/dask_workers.py --repeats 5

Each worker process is pinned to one core (every thread, `pin_to_core`) and PoCL runs one
thread (POCL_MAX_PTHREAD_COUNT=1), so a worker is one core's worth of device. Both
clusters stay up for the whole run and their repeats alternate, so load from other
processes falls on both alike; each repeat renders every frame into a fresh folder after
one untimed warm-up run (kernels built). Prints the median of each and their ratio, and
the CPU time the workers used: on a machine shared with other jobs a pinned worker gets
only part of its core, and CPU time says what the ratio would be without them.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
os.environ["POCL_MAX_PTHREAD_COUNT"] = "1"  # inherited by the worker processes, read when PoCL starts

from clrays.runs.distributed import DaskExecutor, pin_to_core  # noqa: E402
from clrays.runs.sequence import parse_frames, render_sequence, scene_frames  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402


def pin_workers(executor: DaskExecutor) -> dict[str, int]:
    """Pin worker k (in address order) to core k modulo the cores this process may use."""
    cores = sorted(os.sched_getaffinity(0))
    workers = sorted(executor.client.scheduler_info()["workers"])
    pinned = {}
    for index, address in enumerate(workers):
        pinned[address] = cores[index % len(cores)]
        executor.client.run(pin_to_core, pinned[address], workers=[address])
    return pinned


def worker_cpu_seconds(executor: DaskExecutor) -> dict[str, float]:
    """CPU time (every thread, PoCL's included) each worker process has used so far."""
    return executor.client.run(time.process_time)


def timed_run(executor: DaskExecutor, scene, frames: range, folder: Path) -> tuple[float, list[float]]:
    """(wall seconds, CPU seconds of each worker) of one sequence run."""
    before = worker_cpu_seconds(executor)
    start = time.perf_counter()
    report = render_sequence(scene, folder / "frame_{:04d}.png", frames, executor=executor)
    seconds = time.perf_counter() - start
    after = worker_cpu_seconds(executor)
    assert len(report.rendered) == len(frames), report.summary()
    return seconds, sorted(after[worker] - before.get(worker, 0.0) for worker in after)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", nargs="?", default=str(REPO / "scenes" / "orbit.yaml"))
    parser.add_argument("--frames", default="0:23")
    parser.add_argument("--size", default="640x360")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    width, height = args.size.split("x")
    scene = load_scene(args.scene, [f"image.width={width}", f"image.height={height}"])
    frames = parse_frames(args.frames, scene_frames(scene))
    times: dict[int, list[float]] = {1: [], 2: []}
    busiest: dict[int, list[float]] = {1: [], 2: []}  # CPU seconds of the busiest worker
    total_cpu: dict[int, list[float]] = {1: [], 2: []}  # CPU seconds of all workers
    with tempfile.TemporaryDirectory() as scratch, DaskExecutor(workers=1) as one, DaskExecutor(workers=2) as two:
        two.client.wait_for_workers(2, timeout=120)
        executors = {1: one, 2: two}
        for count, executor in executors.items():
            print(f"{count} worker(s) pinned to cores {sorted(pin_workers(executor).values())}", flush=True)
            timed_run(executor, scene, frames, Path(scratch) / f"warm{count}")
        for repeat in range(args.repeats):
            for count in (1, 2) if repeat % 2 == 0 else (2, 1):
                seconds, cpu = timed_run(executors[count], scene, frames, Path(scratch) / f"r{repeat}w{count}")
                times[count].append(seconds)
                busiest[count].append(max(cpu))
                total_cpu[count].append(sum(cpu))
                print(f"repeat {repeat}: {count} worker(s) {seconds:.2f} s wall, worker CPU "
                      f"{' + '.join(f'{c:.2f}' for c in cpu)} s", flush=True)
    one_s, two_s = statistics.median(times[1]), statistics.median(times[2])
    print(f"\n{len(frames)} frames {width}x{height}: 1 worker {one_s:.2f} s ({one_s / len(frames):.3f} s/frame), "
          f"2 workers {two_s:.2f} s; speedup {one_s / two_s:.2f}x (median of {args.repeats})")
    cpu_one, cpu_two = statistics.median(total_cpu[1]), statistics.median(total_cpu[2])
    print(f"worker CPU: 1 worker {cpu_one:.2f} s; 2 workers {cpu_two:.2f} s in all, the busiest "
          f"{statistics.median(busiest[2]):.2f} s; speedup if each worker had its core to itself "
          f"{cpu_one / statistics.median(busiest[2]):.2f}x (1-worker CPU / busiest worker's CPU)")


if __name__ == "__main__":
    main()
