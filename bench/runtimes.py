"""The bench scenes on every CPU OpenCL runtime installed, in one run: each runtime's image
against PoCL's (minmax and raymarch), and warm minmax frame times taken in turns
(bench/RESULTS.md, "Every CPU runtime"; docs/devices.md's table of runtimes).

    .venv/bin/python bench/runtimes.py --size 1280x720 --rounds 7
    .venv/bin/python bench/runtimes.py --size 320x180 --rounds 3 demo

Intel's CPU runtime comes with `pip install '.[intel-cpu]'`; clrays finds it by itself
(clrays/runtimes.py). Images are rendered from scratch (no reuse). The difference is the
relative RMSE of the linear RGB images, sqrt(mean((a − b)²)) / sqrt(mean(b²)), b PoCL's,
over every pixel and channel. Frame time is the wall time of `Renderer.render`, median
over the rounds; each round renders every runtime's frame once, one after the other, so
the machine's slow spells fall on every runtime alike.
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

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from arguments import frame_count, image_size  # noqa: E402  (bench/, beside this script)
from clrays.device import Device, list_devices  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.session import Renderer  # noqa: E402

SCENES = ("demo", "bunny", "behind", "sun")
METHODS = ("minmax", "raymarch")
POCL = "Portable Computing Language"


def relative_rmse(image: np.ndarray, reference: np.ndarray) -> float:
    reference = reference.astype(np.float64)
    return float(np.sqrt(np.mean((image - reference) ** 2)) / max(np.sqrt(np.mean(reference ** 2)), 1e-30))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=SCENES, help="scene names in scenes/ (default: the bench four)")
    parser.add_argument("--size", type=image_size, default="1280x720", help="WxH (default 1280x720)")
    parser.add_argument("--rounds", type=frame_count, default=7, help="timed minmax frames per runtime (default 7)")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    cpus = [(f"{p}:{d}", platform.name.strip()) for p, d, platform, device in list_devices()
            if device.type & cl.device_type.CPU]
    cpus.sort(key=lambda entry: entry[1] != POCL)  # PoCL first: the images are compared with its
    if not cpus or cpus[0][1] != POCL:
        sys.exit("runtimes.py: PoCL's CPU device is not installed (pocl-binary-distribution)")
    renderers = {name: Renderer(Device(spec), reuse=False) for spec, name in cpus}
    print(f"{width}×{height}; runtimes: {', '.join(f'{name} ({spec})' for spec, name in cpus)}; "
          f"load average {os.getloadavg()[0]:.1f} at start\n")
    names = list(renderers)
    print("| scene | method | " + " | ".join(f"{name}: rel. RMSE vs PoCL" for name in names[1:]) + " |")
    print("|---|---|" + "---|" * (len(names) - 1))
    scenes = {}
    for scene_name in args.scenes:
        scenes[scene_name] = scene = load_scene(REPO / "scenes" / f"{scene_name}.yaml",
                                                overrides=[f"image.width={width}", f"image.height={height}"])
        for method in METHODS:
            images = {name: np.asarray(renderer.render(scene, method=method).image, dtype=np.float64)
                      for name, renderer in renderers.items()}
            cells = [f"{relative_rmse(images[name], images[POCL]):.2e}" for name in names[1:]]
            print(f"| {scene_name} | {method} | " + " | ".join(cells) + " |", flush=True)
    print(f"\nminmax frame wall time, ms: median (min–max) of {args.rounds} rounds, in turns\n")
    print("| scene | " + " | ".join(names) + " | " + " | ".join(f"{name} / PoCL" for name in names[1:]) + " |")
    print("|---|" + "---|" * (2 * len(names) - 1))
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
        ratios = [f"{medians[name] / medians[POCL]:.2f}" for name in names[1:]]
        print(f"| {scene_name} | " + " | ".join(cells) + " | " + " | ".join(ratios) + " |", flush=True)


if __name__ == "__main__":
    main()
