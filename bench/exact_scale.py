"""How `exact` and the BVH build scale (bench/RESULTS.md, "exact on the BVH"):

    .venv/bin/python bench/exact_scale.py            # BVH builds, a 1M-triangle terrain at 160×90
    .venv/bin/python bench/exact_scale.py --bunny    # and the bunny at 640×360 in full

- `build_bvh` on the bunny (75,536 triangles) and on 1M random triangles: median of 3.
- `exact` (on the BVH) on a generated 1M-triangle mesh: a 708 × 708 heightfield of
  rolling hills under a point light in fog, its ridges shadowing the valleys; and with
  --bunny, `render_exact` on scenes/bunny.yaml at its own 640×360.
Scenes are built here (seeded), so nothing beside the repository is needed.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from clrays.bvh import build_bvh  # noqa: E402
from clrays.reference.exact import render_exact  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.scene.model import Camera, Geometry, Image, Medium, Phase, PointLight, Render, Scene  # noqa: E402


def terrain(cells: int = 708, size: float = 20.0) -> np.ndarray:
    """2·cells² triangles of the heightfield y = hills(x, z) over [-size/2, size/2]²."""
    axis = np.linspace(-size / 2, size / 2, cells + 1)
    x, z = np.meshgrid(axis, axis, indexing="ij")
    y = 0.6 * np.sin(0.9 * x) * np.cos(0.7 * z) + 0.25 * np.sin(2.3 * x + 1.1 * z) + 0.05 * np.sin(9.0 * x)
    v = np.stack([x, y, z], axis=-1)
    a, b, c, d = v[:-1, :-1], v[1:, :-1], v[1:, 1:], v[:-1, 1:]
    return np.concatenate([np.stack([a, b, c], axis=-2).reshape(-1, 3, 3),
                           np.stack([a, c, d], axis=-2).reshape(-1, 3, 3)])


def terrain_scene(width: int, height: int) -> Scene:
    tri = terrain()
    return Scene(image=Image(width, height, 1),
                 camera=Camera(np.array([0.0, 3.0, 11.0]), np.zeros(3), np.array([0.0, 1, 0]), 60.0, 40.0),
                 lights=(PointLight(np.array([-6.0, 2.5, -4.0]), np.array([40.0, 36, 30])),),
                 medium=Medium(np.array([0.06, 0.06, 0.06]), np.array([0.01, 0.01, 0.01]), Phase("hg", 0.3)),
                 background=np.zeros(3),
                 geometry=Geometry(tri, np.full((len(tri), 3), 0.6), np.zeros(len(tri), np.int32)),
                 render=Render(method="exact"))


def median_build_seconds(triangles: np.ndarray, runs: int = 3) -> float:
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        build_bvh(triangles)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="160x90", help="terrain image size")
    parser.add_argument("--bunny", action="store_true", help="also exact on the bunny at 640×360 (about a minute)")
    args = parser.parse_args()
    bunny = load_scene(REPO / "scenes" / "bunny.yaml")
    random = np.random.default_rng(20111).uniform(-1, 1, (1_000_000, 1, 3)) \
        + np.random.default_rng(7).normal(0, 0.01, (1_000_000, 3, 3))
    bunny_seconds = median_build_seconds(bunny.geometry.triangles)
    print(f"build_bvh, bunny ({bunny.geometry.count} triangles): {bunny_seconds:.3f} s")
    print(f"build_bvh, 1M random triangles: {median_build_seconds(random):.3f} s")
    width, height = (int(v) for v in args.size.split("x"))
    scene = terrain_scene(width, height)
    start = time.perf_counter()
    image = render_exact(scene)
    print(f"exact, terrain ({scene.geometry.count} triangles) at {width}×{height}: "
          f"{time.perf_counter() - start:.1f} s (mean radiance {image.mean():.4g})")
    if args.bunny:
        start = time.perf_counter()
        image = render_exact(bunny)
        print(f"exact, bunny at {bunny.image.width}×{bunny.image.height}: {time.perf_counter() - start:.1f} s "
              f"(mean radiance {image.mean():.4g})")


if __name__ == "__main__":
    main()
