"""Parameter sweeps: the cartesian product of scene overrides, an image per point,
`results.csv` (parameters, times, stage reuse, error against a reference) and a
labelled contact sheet; resumable like sequences.

From Python, a scripted study is a loop over scenes and one render session:

    from clrays import Renderer
    from clrays.runs.sweep import sweep_scenes
    session = Renderer()
    for point, scene in sweep_scenes("scenes/demo.yaml", {"medium.sigma_s": [0.02, 0.05, 0.1],
                                                          "render.slices": [256, 1024]}):
        result = session.render(scene)          # RenderResult: .image, .stage_ms, .reused
        print(point.label, f"{result.wall_ms:.0f} ms", result.reused)

or `run_sweep(...)` for everything `clrays sweep` writes. The session keeps the stage
results that a point shares with earlier ones (DESIGN §7); the points run in an order
that changes early-stage parameters (camera, geometry, lights) least often, while
results keep the order of the product as given.
"""
from __future__ import annotations

import csv
import io
import itertools
import math
import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np
import yaml

from ..errors import ClraysError, OutputError
from ..image_io import to_srgb8, write_atomic, write_image
from ..session import Renderer, RenderResult
from ..reuse import digest, scene_digest
from ..scene.model import Render, Scene
from ..scene.load import MAX_STEPS, load_scene

RESULTS = "results.csv"
CONTACT_SHEET = "contact_sheet.png"
IMAGE_FORMATS = ("png", "exr", "npy")
#: Stage columns of results.csv, in pipeline order (other labels follow, sorted).
STAGES = ("raster", "rectify", "minmax", "integrand", "traverse", "raymarch", "shade")


@dataclass(frozen=True)
class Axis:
    """One swept key and its values (YAML text, as after `=` in `--set`)."""

    key: str
    values: tuple[str, ...]


@dataclass(frozen=True)
class SweepPoint:
    index: int  # position in the product, first axis slowest
    settings: tuple[tuple[str, str], ...]  # (key, value text) per axis

    @property
    def overrides(self) -> list[str]:
        return [f"{key}={value}" for key, value in self.settings]

    @property
    def label(self) -> str:
        return " ".join(self.overrides)


def split_values(text: str) -> list[str]:
    """Split `v1,v2,...` at the commas outside brackets, braces and quotes:
    `[1,2,3],[4,5,6]` is two values."""
    values, depth, quote, current = [], 0, None, []
    for char in text:
        if quote:
            quote = None if char == quote else quote
        elif char in "\"'":
            quote = char
        elif char in "[{":
            depth += 1
        elif char in "]}":
            depth -= 1
        elif char == "," and depth == 0:
            values.append("".join(current).strip())
            current = []
            continue
        current.append(char)
    values.append("".join(current).strip())
    return values


def parse_settings(settings: Sequence[str]) -> tuple[list[Axis], list[str]]:
    """`--set key=v1,v2,...` arguments → (swept axes, fixed overrides); one value is fixed."""
    axes, fixed = [], []
    for text in settings:
        key, sep, value_text = text.partition("=")
        if not sep or not key.strip():
            raise ClraysError(f"--set {text}: expected key.path=value or key.path=v1,v2,..., got {text!r}")
        values = split_values(value_text)
        if any(not v for v in values):
            raise ClraysError(f"--set {text}: {key.strip()}: expected comma-separated values, got an empty one")
        if any(a.key == key.strip() for a in axes):
            raise ClraysError(f"--set {text}: {key.strip()}: expected each key swept once, got it again")
        if len(values) == 1:
            fixed.append(f"{key.strip()}={values[0]}")
        else:
            axes.append(Axis(key.strip(), tuple(values)))
    return axes, fixed


def axes_from(spec: Mapping[str, Sequence[Any]] | Sequence[str] | Sequence[Axis]) -> tuple[list[Axis], list[str]]:
    """Axes from a dict {key: [python values]}, `--set` strings, or Axis objects."""
    if isinstance(spec, Mapping):
        text = lambda v: v if isinstance(v, str) else yaml.safe_dump(v, default_flow_style=True).strip()  # noqa: E731
        spec = [Axis(key, tuple(text(v).removesuffix("\n...").strip() for v in values)) for key, values in spec.items()]
    spec = list(spec)
    if all(isinstance(a, Axis) for a in spec):
        return [a for a in spec if len(a.values) > 1], [f"{a.key}={a.values[0]}" for a in spec if len(a.values) == 1]
    return parse_settings(spec)


def sweep_points(axes: Sequence[Axis]) -> list[SweepPoint]:
    """The cartesian product, first axis slowest."""
    return [SweepPoint(i, tuple(zip((a.key for a in axes), combo)))
            for i, combo in enumerate(itertools.product(*(a.values for a in axes)))]


def stage_rank(key: str) -> int:
    """How early in the pipeline a key is read: 0 raster (camera, geometry, light
    placement, shadow-map size), 1 rectify (texture size), 2 integrand (medium, light
    power, integrand mode), 3 later (shading, method options)."""
    parts = key.split(".")
    if parts[0] in ("image", "camera", "objects", "version"):
        return 0
    if parts[0] == "lights":
        return 2 if parts[-1] in ("intensity", "irradiance") else 0
    if parts[0] == "render":
        field_name = parts[1] if len(parts) > 1 else ""
        return {"shadow_map": 0, "slices": 1, "gamma_samples": 1, "integrand": 2, "svd_rank": 2}.get(field_name, 3)
    if parts[0] == "medium":
        return 2
    return 3


def execution_order(points: Sequence[SweepPoint], axes: Sequence[Axis]) -> list[SweepPoint]:
    """The points reordered so the axes read by early stages change least often."""
    order = sorted(range(len(axes)), key=lambda i: stage_rank(axes[i].key))  # stable: ties keep their order
    position = [{v: j for j, v in enumerate(a.values)} for a in axes]
    return sorted(points, key=lambda p: tuple(position[i][p.settings[i][1]] for i in order))


def check_values(path: str | Path, axes: Sequence[Axis], fixed: Sequence[str] = ()) -> None:
    """Load the scene once per swept value, so a bad value fails before any rendering."""
    load_scene(path, list(fixed))
    for axis in axes:
        for value in axis.values:
            load_scene(path, list(fixed) + [f"{axis.key}={value}"])


def sweep_scenes(path: str | Path, spec, overrides: Sequence[str] = ()) -> Iterator[tuple[SweepPoint, Scene]]:
    """(point, scene) for every point of the product, in the order of the product.

    spec: {key: [values]} (Python values), `--set`-style "key=v1,v2" strings, or Axis
    objects. overrides: `key=value` applied to every point first."""
    axes, fixed = axes_from(spec)
    check_values(path, axes, list(overrides) + fixed)
    for point in sweep_points(axes):
        yield point, load_scene(path, list(overrides) + fixed + point.overrides)


# --------------------------------------------------------------------------- references


def parse_reference(text: str | None) -> tuple[str, int] | None:
    """`exact` or `raymarch:N` (N steps per ray) → (method, steps)."""
    if text is None:
        return None
    method, _, steps = text.strip().partition(":")
    if method == "exact" and not steps:
        return "exact", 0
    if method == "raymarch" and steps.strip().isdigit() and 1 <= int(steps) <= MAX_STEPS:
        return "raymarch", int(steps)
    raise ClraysError(f"--reference {text}: expected exact or raymarch:N (N steps per ray, 1 to {MAX_STEPS}), "
                      f"got {text!r}")


def reference_scene(scene: Scene, reference: tuple[str, int]) -> Scene:
    """The scene as the reference renders it: only the render settings it reads are kept,
    so points that differ in nothing else share one reference image."""
    method, steps = reference
    if method == "exact":
        return replace(scene, render=Render(method="exact"), source=None, animation=None)
    r = scene.render
    return replace(scene, render=Render(method="raymarch", steps=steps, jitter=r.jitter, shadow_map=r.shadow_map,
                                        pcf=r.pcf), source=None, animation=None)


class References:
    """Reference images and depth-edge masks, kept in memory and (images) in the sweep
    folder, so a resumed sweep does not render them again."""

    def __init__(self, reference: tuple[str, int], renderer: Renderer, folder: Path | None):
        self.reference, self.renderer, self.folder = reference, renderer, folder
        self._images: dict[bytes, np.ndarray] = {}
        self._edges: dict[bytes, np.ndarray] = {}

    @property
    def name(self) -> str:
        method, steps = self.reference
        return method if method == "exact" else f"raymarch:{steps}"

    def image(self, scene: Scene) -> np.ndarray:
        ref_scene = reference_scene(scene, self.reference)
        key = scene_digest(ref_scene)
        if key not in self._images:
            path = self.folder / f".reference_{key.hex()[:16]}.npy" if self.folder else None
            if path is not None and path.exists():
                self._images[key] = np.load(path)
            else:
                self._images[key] = self.renderer.render(ref_scene, reuse=False).image
                if path is not None:
                    write_image(path, self._images[key])
        return self._images[key]

    def edges(self, scene: Scene) -> np.ndarray:
        from ..reference.metrics import depth_edges, depth_map

        key = digest(scene.camera, scene.image, scene.geometry.triangles)
        if key not in self._edges:
            self._edges[key] = depth_edges(depth_map(scene))
        return self._edges[key]

    def error(self, scene: Scene, image: np.ndarray):
        from ..reference.metrics import image_error

        return image_error(image, self.image(scene), self.edges(scene))


# --------------------------------------------------------------------------- the sweep


@dataclass
class SweepReport:
    folder: Path
    rows: list[dict[str, str]]  # results.csv, in point order
    rendered: list[int] = field(default_factory=list)  # points rendered by this run
    kept: list[int] = field(default_factory=list)  # points kept from an earlier run
    wall_s: float = 0.0

    def summary(self) -> str:
        return (f"{len(self.rendered)} points rendered, {len(self.kept)} kept from an earlier run "
                f"(of {len(self.rows)}) in {self.wall_s:.1f} s; {self.folder / RESULTS}")


def _image_name(point: SweepPoint, count: int, fmt: str) -> str:
    return f"{point.index:0{max(3, len(str(count - 1)))}d}.{fmt}"


def _read_rows(path: Path) -> dict[int, dict[str, str]]:
    try:
        with open(path, newline="", encoding="utf-8") as f:
            return {int(row["index"]): row for row in csv.DictReader(f) if row.get("index", "").isdigit()}
    except (OSError, csv.Error, KeyError, ValueError):
        return {}


def _write_rows(path: Path, rows: list[dict[str, str]], axes: Sequence[Axis]) -> None:
    stages = [s for s in STAGES if any(f"{s}_ms" in r for r in rows)]
    extra = sorted({k[:-3] for r in rows for k in r if k.endswith("_ms") and k[:-3] not in STAGES
                    and k not in ("wall_ms", "device_ms")})
    columns = (["index", "image"] + [a.key for a in axes] + ["method", "wall_ms", "device_ms"]
               + [f"{s}_ms" for s in stages + extra] + ["reused", "computed"])
    if any(r.get("reference") for r in rows):
        columns += ["reference", "error_mean", "error_p99", "error_rmse", "error_pixels"]
    columns.append("scene_digest")

    def write(temporary: str) -> None:
        with open(temporary, "w", newline="", encoding="utf-8") as f:
            writer = csv.DictWriter(f, columns, extrasaction="ignore", restval="")
            writer.writeheader()
            writer.writerows(rows)

    write_atomic(path, write)


def _row(point: SweepPoint, image_name: str, result: RenderResult, digest_hex: str, error, reference) -> dict:
    row = {"index": str(point.index), "image": image_name, **dict(point.settings), "method": result.method,
           "wall_ms": f"{result.wall_ms:.2f}", "device_ms": f"{sum(result.stage_ms.values()):.2f}",
           "reused": " ".join(s for s, v in result.stage_status.items() if v == "reused"),
           "computed": " ".join(s for s, v in result.stage_status.items() if v == "computed"),
           "scene_digest": digest_hex}
    row.update({f"{stage}_ms": f"{ms:.2f}" for stage, ms in result.stage_ms.items()})
    if error is not None:
        row.update({"reference": reference, "error_mean": f"{error.mean:.6g}", "error_p99": f"{error.p99:.6g}",
                    "error_rmse": f"{error.rmse:.6g}", "error_pixels": str(error.pixels)})
    return row


def run_sweep(path: str | Path, spec, out_dir: str | Path, *, overrides: Sequence[str] = (),
              method: str | None = None, reference: str | None = None, renderer: Renderer | None = None,
              exposure: float = 0.0, image_format: str = "png", contact_sheet: bool = True,
              overwrite: bool = False, progress: bool = False,
              on_point: Callable[[SweepPoint, dict], None] | None = None) -> SweepReport:
    """Render every point of the sweep into `out_dir` (created): one image per point,
    results.csv and contact_sheet.png. `spec` as for `sweep_scenes`; `reference`:
    "exact" or "raymarch:N" adds error columns (`clrays.reference.metrics.image_error`, depth edges
    excluded). Points whose image and results row exist from an earlier run of the same
    scene and settings are kept unless `overwrite`. on_point(point, row) after each."""
    if image_format not in IMAGE_FORMATS:
        raise ClraysError(f"image format: expected one of {', '.join(IMAGE_FORMATS)}, got {image_format!r}")
    axes, fixed = axes_from(spec)
    ref = parse_reference(reference)
    fixed = list(overrides) + fixed
    check_values(path, axes, fixed)
    folder = Path(out_dir)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{folder}: cannot create the sweep folder: {exc.strerror or exc}") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f"{folder}: folder is not writable")

    renderer = renderer or Renderer()
    references = References(ref, renderer, folder) if ref else None
    points = sweep_points(axes)
    earlier = {} if overwrite else _read_rows(folder / RESULTS)
    rows: dict[int, dict[str, str]] = {}
    report = SweepReport(folder, [])
    start = time.perf_counter()
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(points), unit="point", desc="sweep")
    try:
        for point in execution_order(points, axes):
            scene = load_scene(path, fixed + point.overrides)
            if method is not None:
                scene = replace(scene, render=replace(scene.render, method=method))
            digest_hex = digest(scene_digest(scene), exposure).hex()  # what the point's image depends on
            name = _image_name(point, len(points), image_format)
            old = earlier.get(point.index)
            if (old is not None and old.get("scene_digest") == digest_hex and (folder / name).exists()
                    and old.get("image") == name and (references is None or old.get("reference") == references.name)):
                rows[point.index] = old
                report.kept.append(point.index)
            else:
                result = renderer.render(scene)
                if not np.isfinite(result.image).all():
                    raise ClraysError(f"{point.label}: the render produced non-finite values "
                                      f"(a bug: please report the scene)")
                write_image(folder / name, result.image, exposure)
                error = references.error(scene, result.image) if references else None
                rows[point.index] = _row(point, name, result, digest_hex, error,
                                         references.name if references else None)
                report.rendered.append(point.index)
                # Rows of an earlier run stay until this run reaches their point, so an
                # interrupted resume loses nothing.
                merged = {**{i: row for i, row in earlier.items() if i < len(points)}, **rows}
                _write_rows(folder / RESULTS, [merged[i] for i in sorted(merged)], axes)
            if on_point:
                on_point(point, rows[point.index])
            if bar is not None:
                bar.set_postfix_str(point.label[:60], refresh=False)
                bar.update(1)
        report.rows = [rows[i] for i in sorted(rows)]
        _write_rows(folder / RESULTS, report.rows, axes)
        if contact_sheet:
            write_contact_sheet(folder / CONTACT_SHEET, folder, report.rows, axes, exposure)
    finally:
        if bar is not None:
            bar.close()
        report.wall_s = time.perf_counter() - start
    return report


# --------------------------------------------------------------------------- contact sheet


def _thumbnail(path: Path, exposure: float, width: int):
    from PIL import Image

    suffix = path.suffix.lower()
    if suffix == ".png":
        image = Image.open(path).convert("RGB")
    elif suffix == ".npy":
        image = Image.fromarray(to_srgb8(np.load(path), exposure), mode="RGB")
    else:
        import OpenEXR

        with OpenEXR.File(str(path)) as exr:
            image = Image.fromarray(to_srgb8(np.asarray(exr.channels()["RGB"].pixels), exposure), mode="RGB")
    if image.width > width:
        image = image.resize((width, max(1, round(image.height * width / image.width))), Image.Resampling.LANCZOS)
    return image


def _label_lines(row: dict[str, str], axes: Sequence[Axis]) -> list[str]:
    lines = [f"{a.key}={row.get(a.key, '')}" for a in axes] + [f"#{row['index']}  {float(row['wall_ms']):.0f} ms"]
    if row.get("error_mean"):
        lines.append(f"error {float(row['error_mean']):.2%}, p99 {float(row['error_p99']):.1%}")
    return lines


def write_contact_sheet(path: Path, folder: Path, rows: list[dict[str, str]], axes: Sequence[Axis],
                        exposure: float = 0.0, thumb_width: int = 240) -> Path:
    """A grid of the sweep's images, each labelled with its parameters, time and error:
    one row per combination of the other axes, one column per value of the last axis."""
    from PIL import Image, ImageDraw, ImageFont

    if not rows:
        raise OutputError(f"{path}: no images for a contact sheet")
    font = ImageFont.load_default(size=12)
    thumbs = [_thumbnail(folder / row["image"], exposure, thumb_width) for row in rows]
    columns = len(axes[-1].values) if len(axes) > 1 else min(len(rows), 6)
    labels = [_label_lines(row, axes) for row in rows]
    line_height, pad = 15, 6
    measure = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    text_width = max(measure.textlength(line, font=font) for lines in labels for line in lines)
    cell_w = int(max(max(t.width for t in thumbs), text_width)) + 2 * pad
    cell_h = max(t.height for t in thumbs) + line_height * max(len(lines) for lines in labels) + 3 * pad
    grid_rows = math.ceil(len(rows) / columns)
    sheet = Image.new("RGB", (columns * cell_w, grid_rows * cell_h), (24, 24, 24))
    draw = ImageDraw.Draw(sheet)
    for n, (lines, thumb) in enumerate(zip(labels, thumbs)):
        x, y = (n % columns) * cell_w + pad, (n // columns) * cell_h + pad
        sheet.paste(thumb, (x, y))
        for k, line in enumerate(lines):
            draw.text((x, y + thumb.height + 3 + k * line_height), line, fill=(230, 230, 230), font=font)
    write_atomic(path, lambda temporary: sheet.save(temporary, format="PNG"))
    return path


def format_table(rows: list[dict[str, str]], axes: Sequence[Axis]) -> str:
    """results.csv as an aligned text table (for the terminal)."""
    columns = [a.key for a in axes] + ["wall_ms", "reused"] + (["error_mean"] if any(r.get("error_mean") for r in rows)
                                                              else [])
    buffer = io.StringIO()
    widths = [max(len(c), *(len(r.get(c, "")) for r in rows)) for c in columns]
    buffer.write("  ".join(c.ljust(w) for c, w in zip(columns, widths)).rstrip() + "\n")
    for r in rows:
        buffer.write("  ".join(r.get(c, "").ljust(w) for c, w in zip(columns, widths)).rstrip() + "\n")
    return buffer.getvalue()
