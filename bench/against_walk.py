"""Epipolar sampling against the per-pixel walk it interpolates: per bench scene at one
image size, the camera samples fixed up and line samples computed (as `--stats` counts
them), and how far the default image's luminance is from the walk's (`render.sampling:
pixel`), relative, over every pixel (bench/RESULTS.md, "Fewer fix-ups").

    .venv/bin/python bench/against_walk.py --size 1280x720
    .venv/bin/python bench/against_walk.py demo --size 1280x720 --set render.refine_threshold=0.04

Run it in two trees to compare a change: the walk is the same in both, so its figures say
whether interpolating more pixels moved the image away from it.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from arguments import image_size  # noqa: E402  (bench/, beside this script)
from stage_times import SCENES, check_scenes  # noqa: E402
from clrays.errors import ClraysError  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.session import Renderer  # noqa: E402

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=SCENES, help="scene names in scenes/ (default: the bench four)")
    parser.add_argument("--size", type=image_size, default="1280x720", help="WxH (default 1280x720)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="a scene override, as `clrays render --set` (repeatable)")
    args = parser.parse_args()
    check_scenes("against_walk.py", args.scenes)
    width, height = (int(v) for v in args.size.split("x"))
    settings = f"; {', '.join(args.overrides)}" if args.overrides else ""
    print(f"{width}×{height}{settings}; relative luminance difference from the per-pixel walk\n")
    print("| scene | fixed up | line samples computed | mean | RMS | pixels over 0.5 % | over 2 % |")
    print("|---|---|---|---|---|---|---|")
    renderer = Renderer(reuse=False)
    for name in args.scenes:
        overrides = [f"image.width={width}", f"image.height={height}", *args.overrides]
        try:
            sampled, walked = (load_scene(REPO / "scenes" / f"{name}.yaml", overrides=overrides + extra)
                               for extra in ([], ["render.sampling=pixel"]))
        except ClraysError as exc:  # a bad --set: one line, no traceback
            sys.exit(f"against_walk.py: {exc}")
        result = renderer.render(sampled)
        counts = result.samples
        image = result.image.astype(np.float64) @ LUMINANCE
        reference = renderer.render(walked).image.astype(np.float64) @ LUMINANCE
        relative = np.abs(image - reference) / np.maximum(reference, 1e-3)
        print(f"| {name} | {counts.fixed_up} | {counts.computed} | {relative.mean():.3e} | "
              f"{np.sqrt(np.mean(relative ** 2)):.3e} | {int((relative > 0.005).sum())} | "
              f"{int((relative > 0.02).sum())} |", flush=True)


if __name__ == "__main__":
    main()
