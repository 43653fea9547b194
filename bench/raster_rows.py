"""Raster stage time with big triangles drawn one row per work-item (the default) against
a build where every triangle draws its own rows (RASTER_BIG_ROWS beyond any view), in one
process, alternating; checks the images are the same bits (bench/RESULTS.md, "Costs that
follow the image").

    .venv/bin/python bench/raster_rows.py scenes/demo.yaml --size 1280x720 --frames 3
"""
from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from clrays import structs  # noqa: E402
from clrays.device import Device  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.session import Renderer  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene")
    parser.add_argument("--size", default="1280x720", help="WxH (default 1280x720)")
    parser.add_argument("--frames", type=int, default=3, help="timed frames each after a warm-up (default 3)")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    scene = load_scene(args.scene, overrides=[f"image.width={width}", f"image.height={height}"])
    binned = Renderer(Device(None), reuse=False)
    default_rows = structs.KERNEL_CONSTANTS["RASTER_BIG_ROWS"]
    structs.KERNEL_CONSTANTS["RASTER_BIG_ROWS"] = 1 << 30  # the build options are read at build time
    one_pass_device = Device(None)
    for defines in (None, {"RASTER_ATOMIC64": 1}):
        one_pass_device.program("raster", defines)
    structs.KERNEL_CONSTANTS["RASTER_BIG_ROWS"] = default_rows
    one_pass = Renderer(one_pass_device, reuse=False)
    times, images = {"one pass": [], "binned": []}, {}
    for frame in range(args.frames + 1):
        for name, renderer in (("one pass", one_pass), ("binned", binned)):
            result = renderer.render(scene)
            images[name] = result.image
            if frame:  # frame 0 builds the kernels
                times[name].append(result.stage_ms["raster"])
    one, big = statistics.median(times["one pass"]), statistics.median(times["binned"])
    print(f"{args.scene} {width}×{height}: raster one pass {one:.0f} ms, binned {big:.0f} ms, ratio {one / big:.2f}; "
          f"same image: {np.array_equal(images['one pass'], images['binned'])}")


if __name__ == "__main__":
    main()
