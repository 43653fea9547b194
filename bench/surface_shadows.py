"""Error of `minmax` against `exact` with `render.surface_shadows` `map` and `exact`, on
the bench's fixed pixel subset (bench/RESULTS.md, "Exact surface shadows"):

    .venv/bin/python bench/surface_shadows.py demo behind sun bunny

For each scene at 640×360 (`--size`): `exact` on `bench.error_pixels` (4000 pixels,
seed 20111), then minmax at its defaults with each setting, and `metrics.image_error` on
that subset with `depth_edges_at` excluded: relative RMSE, mean and p99, in %, with the
frame's stage time (median of 3).
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from clrays.reference import metrics  # noqa: E402
from clrays.reference.exact import exact_pixels  # noqa: E402
from clrays.runs.bench import error_pixels  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.session import Renderer  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=["demo", "behind", "sun", "bunny"])
    parser.add_argument("--size", default="640x360")
    parser.add_argument("--pixels", type=int, default=4000)
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    print(f"{width}×{height}, {args.pixels} pixels; errors in % (rel. RMSE, mean / p99), stage time ms\n")
    print("| scene | RMSE, map | RMSE, exact | mean / p99, exact | stage ms, map / exact | exact reference s |")
    print("|---|---|---|---|---|---|")
    renderer = Renderer(reuse=False)
    for name in args.scenes:
        scene = load_scene(REPO / "scenes" / f"{name}.yaml", overrides=[f"image.width={width}", f"image.height={height}"])
        ys, xs = error_pixels(width, height, args.pixels)
        start = time.perf_counter()
        reference = exact_pixels(scene, ys, xs)[:, None, :]
        exact_s = time.perf_counter() - start
        edges = metrics.depth_edges_at(scene, ys, xs)[:, None]
        cells = {}
        for setting in ("map", "exact"):
            chosen = load_scene(REPO / "scenes" / f"{name}.yaml",
                                overrides=[f"image.width={width}", f"image.height={height}",
                                           f"render.surface_shadows={setting}"])
            renderer.render(chosen, "minmax")  # warm-up: kernel builds
            runs = [renderer.render(chosen, "minmax") for _ in range(3)]
            image = runs[-1].image[ys, xs][:, None, :]
            cells[setting] = (metrics.image_error(image, reference, edges),
                              statistics.median(sum(run.stage_ms.values()) for run in runs))
        (m, m_ms), (e, e_ms) = cells["map"], cells["exact"]
        print(f"| {name} | {100 * m.rmse:.3f} | {100 * e.rmse:.3f} | {100 * e.mean:.3f} / {100 * e.p99:.3f} "
              f"| {m_ms:.0f} / {e_ms:.0f} | {exact_s:.0f} |", flush=True)


if __name__ == "__main__":
    main()
