"""`volume_moments` against `minmax` at one size, timed in the same run, and both against `exact`
on the bench's fixed pixel subset (bench/RESULTS.md, "The moments method"):

    .venv/bin/python bench/moments_method.py demo bunny behind sun --size 1280x720

For each scene: `exact` on `bench.error_pixels` (`--pixels`, seed 20111), then frames of
minmax and moments alternating (one warm-up each, then `--repeats` each, every stage
computed), the median wall time and device time of each, their ratio, and
`metrics.image_error` on the subset with `depth_edges_at` excluded (relative RMSE, p99).
"""
from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from clrays.reference import metrics  # noqa: E402
from clrays.reference.exact import exact_pixels  # noqa: E402
from clrays.runs.bench import error_pixels  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.session import Renderer  # noqa: E402

METHODS = ("minmax", "volume_moments")


def write_images(folder: Path, name: str, minmax, moments) -> None:
    from PIL import Image

    from clrays.image_io import make_folder, write_image
    from clrays.runs.compare import heat_map

    make_folder(folder)
    write_image(folder / f"{name}_minmax.png", minmax)
    write_image(folder / f"{name}_moments.png", moments)
    Image.fromarray(heat_map(moments, minmax)).save(folder / f"{name}_moments_diff.png")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=["demo", "bunny", "behind", "sun"])
    parser.add_argument("--size", default="1280x720")
    parser.add_argument("--pixels", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--images", type=Path, help="write <scene>_minmax.png, <scene>_moments.png and "
                        "<scene>_moments_diff.png (heat map against minmax: red brighter, blue darker) here")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    print(f"{width}×{height}; times: median of {args.repeats} frames, interleaved; errors against exact on "
          f"{args.pixels} pixels, %\n")
    print("| scene | minmax wall ms | moments wall ms | ratio | minmax device ms | moments device ms | ratio "
          "| traverse ms | volume_moments ms | minmax RMSE / p99 | moments RMSE / p99 |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    renderer = Renderer(reuse=False)
    for name in args.scenes:
        scene = load_scene(REPO / "scenes" / f"{name}.yaml",
                           overrides=[f"image.width={width}", f"image.height={height}"])
        ys, xs = error_pixels(width, height, args.pixels)
        reference = exact_pixels(scene, ys, xs)[:, None, :]
        edges = metrics.depth_edges_at(scene, ys, xs)[:, None]
        for method in METHODS:
            renderer.render(scene, method)  # warm-up: kernel builds
        runs = {method: [] for method in METHODS}
        for _ in range(args.repeats):
            for method in METHODS:
                runs[method].append(renderer.render(scene, method))
        cells = {}
        for method, results in runs.items():
            error = metrics.image_error(results[-1].image[ys, xs][:, None, :], reference, edges)
            cells[method] = (statistics.median(r.wall_ms for r in results),
                             statistics.median(r.device_ms for r in results),
                             statistics.median(r.stage_ms.get("traverse", r.stage_ms.get("volume_moments", 0.0))
                                               for r in results), error)
        (mw, md, mt, me), (ow, od, ot, oe) = cells["minmax"], cells["volume_moments"]
        if args.images:
            images = {method: results[-1].image for method, results in runs.items()}
            write_images(args.images, name, images["minmax"], images["volume_moments"])
        print(f"| {name} | {mw:.0f} | {ow:.0f} | {ow / mw:.2f} | {md:.0f} | {od:.0f} | {od / md:.2f} | {mt:.0f} "
              f"| {ot:.0f} | {100 * me.rmse:.2f} / {100 * me.p99:.1f} | {100 * oe.rmse:.2f} / {100 * oe.p99:.1f} |",
              flush=True)


if __name__ == "__main__":
    main()
