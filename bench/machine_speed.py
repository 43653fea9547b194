"""How fast this machine is now: its memory bandwidth and one core's speed, to take beside a stage table.

A copy of 200 MB (memory bandwidth), random reads over 32 MB (numpy's `take`: the rate of
independent scattered reads, as a frame's shadow-map and line reads are; a cube face is
4 MB) and a pure-Python loop (one core's speed), each alone and on both cores at once;
medians over a few repeats.

    .venv/bin/python bench/machine_speed.py

The same tree's 1280×720 frame has read up to 1.4× apart within an hour on the 2-core
bench machine (bench/RESULTS.md, "Column blocks on a GPU, fewer and earlier loads on a
CPU"): these figures, taken beside a table, say what the machine offered then.
"""
from __future__ import annotations

import argparse
import statistics
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

COPY_FLOATS = 50_000_000  # 200 MB each way
RANDOM_FLOATS = 8 << 20  # 32 MB
RANDOM_READS = 4_000_000
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


def random_read_ns(repeats: int) -> float:
    """Nanoseconds per read of RANDOM_READS floats at random places in RANDOM_FLOATS (with
    the index array streamed in and the result written out)."""
    values = np.ones(RANDOM_FLOATS, np.float32)
    places = np.random.default_rng(1).integers(0, RANDOM_FLOATS, RANDOM_READS)
    values.take(places)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        values.take(places)
        times.append(time.perf_counter() - start)
    return statistics.median(times) / RANDOM_READS * 1e9


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
    probes = (("copy", copy_gbps, "{:.1f} GB/s"), ("random reads", random_read_ns, "{:.1f} ns"),
              ("loop", loop_ms, "{:.0f} ms"))
    with ProcessPoolExecutor(2) as pool:
        for name, probe, form in probes:
            alone = probe(args.repeats)
            both = list(pool.map(probe, [args.repeats] * 2))
            print(f"{name}: {form.format(alone)} alone, {form.format(both[0])} and {form.format(both[1])} "
                  f"on two cores at once")


if __name__ == "__main__":
    main()
