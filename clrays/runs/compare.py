"""`clrays compare`: the shadow filters of one scene against a reference, as the moment
study measures them (docs/design.md §9): per filter its image, a heat map of its
difference from the reference, and a table of RMSE, p99, light-leak pixels and time.

The reference is PCF with the same radius (`shadow_filter: {type: pcf}`): the moment
filters blur the same (2r + 1)² footprint, so the difference is their reconstruction's
alone. With `exact_pixels`, each image is also measured against the `exact` method on a
fixed subset of pixels (as `clrays bench` measures), at the scene's samples per pixel.
"""
from __future__ import annotations

import csv
import statistics
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..image_io import make_folder, write_atomic, write_image
from ..reference import metrics
from ..scene.model import SHADOW_FILTERS, Scene, ShadowFilter
from ..session import Renderer

#: A pixel leaks light where it is brighter than the reference by more than this fraction
#: of the reference's luminance plus LEAK_FLOOR of the image's mean (so that noise in the
#: dark does not count).
LEAK_RELATIVE = 0.05
LEAK_FLOOR = 0.01
#: The heat maps' full scale: a signed luminance difference of this fraction of the
#: reference's mean luminance is full red (brighter: leaks) or full blue (darker).
HEAT_SCALE = 0.25


@dataclass
class Comparison:
    """One filter's row of the table."""

    filter: str
    rmse: float  # relative RMSE of luminance against the reference (fraction of its mean)
    p99: float  # 99th percentile of the relative luminance error
    leak_pixels: int  # pixels brighter than the reference (LEAK_RELATIVE, LEAK_FLOOR)
    filter_ms: float  # median device time of the shadow_filter stage
    frame_ms: float  # median wall time of the frame
    exact_rmse: float | None = None  # relative RMSE against `exact` on the pixel subset


def with_filter(scene: Scene, kind: str, radius: int) -> Scene:
    """The scene with `shadow_filter: {type: kind, radius}` (the scene's biases kept)."""
    chosen = replace(scene.render.shadow_filter or ShadowFilter(), type=kind, radius=radius)
    return replace(scene, render=replace(scene.render, surface_shadows="filtered", pcf=0, shadow_filter=chosen))


def leak_mask(image: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Pixels that `image` shows brighter than `reference` (light leaks)."""
    lum, ref = metrics.luminance(image), metrics.luminance(reference)
    return lum > ref * (1 + LEAK_RELATIVE) + LEAK_FLOOR * ref.mean()


def heat_map(image: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """uint8 RGB: red where `image` is brighter than `reference`, blue where darker, black
    where equal, full scale at HEAT_SCALE × the reference's mean luminance."""
    ref = metrics.luminance(reference)
    signed = (metrics.luminance(image) - ref) / max(float(ref.mean()), 1e-30) / HEAT_SCALE
    heat = np.zeros(image.shape[:2] + (3,))
    heat[..., 0] = np.clip(signed, 0, 1)
    heat[..., 2] = np.clip(-signed, 0, 1)
    return np.round(255 * np.sqrt(heat)).astype(np.uint8)  # sqrt: small differences stay visible


def _write_png(path: Path, pixels: np.ndarray) -> None:
    from PIL import Image

    write_atomic(path, lambda temporary: Image.fromarray(pixels).save(temporary, format="PNG"))


def _timed(renderer: Renderer, scene: Scene, repeats: int):
    """Warm-up, then `repeats` frames: (last image, median shadow_filter ms, median wall ms)."""
    renderer.render(scene)
    runs = [renderer.render(scene) for _ in range(repeats)]
    return (runs[-1].image, statistics.median(run.stage_ms.get("shadow_filter", 0.0) for run in runs),
            statistics.median(run.wall_ms for run in runs))


def compare(scene: Scene, out: Path, radius: int = 2, filters=SHADOW_FILTERS, repeats: int = 3,
            exact_pixels: int = 0, renderer: Renderer | None = None, log=lambda line: None,
            exposure: float = 0.0) -> list[Comparison]:
    """Render `scene` with each shadow filter at `radius` and the PCF reference, write
    OUT/<filter>.png, OUT/<filter>_diff.png, OUT/compare.csv and OUT/compare.md; return
    the rows. Frames are timed without reuse (every stage computed), median of `repeats`."""
    out = make_folder(out)
    renderer = renderer or Renderer(reuse=False)
    reference, _, _ = _timed(renderer, with_filter(scene, "pcf", radius), 1)
    write_image(out / "reference_pcf.png", reference, exposure)
    subset = None
    if exact_pixels:
        from ..reference.exact import exact_pixels as exact_at
        from .bench import error_pixels

        ys, xs = error_pixels(scene.image.width, scene.image.height, exact_pixels)
        start = time.perf_counter()
        subset = (ys, xs, exact_at(scene, ys, xs)[:, None, :], metrics.depth_edges_at(scene, ys, xs)[:, None])
        log(f"exact on {len(ys)} pixels: {time.perf_counter() - start:.0f} s")
    rows = []
    for kind in filters:
        image, filter_ms, frame_ms = _timed(renderer, with_filter(scene, kind, radius), repeats)
        error = metrics.image_error(image, reference)
        row = Comparison(kind, error.rmse, error.p99, int(leak_mask(image, reference).sum()), filter_ms, frame_ms)
        if subset is not None:
            ys, xs, exact, edges = subset
            row.exact_rmse = metrics.image_error(image[ys, xs][:, None, :], exact, edges).rmse
        write_image(out / f"{kind}.png", image, exposure)
        _write_png(out / f"{kind}_diff.png", heat_map(image, reference))
        rows.append(row)
        log(f"{kind}: RMSE {100 * row.rmse:.3f} %, {row.leak_pixels} leak px, {row.filter_ms:.1f} ms")
    _write_tables(rows, out, scene, radius)
    return rows


def markdown_table(rows: list[Comparison]) -> str:
    exact = any(row.exact_rmse is not None for row in rows)
    head = "| filter | RMSE vs PCF % | p99 vs PCF % | leak px | shadow_filter ms | frame ms |"
    rule = "|---|---|---|---|---|---|"
    if exact:
        head, rule = head + " RMSE vs exact % |", rule + "---|"
    lines = [head, rule]
    for row in rows:
        line = (f"| {row.filter} | {100 * row.rmse:.3f} | {100 * row.p99:.2f} | {row.leak_pixels} "
                f"| {row.filter_ms:.1f} | {row.frame_ms:.0f} |")
        if exact:
            line += f" {100 * row.exact_rmse:.3f} |"
        lines.append(line)
    return "\n".join(lines) + "\n"


def _write_tables(rows: list[Comparison], out: Path, scene: Scene, radius: int) -> None:
    fields = list(Comparison.__dataclass_fields__)

    def write_csv(temporary: str) -> None:
        with open(temporary, "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(fields)
            for row in rows:
                writer.writerow([getattr(row, name) for name in fields])

    write_atomic(out / "compare.csv", write_csv)
    title = (f"{scene.source or 'scene'}, {scene.image.width}×{scene.image.height}, radius {radius}; reference: "
             f"PCF radius {radius} (reference_pcf.png); leak px: brighter than it by > {LEAK_RELATIVE:.0%} "
             f"+ {LEAK_FLOOR:.0%} of its mean\n\n")
    text = title + markdown_table(rows)
    write_atomic(out / "compare.md", lambda temporary: Path(temporary).write_text(text, encoding="utf-8"))
