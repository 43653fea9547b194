"""The bench scenes on every CPU OpenCL runtime installed, in one run: each runtime's image
against PoCL's (minmax and raymarch), and warm minmax frame times taken in turns
(bench/RESULTS.md, "Runtimes"; docs/devices.md's table of runtimes).

    .venv/bin/python bench/runtimes.py --size 1280x720 --rounds 7
    .venv/bin/python bench/runtimes.py --size 320x180 --rounds 3 demo

Intel's CPU runtime comes with `pip install '.[intel-cpu]'`; clrays finds it by itself
(clrays/runtimes.py). Images are rendered from scratch (no reuse). The difference is the
relative RMSE of the linear RGB images, sqrt(mean((a − b)²)) / sqrt(mean(b²)), b PoCL's,
over every pixel and channel. Frame time is the wall time of `Renderer.render`, median
over the rounds; each round renders every runtime's frame once, one after the other, so
the machine's slow spells fall on every runtime alike. Where PoCL cannot build for this
CPU (clrays.runtimes.pocl_builds_here), it is left out and the first other runtime is the
one the images are compared with.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import pyopencl as cl

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import SCENES, check_scenes, frame_count, image_size, load, markdown_table, width_height  # noqa: E402
from clrays import runtimes  # noqa: E402
from clrays.device import Device, list_devices  # noqa: E402
from clrays.session import Renderer  # noqa: E402

METHODS = ("minmax", "raymarch")
POCL = "Portable Computing Language"


def relative_rmse(image: np.ndarray, reference: np.ndarray) -> float:
    reference = reference.astype(np.float64)
    return float(np.sqrt(np.mean((image - reference) ** 2)) / max(np.sqrt(np.mean(reference ** 2)), 1e-30))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=list(SCENES), help="scene names in scenes/ (default: the bench four)")
    parser.add_argument("--size", type=image_size, default="1280x720", help="WxH (default 1280x720)")
    parser.add_argument("--rounds", type=frame_count, default=7, help="timed minmax frames per runtime (default 7)")
    args = parser.parse_args()
    check_scenes("runtimes.py", args.scenes)
    width, height = width_height(args.size)
    pocl_builds = runtimes.pocl_builds_here()
    cpus = [(f"{p}:{d}", platform.name.strip()) for p, d, platform, device in list_devices()
            if device.type & cl.device_type.CPU and (pocl_builds or platform.name.strip() != POCL)]
    cpus.sort(key=lambda entry: entry[1] != POCL)  # PoCL first: the images are compared with its
    if not cpus:
        sys.exit("runtimes.py: no CPU OpenCL runtime that builds here (pocl-binary-distribution, clrays[intel-cpu])")
    reference = cpus[0][1]
    renderers = {name: Renderer(Device(spec), reuse=False) for spec, name in cpus}
    print(f"{width}×{height}; runtimes: {', '.join(f'{name} ({spec})' for spec, name in cpus)}; "
          f"load average {os.getloadavg()[0]:.1f} at start\n")
    names = list(renderers)
    scenes = {name: load("runtimes.py", name, width, height) for name in args.scenes}
    if len(names) > 1:  # the images, each runtime's against the reference's
        print(markdown_table(["scene", "method", *(f"{name}: rel. RMSE vs {reference}" for name in names[1:])], []))
        for scene_name, scene in scenes.items():
            for method in METHODS:
                images = {name: np.asarray(renderer.render(scene, method=method).image, dtype=np.float64)
                          for name, renderer in renderers.items()}
                cells = [f"{relative_rmse(images[name], images[reference]):.2e}" for name in names[1:]]
                print(f"| {scene_name} | {method} | " + " | ".join(cells) + " |", flush=True)
    else:
        print(f"one runtime builds here ({reference}): no images to compare")
    print(f"\nminmax frame wall time, ms: median (min–max) of {args.rounds} rounds, in turns\n")
    print(markdown_table(["scene", *names, *(f"{name} / {reference}" for name in names[1:])], []))
    for scene_name, scene in scenes.items():
        walls = {name: [] for name in names}
        for name, renderer in renderers.items():
            renderer.render(scene, method="minmax")  # warm: kernels built, pool filled
        for _ in range(args.rounds):
            for name, renderer in renderers.items():
                start = time.perf_counter()
                renderer.render(scene, method="minmax")
                walls[name].append(1000 * (time.perf_counter() - start))
        medians = {name: statistics.median(times) for name, times in walls.items()}
        cells = [f"{medians[name]:.1f} ({min(walls[name]):.1f}–{max(walls[name]):.1f})" for name in names]
        ratios = [f"{medians[name] / medians[reference]:.2f}" for name in names[1:]]
        print("| " + " | ".join([scene_name, *cells, *ratios]) + " |", flush=True)


if __name__ == "__main__":
    main()
