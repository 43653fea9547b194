"""Translucent occluders on scenes/glass_pane.yaml: what the translucency stage costs, and
how far minmax and raymarch are from exact (docs/design.md, "Translucent occluders: the
light side"; recorded in bench/RESULTS.md).

    .venv/bin/python bench/translucency.py --size 1280x720 --frames 3      # stage times
    .venv/bin/python bench/translucency.py --size 640x360 --error          # error against exact

Times: the scene as written against the same scene with the pane opaque
(`objects.1.opacity=1`, which takes the opaque-only path), every stage computed (no
reuse), median of `--frames` frames after a warm-up. Error: relative RMSE of luminance
(`clrays.reference.metrics.image_error`) and per channel, depth edges out and the pixels
whose rays cross the pane (grown by a pixel), whose compositing is the camera side's;
`--films` keeps those in.
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

import clrays
from clrays.reference.exact import render_exact
from clrays.reference.metrics import depth_edges, depth_map, image_error
from clrays.reference.translucency import film_pixels
from clrays.session import Renderer

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "glass_pane.yaml"


def times(size: list[str], frames: int) -> None:
    renderer = Renderer(reuse=False)
    print("| scene | method | stage total ms | translucency ms | traverse or raymarch ms | device MiB |")
    print("|---|---|---:|---:|---:|---:|")
    for label, extra in (("glass_pane", []), ("pane opaque", ["objects.1.opacity=1"])):
        scene = clrays.load_scene(SCENE, overrides=size + extra)
        for method in ("minmax", "raymarch"):
            renderer.render(scene, method)  # warm-up: kernel builds
            runs = [renderer.render(scene, method) for _ in range(frames)]
            total = statistics.median(sum(run.stage_ms.values()) for run in runs)
            stage = statistics.median(run.stage_ms.get("translucency", 0.0) for run in runs)
            walk = statistics.median(run.stage_ms.get("traverse", run.stage_ms.get("raymarch", 0.0)) for run in runs)
            print(f"| {label} | {method} | {total:.0f} | {stage:.0f} ({runs[0].stage_status['translucency']}) "
                  f"| {walk:.0f} | {runs[0].device_bytes / 2**20:.0f} |")


def errors(size: list[str], steps: int, films: bool) -> None:
    print("| method | sampling | rel. RMSE | R, G, B rel. RMSE | mean | p99 |")
    print("|---|---|---:|---|---:|---:|")
    scene = clrays.load_scene(SCENE, overrides=size + [f"render.steps={steps}"])
    start = time.perf_counter()
    reference = render_exact(scene)
    exact_s = time.perf_counter() - start
    exclude = depth_edges(depth_map(scene))
    if not films:
        exclude |= film_pixels(scene, grow=True)
    keep = ~exclude
    for method, sampling in (("raymarch", "epipolar"), ("minmax", "epipolar"), ("minmax", "pixel")):
        image = clrays.render(clrays.load_scene(SCENE, overrides=size + [f"render.steps={steps}",
                                                                         f"render.sampling={sampling}"]), method)
        error = image_error(image, reference, exclude)
        channels = [np.sqrt(np.mean((image[..., c][keep] - reference[..., c][keep]) ** 2))
                    / reference[..., c][keep].mean() for c in range(3)]
        shown = sampling if method == "minmax" else "-"
        print(f"| {method} | {shown} | {error.rmse:.2%} | {', '.join(f'{c:.2%}' for c in channels)} "
              f"| {error.mean:.2%} | {error.p99:.2%} |")
    print(f"\n(exact: {exact_s:.0f} s; {int(keep.sum())} of {keep.size} pixels compared)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="1280x720", help="WxH")
    parser.add_argument("--frames", type=int, default=3)
    parser.add_argument("--error", action="store_true", help="error against exact instead of times")
    parser.add_argument("--steps", type=int, default=1024, help="raymarch steps for --error")
    parser.add_argument("--films", action="store_true",
                        help="--error over the pixels that see the pane too (the camera side's compositing)")
    args = parser.parse_args()
    width, height = args.size.split("x")
    size = [f"image.width={width}", f"image.height={height}"]
    if args.error:
        errors(size, args.steps, args.films)
    else:
        times(size, args.frames)


if __name__ == "__main__":
    main()
