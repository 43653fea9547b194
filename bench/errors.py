"""The error against `exact` of each bench scene's default render, measured as `clrays
bench` measures it: `exact` on the bench's fixed pixel subset (4000 pixels, seed 20111,
kept in `--cache`), relative luminance RMSE and p99 with depth edges left out (bench/RESULTS.md
quotes these for every change that moves an image).

    .venv/bin/python bench/errors.py --size 1280x720
    .venv/bin/python bench/errors.py demo sun --size 640x360
    .venv/bin/python bench/errors.py --size 640x360 --set render.sampling=pixel   # another setting
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from arguments import image_size  # noqa: E402  (bench/, beside this script)
from clrays.runs.bench import error_pixels  # noqa: E402
from clrays.runs.references import EXACT, ReferenceCache  # noqa: E402
from clrays.errors import ClraysError  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.session import Renderer  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=["demo", "bunny", "behind", "sun"])
    parser.add_argument("--size", type=image_size, default="1280x720")
    parser.add_argument("--pixels", type=int, default=4000)
    parser.add_argument("--cache", default=str(REPO / ".cache" / "references"))
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a scene override, as `clrays render --set` (repeatable)")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    pixels = error_pixels(width, height, args.pixels)
    references = ReferenceCache(Path(args.cache))
    renderer = Renderer(reuse=False)
    settings = ", ".join(args.set) or "default settings"
    print(f"{width}×{height}, {settings}; error against exact on {args.pixels} pixels, depth edges out\n")
    print("| scene | relative RMSE % | p99 % |")
    print("|---|---|---|")
    for name in args.scenes:
        try:
            scene = load_scene(REPO / "scenes" / f"{name}.yaml", overrides=[f"image.width={width}",
                                                                              f"image.height={height}", *args.set])
        except ClraysError as exc:
            sys.exit(f"errors.py: {exc}")
        error = references.error(scene, EXACT, renderer.render(scene).image, pixels)
        if not error.pixels:  # every pixel of a tiny image on a depth edge or dark
            print(f"| {name} | — | — (no pixel left to compare) |", flush=True)
            continue
        print(f"| {name} | {100 * error.rmse:.4f} | {100 * error.p99:.4f} |", flush=True)


if __name__ == "__main__":
    main()
