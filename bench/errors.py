"""The error against `exact` of each bench scene's default render, measured as `clrays
bench` measures it: `exact` on the bench's fixed pixel subset (4000 pixels, seed 20111,
kept in `--cache`), relative luminance RMSE and p99 with depth edges left out
(bench/RESULTS.md, "Accuracy: every scene at every size").

    .venv/bin/python bench/errors.py --size 1280x720
    .venv/bin/python bench/errors.py demo sun --size 640x360
    .venv/bin/python bench/errors.py --size 640x360 --set render.sampling=pixel   # another setting
    .venv/bin/python bench/errors.py --all --methods minmax,raymarch --size 320x180  # every scene in scenes/
    .venv/bin/python bench/errors.py orbit --frame 10 --methods minmax,raymarch --size 640x360
    .venv/bin/python bench/errors.py --all orbit@10 --methods minmax --size 96x64,320x180,640x360,1280x720

A scene named NAME@N is the animated scene's frame N (`--frame N` sets it for every
scene). With `--methods`, a column per method (the scene's own `render` otherwise, as
`--set render.method=M` would give). At one size each method's column pair is RMSE and
p99 with the frame time of each (one warm frame); at several sizes (comma-separated), a
cell `RMSE / p99` per size and method.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from harness import REPO, check_scenes, frame_count, image_sizes, load, width_height  # noqa: E402


def scene_frame(text: str, frame: int | None) -> tuple[str, int | None]:
    """(name, frame) of a scene argument NAME or NAME@N."""
    name, _, number = text.partition("@")
    if number and not number.isdigit():
        sys.exit(f"errors.py: scenes: expected NAME or NAME@FRAME, got {text!r}")
    return name, int(number) if number else frame


def main() -> None:
    from clrays.runs.bench import DEFAULT_SCENES, error_pixels
    from clrays.runs.references import EXACT, ReferenceCache
    from clrays.session import Renderer

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", help="scene names in scenes/, NAME@FRAME for an animation's frame "
                                                  "(default: the bench's, fine occluders included)")
    parser.add_argument("--all", action="store_true", help="every scene in scenes/, then the scenes named")
    parser.add_argument("--methods", default="", help="comma-separated methods, a column each "
                                                      "(default: the scene's own method)")
    parser.add_argument("--frame", type=int, default=None, help="an animated scene's frame (default: its base frame)")
    parser.add_argument("--size", type=image_sizes, default=image_sizes("1280x720"),
                        help="WxH, or several comma-separated (default 1280x720)")
    parser.add_argument("--pixels", type=frame_count, default=4000)
    parser.add_argument("--cache", default=str(REPO / ".cache" / "references"))
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a scene override, as `clrays render --set` (repeatable)")
    args = parser.parse_args()
    named = args.scenes or ([] if args.all else [Path(path).stem for path in DEFAULT_SCENES])
    every = sorted(path.stem for path in (REPO / "scenes").glob("*.yaml")) if args.all else []
    scenes = [scene_frame(text, args.frame) for text in every + named]
    check_scenes("errors.py", (name for name, _ in scenes))
    methods = [method for method in args.methods.split(",") if method] or [None]
    references = ReferenceCache(Path(args.cache))
    renderer = Renderer(reuse=False)
    settings = ", ".join(args.set) or "default settings"
    one_size = len(args.size) == 1
    print(f"{', '.join(args.size)}, {settings}; error against exact on {args.pixels} pixels, depth edges out\n")
    if one_size and methods == [None]:
        header = ["relative RMSE %", "p99 %"]
    elif one_size:
        header = [f"{m} {column}" for m in methods for column in ("RMSE %", "p99 %", "ms")]
    else:
        header = [f"{size.replace('x', '×')}{' ' + m if m else ''}: RMSE / p99 %" for size in args.size
                  for m in methods]
    print("| scene | " + " | ".join(header) + " |\n|---|" + "---|" * len(header), flush=True)
    for name, frame in scenes:
        cells = []
        for size in args.size:
            width, height = width_height(size)
            pixels = error_pixels(width, height, args.pixels)
            for method in methods:
                chosen = [f"render.method={method}"] if method else []
                scene = load("errors.py", name, width, height, [*chosen, *args.set])
                if frame is not None and scene.animation is not None:
                    scene = scene.animation.scene_at(scene, frame)
                renderer.render(scene)  # kernels built
                start = time.perf_counter()
                image = renderer.render(scene).image
                frame_ms = (time.perf_counter() - start) * 1e3
                error = references.error(scene, EXACT, image, pixels)
                timed = one_size and method is not None
                if not error.pixels:  # every pixel of a tiny image on a depth edge or dark
                    cells.append("— (no pixel left to compare)" + (" | — | —" if timed else " | —" if one_size else ""))
                elif one_size:
                    cells.append(f"{100 * error.rmse:.4f} | {100 * error.p99:.4f}" + (f" | {frame_ms:.0f}" if timed else ""))
                else:
                    cells.append(f"{100 * error.rmse:.3f} / {100 * error.p99:.2f}")
        label = name if frame is None or args.frame is not None else f"{name}, frame {frame}"
        print(f"| {label} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
