"""Does a tuned setting keep its promise off the pixels it was tuned on? Per scene, the
setting `clrays tune` picks with its margin and held-out check (clrays.runs.tune) beside
the one the search alone picks (aiming at the target itself, nothing held out), each
measured against `exact` on every pixel of the image (depth edges out) (bench/RESULTS.md,
"Tuning: the promise off the sample").

    .venv/bin/python bench/tune_held_out.py grate --size 128x72 --target 2 --pixels 800
    .venv/bin/python bench/tune_held_out.py grate --size 160x90 --target 1 --most-settings 100
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from arguments import image_size  # noqa: E402  (bench/, beside this script)
from clrays.reference.exact import exact_pixels  # noqa: E402
from clrays.reference.metrics import depth_edges_at, image_error  # noqa: E402
from clrays.runs import tune as tuning  # noqa: E402
from clrays.runs.references import ReferenceCache  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.session import Renderer  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+", help="names of scenes/*.yaml")
    parser.add_argument("--size", type=image_size, default="160x90")
    parser.add_argument("--target", type=float, default=1.0, help="percent")
    parser.add_argument("--pixels", type=int, default=tuning.TUNE_PIXELS, help="the search's sample")
    parser.add_argument("--most-settings", type=int, default=tuning.MOST_SETTINGS)
    parser.add_argument("--cache", type=Path, default=REPO / ".cache" / "bench-references")
    args = parser.parse_args()
    width, height = map(int, args.size.split("x"))
    target = args.target / 100
    print("| scene | search | setting | on its sample % | held out % | whole image % | settings | s |")
    print("|---|---|---|---|---|---|---|---|")
    for name in args.scenes:
        scene = load_scene(REPO / "scenes" / f"{name}.yaml", [f"image.width={width}", f"image.height={height}"])
        ys, xs = np.divmod(np.arange(width * height), width)
        reference, edges = exact_pixels(scene, ys, xs), depth_edges_at(scene, ys, xs)
        references = ReferenceCache(args.cache)
        for label, margin, held_out in (("alone", 1.0, False), ("clrays tune", tuning.SEARCH_MARGIN, True)):
            renderer = Renderer(reuse=False)
            method = scene.render.method
            search = tuning.Search(scene, method, references, renderer, args.pixels, repeats=1)
            if not held_out:
                search.held_out_pixels, search.held_out_frames = None, []
            started = time.perf_counter()
            result = tuning.tune(scene, target, references, renderer, method, args.pixels, repeats=1, search=search,
                                 most_settings=args.most_settings, margin=margin)
            seconds = time.perf_counter() - started
            best = result.best
            if best is None:
                print(f"| {name} | {label} | not reached (best {100 * result.closest.rmse:.3f} %) | | | | "
                      f"{len(result.trials)} | {seconds:.0f} |")
                continue
            image = renderer.render(tuning.with_settings(scene, best.settings)).image
            whole = image_error(image[ys, xs], reference, edges).rmse
            kept = "-" if result.held_out is None else f"{100 * result.held_out:.3f}"
            print(f"| {name} | {label} | {tuning.settings_text(best.settings)} | {100 * best.rmse:.3f} | {kept} | "
                  f"{100 * whole:.3f} | {len(result.trials)} | {seconds:.0f} |", flush=True)


if __name__ == "__main__":
    main()
