"""A 1024 × 1024 relief drawn by its pre-warp against the same relief as a 2M-triangle
mesh, frame time and error against `exact` (bench/RESULTS.md, "Relief objects"):

    .venv/bin/python bench/relief.py                    # 640×360, 1024² texels, 100 error pixels
    .venv/bin/python bench/relief.py --texels 256 --size 320x180

The relief is a field of Gaussian bumps without holes (2·1023² = 2 093 058 triangles at
1024²) on a floor, under a spot light in fog; the mesh is what `relief_to_mesh` writes
for it (a PLY). Each setting is rendered once untimed (kernel builds), then 3 times
alternating relief and mesh; the table gives the median wall time of a frame, the
median of its stage times (device events and host stages), the relief pass's, the
raster's and the visibility BVH's (host) share, and the mesh frame's wall time over the
relief frame's. A relief keeps what frames derive from its texels (its bounds, digest,
faces, BVH subtree and boxes: docs/design.md, "What a frame carries"), so the row
"relief, first" is one frame of the same scene loaded afresh, which derives them. The
error is `metrics.image_error` against `exact` (of the mesh, the same triangles) on
`--pixels` pixels of `bench.error_pixels`, depth edges excluded.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from clrays.reference import metrics  # noqa: E402
from clrays.reference.exact import exact_pixels  # noqa: E402
from clrays.runs.bench import error_pixels  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.scene.relief import relief_to_mesh  # noqa: E402
from clrays.session import Renderer  # noqa: E402

SCENE = """version: 1
image: {{width: {width}, height: {height}}}
camera: {{position: [2.2, 2.4, 3.0], look_at: [0, 0.1, 0], fov_deg: 50, far: 20}}
lights: [{{type: spot, position: [1.5, 3.5, 1.0], direction: [-0.35, -1, -0.2], cone_deg: 40, intensity: 12}}]
medium: {{sigma_s: 0.08, sigma_a: 0.01}}
render: {{surface_shadows: {shadows}}}
objects:
  - {{type: plane, center: [0, -0.6, 0], normal: [0, 1, 0], size: 8, segments: 1, albedo: 0.6}}
  - {{type: relief, center: [0, 0, 0], normal: [0, 1, 0], up: [0, 0, -1], size: [2.5, 2.5], depth_map: bumps.npy,
     height: 0.45, albedo: [0.7, 0.6, 0.5]}}
"""


def bump_field(size: int, seed: int = 3) -> np.ndarray:
    """Gaussian bumps of random centres and widths, in [0, 1] (as tests/methods/test_relief.py)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] + 0.5
    field = np.zeros((size, size))
    for _ in range(7):
        cx, cy = rng.uniform(0.15, 0.85, 2) * size
        width = rng.uniform(0.06, 0.16) * size
        field += np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * width ** 2))
    return field / field.max()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="640x360")
    parser.add_argument("--texels", type=int, default=1024)
    parser.add_argument("--pixels", type=int, default=100)
    parser.add_argument("--method", default="minmax")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    folder = Path(tempfile.mkdtemp(prefix="clrays-relief-bench-"))
    np.save(folder / "bumps.npy", bump_field(args.texels))
    renderer = Renderer(reuse=False)
    print(f"{width}×{height}, {args.method}, relief {args.texels}² texels; times in ms (median of 3)\n")
    print("| surface_shadows | frame | wall | stages | relief pass | raster | bvh (host) | triangles drawn by raster |")
    print("|---|---|---|---|---|---|---|---|")
    errors = {}
    for shadows in ("map", "exact"):
        path = folder / f"relief_{shadows}.yaml"
        path.write_text(SCENE.format(width=width, height=height, shadows=shadows))
        relief_to_mesh(path, folder / "relief.ply", 1)
        scenes = {"relief": load_scene(path),
                  "mesh": load_scene(path, ["objects.1={type: mesh, file: relief.ply, normals: flat, "
                                            "albedo: [0.7, 0.6, 0.5]}"])}
        runs = {name: [] for name in scenes}
        for name, scene in scenes.items():
            renderer.render(scene, args.method)  # warm-up: kernel builds
        for _ in range(3):
            for name, scene in scenes.items():
                runs[name].append(renderer.render(scene, args.method))
        runs["relief, first"] = [renderer.render(load_scene(path), args.method)]
        scenes["relief, first"] = scenes["relief"]
        for name, results in runs.items():
            geometry = scenes[name].geometry
            drawn = geometry.count - sum(r.rows.stop - r.rows.start for r in geometry.reliefs)
            print(f"| {shadows} | {name} | {statistics.median(r.wall_ms for r in results):.0f} "
                  f"| {statistics.median(sum(r.stage_ms.values()) for r in results):.0f} "
                  f"| {statistics.median(r.stage_ms.get('relief', 0.0) for r in results):.0f} "
                  f"| {statistics.median(r.stage_ms.get('raster', 0.0) for r in results):.0f} "
                  f"| {statistics.median(r.stage_ms.get('bvh', 0.0) for r in results):.0f} | {drawn} |", flush=True)
        ratio = (statistics.median(r.wall_ms for r in runs["mesh"])
                 / statistics.median(r.wall_ms for r in runs["relief"]))
        print(f"| {shadows} | mesh / relief wall | {ratio:.2f}× | | | | | |", flush=True)
        errors[shadows] = {name: results[-1].image for name, results in runs.items() if name != "relief, first"}
    ys, xs = error_pixels(width, height, args.pixels)
    mesh_scene = load_scene(folder / "relief_map.yaml", ["objects.1={type: mesh, file: relief.ply, normals: flat, "
                                                         "albedo: [0.7, 0.6, 0.5]}"])
    start = time.perf_counter()
    reference = exact_pixels(mesh_scene, ys, xs)[:, None, :]
    seconds = time.perf_counter() - start
    edges = metrics.depth_edges_at(mesh_scene, ys, xs)[:, None]
    print(f"\nError against exact on {args.pixels} pixels ({seconds:.0f} s), depth edges excluded:\n")
    print("| surface_shadows | frame | rel. RMSE | mean | p99 |")
    print("|---|---|---|---|---|")
    for shadows, images in errors.items():
        for name, image in images.items():
            error = metrics.image_error(image[ys, xs][:, None, :], reference, edges)
            print(f"| {shadows} | {name} | {100 * error.rmse:.3f} % | {100 * error.mean:.3f} % "
                  f"| {100 * error.p99:.3f} % |", flush=True)


if __name__ == "__main__":
    main()
