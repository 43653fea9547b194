"""How much a warm frame's CPU time varies from run to run, as `clrays tune` times a setting:
every stage computed (`reuse=False`), the process's CPU time, after one frame that builds the
kernels (bench/RESULTS.md, "Tuning the lattice at 640×360", which set tune.LONG_FRAME_MS).

    .venv/bin/python bench/frame_spread.py lattice --size 640x360
    .venv/bin/python bench/frame_spread.py lattice --size 640x360 --set render.shadow_map=4096 --set render.slices=4096
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from arguments import frame_count, image_size  # noqa: E402  (bench/, beside this script)
from clrays.errors import ClraysError  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.session import Renderer  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", help="a scene name in scenes/")
    parser.add_argument("--size", type=image_size, default="640x360")
    parser.add_argument("--frames", type=frame_count, default=7, help="timed frames (default 7)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a scene override, as `clrays render --set` (repeatable)")
    args = parser.parse_args()
    width, height = args.size.split("x")
    try:
        scene = load_scene(REPO / "scenes" / f"{args.scene}.yaml",
                           overrides=[f"image.width={width}", f"image.height={height}", *args.set])
    except ClraysError as exc:
        sys.exit(f"frame_spread.py: {exc}")
    renderer = Renderer(reuse=False)
    renderer.render(scene)  # kernels built
    costs = []
    for _ in range(args.frames):
        start = time.process_time()
        renderer.render(scene)
        costs.append((time.process_time() - start) * 1e3)
    median = statistics.median(costs)
    print(f"{args.scene} {args.size} {' '.join(args.set) or 'default settings'}: CPU ms "
          f"{', '.join(f'{cost:.0f}' for cost in costs)}; median {median:.0f}, spread (max - min) / median "
          f"{(max(costs) - min(costs)) / median:.3f}, first / median {costs[0] / median:.3f}")


if __name__ == "__main__":
    main()
