"""Frame time of minmax in a bounded or heterogeneous medium against the homogeneous one
(docs/media.md, "The walk"): a bench scene as it is, with height fog, and with a 128³ density
grid over its bounds, rendered from scratch in turns (so that a loaded machine slows each
alike), median stage time (ms) and its ratio to the homogeneous frame.

    .venv/bin/python bench/media_cost.py --size 1280x720 --frames 3 demo sun
"""
from __future__ import annotations

import dataclasses
import os
import statistics
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from harness import REPO, check_scenes, frame_arguments  # noqa: E402  (bench/, beside this script)
from clrays.scene.load import load_scene  # noqa: E402
from clrays.scene.model import Box, GridDensity, HeightDensity  # noqa: E402
from clrays.session import Renderer  # noqa: E402

#: Voxels per side of the grid case.
GRID_SIDE = 128


def smooth_grid(bounds: Box, side: int, seed: int = 1) -> GridDensity:
    """A seeded, smooth random density (sums of a few sine waves), side³ voxels, mean about 1."""
    rng = np.random.default_rng(seed)
    axis = (np.arange(side) + 0.5) / side
    z, y, x = np.meshgrid(axis, axis, axis, indexing="ij")
    values = np.ones((side, side, side))
    for _ in range(6):
        k = rng.uniform(2, 12, 3)
        values += 0.15 * np.sin(2 * np.pi * (k[0] * x + k[1] * y + k[2] * z) + rng.uniform(0, 2 * np.pi))
    return GridDensity(np.clip(values, 0, None).astype(np.float32), bounds)


def media(scene) -> dict:
    """name → scene: the homogeneous medium, height fog, a grid over the scene's bounds."""
    lo, hi = (np.asarray(v, np.float64) for v in scene.geometry.bounds())
    base = float(lo[1])
    height = dataclasses.replace(scene.medium, density=HeightDensity(base=base, scale_height=max(hi[1] - lo[1], 1.0) / 2))
    grid = dataclasses.replace(scene.medium, density=smooth_grid(Box(lo, hi), GRID_SIDE))
    return {"homogeneous": scene, "height fog": dataclasses.replace(scene, medium=height),
            f"{GRID_SIDE}³ grid": dataclasses.replace(scene, medium=grid)}


def main() -> None:
    parser = frame_arguments(__doc__.splitlines()[0], "1280x720", 3)
    args = parser.parse_args()
    scenes = args.scenes if args.scenes != parser.get_default("scenes") else ["demo", "sun"]
    check_scenes("media_cost.py", scenes)
    width, height = (int(v) for v in args.size.split("x"))
    print(f"{width}×{height}, minmax, median of {args.frames} frames in turns, stage ms; load average "
          f"{os.getloadavg()[0]:.1f} at start\n")
    print("| scene | medium | traverse | shade | total | × homogeneous |")
    print("|---|---|---|---|---|---|")
    for name in scenes:
        scene = load_scene(REPO / "scenes" / f"{name}.yaml",
                           overrides=[f"image.width={width}", f"image.height={height}", *args.overrides])
        cases = media(scene)
        renderer = Renderer(reuse=False)
        for case in cases.values():  # warm-up: kernel builds
            renderer.render(case, "minmax")
        runs = {label: [] for label in cases}
        for _ in range(args.frames):
            for label, case in cases.items():
                runs[label].append(renderer.render(case, "minmax").stage_ms)
        base = statistics.median(sum(run.values()) for run in runs["homogeneous"])
        for label, stage_ms in runs.items():
            total = statistics.median(sum(run.values()) for run in stage_ms)
            traverse = statistics.median(run.get("traverse", 0.0) for run in stage_ms)
            shade = statistics.median(run.get("shade", 0.0) for run in stage_ms)
            print(f"| {name} | {label} | {traverse:.0f} | {shade:.0f} | {total:.0f} | {total / base:.2f} |", flush=True)


if __name__ == "__main__":
    main()
