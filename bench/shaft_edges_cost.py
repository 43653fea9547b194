"""Frame time and error of `render.shaft_edges: blockers` against `texels` on the same
tree, the two in turns (bench/RESULTS.md, "Shaft edges on the blockers").

    .venv/bin/python bench/shaft_edges_cost.py --size 1280x720 --rounds 5
    .venv/bin/python bench/shaft_edges_cost.py sun lattice --size 320x180 --errors --cache /tmp/err_cache
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from arguments import image_size  # noqa: E402  (bench/, beside this script)
from clrays.runs.bench import DEFAULT_SCENES, error_pixels  # noqa: E402
from clrays.runs.references import EXACT, ReferenceCache  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.session import Renderer  # noqa: E402

MODES = ("texels", "blockers")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=[Path(path).stem for path in DEFAULT_SCENES[:4]])
    parser.add_argument("--size", type=image_size, default="1280x720")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--errors", action="store_true", help="also the error against exact (4000 pixels)")
    parser.add_argument("--cache", default=str(REPO / ".cache" / "references"))
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    renderer = Renderer(reuse=False)
    references = ReferenceCache(Path(args.cache))
    print(f"{width}×{height}; wall ms per frame, median of {args.rounds} rounds, the two modes in turns\n")
    print("| scene | texels ms | blockers ms | blockers / texels |" + (" texels RMSE % | blockers RMSE % |"
                                                                   if args.errors else ""))
    print("|---|---|---|---|" + ("---|---|" if args.errors else ""))
    for name in args.scenes:
        scenes = {mode: load_scene(REPO / "scenes" / f"{name}.yaml", overrides=[
            f"image.width={width}", f"image.height={height}", f"render.shaft_edges={mode}"]) for mode in MODES}
        times = {mode: [] for mode in MODES}
        for mode in MODES:
            renderer.render(scenes[mode])  # kernels built
        for _ in range(args.rounds):
            for mode in MODES:
                start = time.perf_counter()
                renderer.render(scenes[mode])
                times[mode].append((time.perf_counter() - start) * 1e3)
        medians = {mode: statistics.median(times[mode]) for mode in MODES}
        row = f"| {name} | {medians['texels']:.1f} | {medians['blockers']:.1f} | " \
              f"{medians['blockers'] / medians['texels']:.2f} |"
        if args.errors:
            pixels = error_pixels(width, height, 4000)
            for mode in MODES:
                error = references.error(scenes[mode], EXACT, renderer.render(scenes[mode]).image, pixels)
                row += f" {100 * error.rmse:.3f} |"
        print(row, flush=True)


if __name__ == "__main__":
    main()
