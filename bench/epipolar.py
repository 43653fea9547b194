"""Epipolar sampling against the per-pixel walk: time and error against `exact`
(bench/RESULTS.md, "Epipolar sampling"):

    .venv/bin/python bench/epipolar.py demo behind sun --size 1280x720

For each scene: `exact` on `bench.error_pixels` (4000 pixels, seed 20111, kept in
`--cache`), then minmax with `render.sampling: pixel` and `epipolar` (and each `--set`
variant given), alternating, `--frames` frames each after a warm-up. Reported: the
median traverse and frame stage time, the ratio pixel / epipolar of each (same run), and
`metrics.image_error` against exact on the subset with depth edges left out (relative
RMSE, p99, in %), with epipolar sampling's counts.
"""
from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from clrays.runs.bench import error_pixels  # noqa: E402
from clrays.runs.references import EXACT, ReferenceCache  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.session import Renderer  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=["demo", "behind", "sun", "bunny"])
    parser.add_argument("--size", default="1280x720")
    parser.add_argument("--pixels", type=int, default=4000)
    parser.add_argument("--frames", type=int, default=3)
    parser.add_argument("--cache", default=str(REPO / ".cache" / "references"))
    parser.add_argument("--variant", action="append", default=[],
                        help="extra epipolar settings, e.g. 'render.initial_step=16,render.line_samples=512'")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    ys, xs = error_pixels(width, height, args.pixels)
    references = ReferenceCache(args.cache)
    renderer = Renderer(reuse=False)
    settings = [("pixel", ["render.sampling=pixel"]), ("epipolar", [])]
    settings += [(variant, variant.split(",")) for variant in args.variant]
    print(f"{width}×{height}; error against exact on {args.pixels} pixels, depth edges out, in %; "
          f"times: median of {args.frames} frames, ms\n")
    print("| scene | sampling | traverse ms | frame ms | traverse ×, frame × | RMSE | p99 | "
          "line samples computed | camera samples fixed up |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in args.scenes:
        path = REPO / "scenes" / f"{name}.yaml"
        size = [f"image.width={width}", f"image.height={height}"]
        scenes = {label: load_scene(path, overrides=size + overrides) for label, overrides in settings}
        runs = {label: [] for label in scenes}
        for label, scene in scenes.items():
            renderer.render(scene)  # warm-up: kernel builds
        for _ in range(args.frames):
            for label, scene in scenes.items():
                runs[label].append(renderer.render(scene))
        pixel_traverse = statistics.median(run.stage_ms["traverse"] for run in runs["pixel"])
        pixel_frame = statistics.median(sum(run.stage_ms.values()) for run in runs["pixel"])
        for label, scene in scenes.items():
            traverse = statistics.median(run.stage_ms["traverse"] for run in runs[label])
            frame = statistics.median(sum(run.stage_ms.values()) for run in runs[label])
            error = references.error(scene, EXACT, runs[label][-1].image, (ys, xs))
            counts = runs[label][-1].samples
            computed = f"{counts.computed}" if counts else "–"
            fixed = f"{counts.fixed_up} of {width * height * scene.image.spp}" if counts else "–"
            print(f"| {name} | {label} | {traverse:.0f} | {frame:.0f} | {pixel_traverse / traverse:.2f}, "
                  f"{pixel_frame / frame:.2f} | {100 * error.rmse:.3f} | {100 * error.p99:.3f} | {computed} | "
                  f"{fixed} |", flush=True)


if __name__ == "__main__":
    main()
