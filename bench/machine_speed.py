"""How fast this machine is now: its memory bandwidth and one core's speed, to take beside a stage table.

A copy of 200 MB (memory bandwidth, which a frame's kernels lean on) and a pure-Python
loop (one core's speed), each alone and on both cores at once; medians over a few repeats.

    .venv/bin/python bench/machine_speed.py

The same tree's 1280×720 frame has read up to 1.4× apart within an hour on the 2-core
bench machine (bench/RESULTS.md, "Column blocks on a GPU, line samples in one load"):
these figures, taken beside a table, say what the machine offered then.
"""
from __future__ import annotations

import argparse
import statistics
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

COPY_FLOATS = 50_000_000  # 200 MB each way
LOOP_COUNT = 5_000_000


def copy_gbps(repeats: int) -> float:
    """Bytes read and written per second by np.copyto over COPY_FLOATS floats, in GB/s."""
    source = np.ones(COPY_FLOATS, np.float32)
    target = np.empty_like(source)
    np.copyto(target, source)  # the pages faulted in before timing
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        np.copyto(target, source)
        times.append(time.perf_counter() - start)
    return 2 * source.nbytes / statistics.median(times) / 1e9


def loop_ms(repeats: int) -> float:
    """A pure-Python loop of LOOP_COUNT additions, in ms."""
    times = []
    for _ in range(repeats):
        start, total = time.perf_counter(), 0
        for value in range(LOOP_COUNT):
            total += value
        times.append(time.perf_counter() - start)
    return 1000 * statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="timed repeats per probe (default 5)")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error(f"--repeats: expected a positive count, got {args.repeats}")
    alone_copy, alone_loop = copy_gbps(args.repeats), loop_ms(args.repeats)
    with ProcessPoolExecutor(2) as pool:
        both_copy = list(pool.map(copy_gbps, [args.repeats] * 2))
        both_loop = list(pool.map(loop_ms, [args.repeats] * 2))
    print(f"copy: {alone_copy:.1f} GB/s alone, {both_copy[0]:.1f} + {both_copy[1]:.1f} GB/s on two cores")
    print(f"loop: {alone_loop:.0f} ms alone, {both_loop[0]:.0f} and {both_loop[1]:.0f} ms on two cores")


if __name__ == "__main__":
    main()
