"""The gathered list (the default) and MBOIT against depth peeling at 1, 2, 4 and 8 layers on scenes/glass_row.yaml (five
overlapping coloured panes in fog), timed in the same run (bench/RESULTS.md history, "Translucent
objects"):

    .venv/bin/python bench/transparency.py --methods minmax raymarch --repeats 5

For each method: frames of every configuration interleaved (one warm-up each, then
`--repeats` each, every stage computed), the median wall time, the device time of the
frame and of the transparency stage (layers and composite; `transparency.fog`, the
in-scattering up to each layer, or MBOIT's one weighted walk, apart; and the median of
their sum per frame), and the error against 8-layer peeling: relative
RMSE of luminance (`metrics.image_error`) and of RGB (every channel of every pixel, over
the mean). `--images` writes each image and a heat map against 8-layer peeling
(`compare.heat_map`: red brighter, blue darker). `--sweep` adds MBOIT's warp × moment_bias.
`--per-film` adds MBOIT with the fog run up to each film, as peeling's (before the weighted walk);
`--pieces 1 2 4` adds MBOIT with its walk in that many pieces (`transparency_walk.WALK_PIECES`).
"""
from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from clrays.reference import metrics  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
import clrays.session  # noqa: E402
from clrays.session import Renderer  # noqa: E402
from clrays.stages import transparency_walk  # noqa: E402
from clrays.stages.transparency import translucent_films  # noqa: E402

PEELING = (1, 2, 4, 8)
REFERENCE = "peel 8"


PER_FILM = "moments per film"  # MBOIT's composite with the fog run up to each film (weighted_walk=False)


def configurations(sweep: bool, per_film: bool = False, pieces: tuple[int, ...] = ()) -> dict[str, str]:
    """label → render.transparency override."""
    runs = {f"peel {k}": f"{{type: depth_peeling, layers: {k}}}" for k in PEELING}
    runs["gathered"] = "{type: gathered}"  # the default: every film, the exact product in front of each
    runs["moments"] = "{type: mboit}"  # MBOIT's defaults: log warp, the measured moment_bias
    if per_film:
        runs[PER_FILM] = "{type: mboit}"
    for count in pieces:
        runs[f"moments {count} pieces"] = "{type: mboit}"
    if sweep:
        for warp in ("none", "log"):
            for bias in (0.0, 5e-5, 5e-4, 5e-3, 2e-2, 5e-2):
                runs[f"moments {warp} {bias:g}"] = f"{{type: mboit, warp: {warp}, moment_bias: {bias}}}"
    return runs


def rgb_rmse(image: np.ndarray, reference: np.ndarray) -> float:
    return float(np.sqrt(np.mean((image.astype(np.float64) - reference) ** 2)) / reference.mean())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="glass_row")
    parser.add_argument("--methods", nargs="*", default=["minmax", "raymarch"])
    parser.add_argument("--size", help="WxH (default: the scene's)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--sweep", action="store_true", help="also MBOIT's warp × moment_bias (no images)")
    parser.add_argument("--per-film", action="store_true", help="also MBOIT with the fog up to each film")
    parser.add_argument("--pieces", type=int, nargs="*", default=[], help="also MBOIT's walk in these many pieces")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="a scene override, as clrays render --set (repeatable)")
    parser.add_argument("--images", type=Path, default=REPO / "out" / "transparency",
                        help="folder of the images and heat maps; '' writes none")
    args = parser.parse_args()
    overrides = list(args.overrides)
    if args.size:
        width, height = args.size.split("x")
        overrides += [f"image.width={width}", f"image.height={height}"]
    runs = configurations(args.sweep, args.per_film, tuple(args.pieces))
    scene_path = REPO / "scenes" / f"{args.scene}.yaml"
    scenes = {label: load_scene(scene_path, overrides=overrides + [f"render.transparency={value}"])
              for label, value in runs.items()}
    image = next(iter(scenes.values())).image
    print(f"{args.scene} {' '.join(args.overrides)}, {image.width}×{image.height}; times: median of {args.repeats} "
          f"frames, interleaved; "
          f"errors against {REFERENCE}, relative RMSE %\n")
    print("| method | transparency | wall ms | device ms | transparency ms | transparency.fog ms | stage ms "
          "| RMSE luminance % | RMSE RGB % |")
    print("|---|---|---|---|---|---|---|---|---|")
    renderer = Renderer(reuse=False)
    pieces = transparency_walk.WALK_PIECES

    def per_film(*arguments, **settings):  # the fog run up to each film, not in MBOIT's one walk
        return translucent_films(*arguments, **settings, weighted_walk=False)

    def render(label, scene, method):
        clrays.session.translucent_films = per_film if label == PER_FILM else translucent_films
        transparency_walk.WALK_PIECES = int(label.split()[1]) if label.endswith(" pieces") else pieces
        return renderer.render(scene, method)

    for method in args.methods:
        results = {label: [] for label in runs}
        images = {}
        for label, scene in scenes.items():  # warm-up: kernel builds
            images[label] = render(label, scene, method).image
        for _ in range(args.repeats):
            for label, scene in scenes.items():
                results[label].append(render(label, scene, method))
        reference = images[REFERENCE]
        for label in runs:
            frames = results[label]
            median = lambda values: statistics.median(values)  # noqa: E731
            wall = median([r.wall_ms for r in frames])
            device = median([r.device_ms for r in frames])
            layers = median([r.stage_ms.get("transparency", 0.0) for r in frames])
            fog = median([r.stage_ms.get("transparency.fog", 0.0) for r in frames])
            stage = median([r.stage_ms.get("transparency", 0.0) + r.stage_ms.get("transparency.fog", 0.0)
                            for r in frames])
            error = metrics.image_error(images[label], reference)
            print(f"| {method} | {label} | {wall:.0f} | {device:.0f} | {layers:.1f} | {fog:.1f} | {stage:.1f} "
                  f"| {100 * error.rmse:.3f} | {100 * rgb_rmse(images[label], reference):.3f} |")
        if str(args.images) not in ("", ".") and not args.sweep:
            write_images(args.images, method, images, reference)


def write_images(folder: Path, method: str, images: dict, reference: np.ndarray) -> None:
    from PIL import Image

    from clrays.image_io import make_folder, write_image
    from clrays.runs.compare import heat_map

    make_folder(folder)
    for label, image in images.items():
        name = label.replace(" ", "")
        write_image(folder / f"{method}_{name}.png", image)
        if label != REFERENCE:
            Image.fromarray(heat_map(image, reference)).save(folder / f"{method}_{name}_diff.png")


if __name__ == "__main__":
    main()
