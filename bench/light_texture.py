"""Textured lights (docs/light-textures.md): minmax's error against exact by SVD rank and
integrand mode, and the frame time of the textured light against the same light without
its texture; prints markdown tables (bench/RESULTS.md history, "Textured lights").

    .venv/bin/python bench/light_texture.py --size 160x90 --error     # error by rank (exact: ~1 min a scene)
    .venv/bin/python bench/light_texture.py --size 640x360 --frames 5  # time cost

Times are stage times (device time of every stage plus the host-timed ones, as
`clrays render --stats` totals them) of frames from scratch (no reuse), median over
`--frames` after a warm-up frame, the textured and untextured frames interleaved so that
load on the machine hits both alike. Errors are `metrics.image_error` (depth edges
excluded), relative RMSE in %.
"""
from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from clrays.reference.metrics import depth_edges, depth_map, image_error  # noqa: E402
from clrays.scene.load import load_scene  # noqa: E402
from clrays.session import Renderer  # noqa: E402

SCENES = ("gobo", "stained_glass")


def _untextured(scene):
    light = dataclasses.replace(scene.lights[0], texture=None)
    return dataclasses.replace(scene, lights=(light,))


def _stage_ms(result) -> float:
    return sum(result.stage_ms.values())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=SCENES)
    parser.add_argument("--size", default="160x90", help="WxH (default 160x90)")
    parser.add_argument("--frames", type=int, default=5, help="timed frames after the warm-up (default 5)")
    parser.add_argument("--error", action="store_true", help="the error table against exact instead of times")
    parser.add_argument("--set", action="append", default=[], help="more scene overrides, key=value")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    renderer = Renderer()
    for name in args.scenes:
        scene = load_scene(REPO / "scenes" / f"{name}.yaml", [f"image.width={width}", f"image.height={height}",
                                                              *args.set])
        if args.error:
            _errors(renderer, name, scene)
        else:
            _times(renderer, name, scene, args.frames)


def _errors(renderer, name, scene) -> None:
    edges = depth_edges(depth_map(scene))
    exact = renderer.render(scene, "exact").image
    exact_plain = renderer.render(_untextured(scene), "exact").image
    plain = renderer.render(_untextured(scene), "minmax", reuse=False).image
    print(f"\n{name} at {scene.image.width}×{scene.image.height}, relative RMSE against exact (%)\n")
    print("| integrand | rank | textured | untextured |\n|---|---:|---:|---:|")
    for mode in ("table", "svd"):
        for rank in (1, 2, 4, 8):
            sized = dataclasses.replace(scene, render=dataclasses.replace(scene.render, integrand=mode, svd_rank=rank))
            textured = renderer.render(sized, "minmax", reuse=False).image
            untextured = renderer.render(_untextured(sized), "minmax", reuse=False).image
            print(f"| {mode} | {rank} | {100 * image_error(textured, exact, edges).rmse:.3f} "
                  f"| {100 * image_error(untextured, exact_plain, edges).rmse:.3f} |")
    raymarch = renderer.render(dataclasses.replace(scene, render=dataclasses.replace(scene.render, steps=2048)),
                               "raymarch", reuse=False).image
    print(f"\nraymarch (2048 steps): {100 * image_error(raymarch, exact, edges).rmse:.3f} %; "
          f"untextured minmax against untextured exact: {100 * image_error(plain, exact_plain, edges).rmse:.3f} %")


def _times(renderer, name, scene, frames: int) -> None:
    plain = _untextured(scene)
    renderer.render(scene, "minmax", reuse=False)  # warm-up: kernel builds
    renderer.render(plain, "minmax", reuse=False)
    textured_ms, plain_ms, texture_stage = [], [], []
    for _ in range(frames):
        result = renderer.render(scene, "minmax", reuse=False)
        textured_ms.append(_stage_ms(result))
        texture_stage.append(result.stage_ms.get("light_texture", 0.0))
        traverse = result.stage_ms.get("traverse", 0.0)
        plain_result = renderer.render(plain, "minmax", reuse=False)
        plain_ms.append(_stage_ms(plain_result))
    t, p = statistics.median(textured_ms), statistics.median(plain_ms)
    print(f"| {name} | {scene.image.width}×{scene.image.height} | {result.render.slices} × "
          f"{result.render.gamma_samples} | {p:.0f} | {t:.0f} | {t / p:.2f}× | "
          f"{statistics.median(texture_stage):.0f} | {traverse:.0f} / {plain_result.stage_ms.get('traverse', 0):.0f} |")


if __name__ == "__main__":
    main()
