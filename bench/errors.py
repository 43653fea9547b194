"""The error against `exact` of each bench scene's default render, measured as `clrays
bench` measures it: `exact` on the bench's fixed pixel subset (4000 pixels, seed 20111,
kept in `--cache`), relative luminance RMSE and p99 with depth edges left out (bench/RESULTS.md
quotes these for every change that moves an image).

    .venv/bin/python bench/errors.py --size 1280x720
    .venv/bin/python bench/errors.py demo sun --size 640x360
    .venv/bin/python bench/errors.py --size 640x360 --set render.sampling=pixel   # another setting
    .venv/bin/python bench/errors.py --all --methods minmax,raymarch --size 320x180  # every scene in scenes/
    .venv/bin/python bench/errors.py orbit --frame 10 --methods minmax,raymarch --size 640x360

With `--methods`, a pair of columns per method (the scene's own `render` otherwise, as
`--set render.method=M` would give), and the frame time of each (one warm frame).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from arguments import frame_count, image_size  # noqa: E402  (bench/, beside this script)
from clrays.runs.bench import DEFAULT_SCENES, error_pixels  # noqa: E402
from clrays.runs.references import EXACT, ReferenceCache  # noqa: E402
from clrays.errors import ClraysError  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.session import Renderer  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=[Path(path).stem for path in DEFAULT_SCENES],
                        help="scene names in scenes/ (default: the bench's, fine occluders included)")
    parser.add_argument("--all", action="store_true", help="every scene in scenes/ (instead of the bench's)")
    parser.add_argument("--methods", default="", help="comma-separated methods, a column pair each "
                                                      "(default: the scene's own method)")
    parser.add_argument("--frame", type=int, default=None, help="an animated scene's frame (default: its base frame)")
    parser.add_argument("--size", type=image_size, default="1280x720")
    parser.add_argument("--pixels", type=frame_count, default=4000)
    parser.add_argument("--cache", default=str(REPO / ".cache" / "references"))
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a scene override, as `clrays render --set` (repeatable)")
    args = parser.parse_args()
    names = sorted(path.stem for path in (REPO / "scenes").glob("*.yaml")) if args.all else args.scenes
    methods = [method for method in args.methods.split(",") if method] or [None]
    width, height = (int(v) for v in args.size.split("x"))
    pixels = error_pixels(width, height, args.pixels)
    references = ReferenceCache(Path(args.cache))
    renderer = Renderer(reuse=False)
    settings = ", ".join(args.set) or "default settings"
    print(f"{width}×{height}, {settings}; error against exact on {args.pixels} pixels, depth edges out\n")
    if methods == [None]:
        print("| scene | relative RMSE % | p99 % |")
        print("|---|---|---|")
    else:
        print("| scene | " + " | ".join(f"{m} RMSE % | {m} p99 % | {m} ms" for m in methods) + " |")
        print("|---|" + "---|---|---|" * len(methods))
    for name in names:
        cells = []
        for method in methods:
            chosen = [f"render.method={method}"] if method else []
            try:
                scene = load_scene(REPO / "scenes" / f"{name}.yaml",
                                   overrides=[f"image.width={width}", f"image.height={height}", *chosen, *args.set])
            except ClraysError as exc:
                sys.exit(f"errors.py: {exc}")
            if args.frame is not None and scene.animation is not None:
                scene = scene.animation.scene_at(scene, args.frame)
            renderer.render(scene)  # kernels built
            start = time.perf_counter()
            image = renderer.render(scene).image
            frame_ms = (time.perf_counter() - start) * 1e3
            error = references.error(scene, EXACT, image, pixels)
            if not error.pixels:  # every pixel of a tiny image on a depth edge or dark
                cells.append("— | — (no pixel left to compare)" + (" | —" if method else ""))
                continue
            cells.append(f"{100 * error.rmse:.4f} | {100 * error.p99:.4f}" + (f" | {frame_ms:.0f}" if method else ""))
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
