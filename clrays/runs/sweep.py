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
results that a point shares with recent ones (docs/design.md §7); `run_sweep` renders
the points that share them one after another (`execution_order`), while the results
keep the order of the product as given.
"""
from __future__ import annotations

import contextlib
import csv
import io
import os
import itertools
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping, Sequence

import yaml

from ..errors import ClraysError, OutputError
from ..exposure import AUTO, auto_ev, exposure_setting
from ..image_io import file_digest, folder_lock, make_folder, read_linear, read_srgb8, write_atomic
from ..outputs import cache_root, check_replaceable
from ..inputs import frame_inputs
from ..session import STAGE_ORDER, Renderer, StageKeys
from ..reuse import digest, scene_digest
from ..scene.model import Scene
from ..scene.files import FileRefused, read_regular_file
from ..scene.limits import MAX_RUN_RECORD_BYTES, MAX_SWEEP_POINTS
from ..scene.load import load_scene
from .tune import Consent, knobs_for, tuned_scene
from .point import ERROR_COLUMNS, REFERENCE_COLUMNS, REFERENCES, SweepPoint, render_point
from .progress import Progress, counted
from .references import ReferenceCache, parse_reference

RESULTS = "results.csv"
CONTACT_SHEET = "contact_sheet.png"
IMAGE_FORMATS = ("png", "exr", "npy")
#: Stage columns of results.csv, in pipeline order (other labels follow, sorted).
STAGES = STAGE_ORDER


@dataclass(frozen=True)
class Axis:
    """One swept key and its values (YAML text, as after `=` in `--set`)."""

    key: str
    values: tuple[str, ...]


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
    """`--set key=v1,v2,...` arguments → (swept axes, fixed overrides); one value is fixed.
    A key given twice, or a key and one inside it (`medium` and `medium.sigma_s`), is an
    error: the later would silently replace the earlier, and results.csv would label its
    points with values they were not rendered with."""
    axes, fixed = [], []
    for text in settings:
        key, sep, value_text = text.partition("=")
        if not sep or not key.strip():
            raise ClraysError(f"--set {text}: expected key.path=value or key.path=v1,v2,..., got {text!r}")
        values = split_values(value_text)
        if any(not v for v in values):
            raise ClraysError(f"--set {text}: {key.strip()}: expected comma-separated values, got an empty one")
        if len(values) == 1:
            fixed.append(f"{key.strip()}={values[0]}")
        else:
            axes.append(Axis(key.strip(), tuple(values)))
    check_distinct_keys(list(settings))
    return axes, fixed


def _key_parts(setting: str) -> tuple[str, ...]:
    """A `key.path=...` setting's key as parts, list indices as numbers (`lights.00` is `lights.0`)."""
    parts = [part.strip() for part in setting.partition("=")[0].split(".")]
    return tuple(str(int(part)) if part.isdecimal() else part for part in parts)


def check_distinct_keys(settings: Sequence[str]) -> None:
    """Refuse two settings (`key.path=...`) of one key, or of a key and a key inside it."""
    seen: list[tuple[tuple[str, ...], str]] = []
    for text in settings:
        parts = _key_parts(text)
        for other_parts, other in seen:
            if parts[:len(other_parts)] == other_parts or other_parts[:len(parts)] == parts:
                shown = lambda t: t if len(t) <= 60 else t[:57] + "..."  # noqa: E731
                relation = ("sets the same key as" if parts == other_parts else
                            "sets a key inside" if len(parts) > len(other_parts) else "sets the key holding")
                raise ClraysError(f"--set {shown(text)}: {'.'.join(parts)} {relation} --set {shown(other)}; "
                                  f"the later would replace the earlier: give each key once")
        seen.append((parts, text))


def axes_from(spec: Mapping[str, Sequence[Any]] | Sequence[str] | Sequence[Axis],
              overrides: Sequence[str] = ()) -> tuple[list[Axis], list[str]]:
    """Axes from a dict {key: [python values]}, `--set` strings, or Axis objects, and the
    fixed overrides (`overrides` first); every key once (`check_distinct_keys`), and at
    most MAX_SWEEP_POINTS points."""
    if isinstance(spec, Mapping):
        text = lambda v: v if isinstance(v, str) else yaml.safe_dump(v, default_flow_style=True).strip()  # noqa: E731
        spec = [Axis(key, tuple(text(v).removesuffix("\n...").strip() for v in values)) for key, values in spec.items()]
    spec = list(spec)
    if all(isinstance(a, Axis) for a in spec):
        axes, fixed = [a for a in spec if len(a.values) > 1], [f"{a.key}={a.values[0]}" for a in spec
                                                             if len(a.values) == 1]
    else:
        axes, fixed = parse_settings(spec)
    fixed = list(overrides) + fixed
    check_distinct_keys(fixed + [f"{a.key}={','.join(a.values)}" for a in axes])
    check_point_count(axes)
    return axes, fixed


def check_point_count(axes: Sequence[Axis]) -> int:
    """The number of points, refused above MAX_SWEEP_POINTS before anything is built."""
    count = math.prod(len(a.values) for a in axes)
    if count > MAX_SWEEP_POINTS:
        sizes = " × ".join(str(len(a.values)) for a in axes)
        raise ClraysError(f"--set: {sizes} = {count} points, more than the limit of {MAX_SWEEP_POINTS}; "
                          f"sweep fewer values (docs/limits.md)")
    return count


def sweep_points(axes: Sequence[Axis]) -> list[SweepPoint]:
    """The cartesian product, first axis slowest."""
    return [SweepPoint(i, tuple(zip((a.key for a in axes), combo)))
            for i, combo in enumerate(itertools.product(*(a.values for a in axes)))]


def stage_keys(scene: Scene) -> tuple[bytes, bytes, bytes]:
    """The session's keys (`clrays.session.StageKeys`) of a scene's shadow maps, camera
    raster and min-max trees: points that share one share that stage's result."""
    keys = StageKeys(frame_inputs(scene))
    trees = digest(*(keys.trees(index) for index in range(len(scene.lights))))
    return digest(*keys.shadow), keys.camera, trees


def execution_order(points: Sequence[SweepPoint], scenes: Iterable[Scene]) -> list[SweepPoint]:
    """`points` (`scenes`: theirs, in the same order) reordered so that those sharing
    shadow maps, then the camera raster, then the min-max trees run one after another,
    while the session still keeps them; ties keep the order of the product.

    Sharing is decided by the session's own keys (`stage_keys`), not by which keys were
    swept. The integrand's key also holds the β and γ ranges that rectify finds on the
    device, so it is not known before a point renders and plays no part."""
    first_seen: dict[bytes, int] = {}
    rank = {point.index: tuple(first_seen.setdefault(key, len(first_seen)) for key in stage_keys(scene))
            for point, scene in zip(points, scenes)}
    return sorted(points, key=lambda point: rank[point.index])


def axes_execution_order(points: Sequence[SweepPoint], axes: Sequence[Axis],
                         value_keys: Sequence[Sequence[tuple[bytes, bytes, bytes]]]) -> list[SweepPoint]:
    """`execution_order` without loading a scene per point: from `value_keys[a][v]`, the
    `stage_keys` of the scene with axis `a` alone set to its value `v` (`check_values`).
    An axis changes a stage's key the same way whatever the other axes' values, so a point
    shares a stage with another when each axis's value gives the same key for it."""
    classes = []  # per axis, per value: the first value of that axis giving the same key, per stage
    for keys in value_keys:
        first: list[dict[bytes, int]] = [{}, {}, {}]
        classes.append([tuple(first[stage].setdefault(key, len(first[stage])) for stage, key in enumerate(value))
                        for value in keys])
    sizes = [len(axis.values) for axis in axes]

    def rank(point: SweepPoint):
        values, index = [], point.index  # the point's value of each axis, first axis slowest
        for size in reversed(sizes):
            index, value = divmod(index, size)
            values.append(value)
        values.reverse()
        return tuple(tuple(classes[a][v][stage] for a, v in enumerate(values)) for stage in range(3)), point.index

    return sorted(points, key=rank)


def check_values(path: str | Path, axes: Sequence[Axis],
                 fixed: Sequence[str] = ()) -> list[list[tuple[bytes, bytes, bytes]]]:
    """Load the scene once per swept value, so a bad value fails before any rendering;
    returns the `stage_keys` of each (per axis, per value) for `axes_execution_order`."""
    load_scene(path, list(fixed))
    return [[stage_keys(load_scene(path, list(fixed) + [f"{axis.key}={value}"])) for value in axis.values]
            for axis in axes]


def sweep_scenes(path: str | Path, spec, overrides: Sequence[str] = ()) -> Iterator[tuple[SweepPoint, Scene]]:
    """(point, scene) for every point of the product, in the order of the product; each
    scene is loaded when its turn comes.

    spec: {key: [values]} (Python values), `--set`-style "key=v1,v2" strings, or Axis
    objects. overrides: `key=value` applied to every point first."""
    axes, fixed = axes_from(spec, overrides)
    check_values(path, axes, fixed)
    for point in sweep_points(axes):
        yield point, load_scene(path, fixed + point.overrides)


# --------------------------------------------------------------------------- the sweep


@dataclass
class SweepReport:
    folder: Path
    rows: list[dict[str, str]]  # results.csv, in point order
    rendered: list[int] = field(default_factory=list)  # points rendered by this run
    kept: list[int] = field(default_factory=list)  # points kept from an earlier run
    wall_s: float = 0.0
    notes: list[str] = field(default_factory=list)  # what the run left out, e.g. the contact sheet

    def summary(self) -> str:
        return (f"{counted(len(self.rendered), 'point')} rendered, {len(self.kept)} kept from an earlier run "
                f"(of {len(self.rows)}) in {self.wall_s:.1f} s; {self.folder / RESULTS}"
                + "".join(f"; {note}" for note in self.notes))


def _image_name(point: SweepPoint, count: int, fmt: str) -> str:
    return f"{point.index:0{max(3, len(str(count - 1)))}d}.{fmt}"


def _read_rows(path: Path) -> dict[int, dict[str, str]]:
    """The rows of an earlier run's results.csv: none when it is missing or not a CSV;
    a link, a FIFO, a device or a file over MAX_RUN_RECORD_BYTES is one line (`read_regular_file`)."""
    try:
        text = read_regular_file(path, MAX_RUN_RECORD_BYTES, follow_links=False).decode("utf-8", "replace")
    except FileRefused as exc:
        if not os.path.lexists(path):
            return {}
        raise OutputError(f"{path}: cannot read the results of an earlier run: {exc}; remove it (its points "
                          f"are rendered again)") from None
    try:
        return {int(row["index"]): row for row in csv.DictReader(io.StringIO(text, newline=""))
                if (row.get("index") or "").isdecimal() and len(row["index"]) < 10}
    except (csv.Error, KeyError, ValueError):
        return {}


def _write_rows(path: Path, rows: list[dict[str, str]], axes: Sequence[Axis]) -> None:
    stages = [s for s in STAGES if any(f"{s}_ms" in r for r in rows)]
    extra = sorted({k[:-3] for r in rows for k in r if k.endswith("_ms") and k[:-3] not in STAGES
                    and k not in ("wall_ms", "device_ms", "warmup_ms", "build_ms", *REFERENCE_COLUMNS)})
    columns = (["index", "image"] + [a.key for a in axes] + ["method", "wall_ms", "device_ms"]
               + [f"{s}_ms" for s in stages + extra] + ["reused", "computed", "warmup_ms", "build_ms"])
    if any(r.get("reference") for r in rows):
        columns += ["reference", *ERROR_COLUMNS, "error_pixels", *REFERENCE_COLUMNS]
    columns += ["scene_digest", "image_digest"]

    def write(temporary: str) -> None:
        with open(temporary, "w", newline="", encoding="utf-8") as f:
            writer = csv.DictWriter(f, columns, extrasaction="ignore", restval="")
            writer.writeheader()
            writer.writerows(rows)

    write_atomic(path, write)


def run_sweep(path: str | Path, spec, out_dir: str | Path, *, overrides: Sequence[str] = (),
              method: str | None = None, reference: str | None = None, renderer: Renderer | None = None,
              exposure: float | str | None = None, image_format: str = "png", contact_sheet: bool = True,
              overwrite: bool = False, progress: bool = False,
              on_point: Callable[[SweepPoint, dict], None] | None = None, executor=None,
              tune: Consent | None = None, how_to_tune: str = "") -> SweepReport:
    """Render every point of the sweep into `out_dir` (created): one image per point,
    results.csv and contact_sheet.png. `spec` as for `sweep_scenes`; `reference`:
    "exact" or "raymarch:N" adds error columns in percent
    (`clrays.reference.metrics.image_error`, depth edges excluded; the reference images
    are kept in `out_dir`/.references). Points whose image and results row exist from an
    earlier run of the same scene and settings are kept unless `overwrite`.
    on_point(point, row) after each. executor: a `clrays.runs.distributed.DaskExecutor`
    to render the points on its workers (`renderer` then only gives the reuse setting);
    results.csv is still written here, by the client alone. exposure: stops for .png points and
    the contact sheet, AUTO (each point its own), or None (each point's render.exposure). tune:
    whether a point's render.target_error may be searched where no tuning is kept, in what
    time for all points (`clrays.runs.tune.Consent`; default: not); how_to_tune: the
    refusal's way to run it anyway."""
    if image_format not in IMAGE_FORMATS:
        raise ClraysError(f"image format: expected one of {', '.join(IMAGE_FORMATS)}, got {image_format!r}")
    axes, fixed = axes_from(spec, overrides)
    against = parse_reference(reference)
    value_keys = check_values(path, axes, fixed)
    folder = make_folder(out_dir, "the sweep folder")
    check_replaceable(folder / CONTACT_SHEET)  # a link there is one line now, not after every point

    renderer = renderer or Renderer()
    swept_render_keys = {axis.key.removeprefix("render.") for axis in axes if axis.key.startswith("render.")}

    def point_scene(point: SweepPoint) -> Scene:
        scene = load_scene(path, fixed + point.overrides)
        scene = scene if method is None else replace(scene, render=replace(scene.render, method=method))
        if scene.render.target_error is not None:
            # A swept setting that the target would tune: the tuned value would replace it in every point.
            tuned_keys = {knob.key for knob in knobs_for(scene.render.method, scene.render.sampling)}
            if swept_render_keys & tuned_keys:
                raise ClraysError(f"{path}: render.{sorted(swept_render_keys & tuned_keys)[0]} is swept, and "
                                  f"render.target_error tunes it: sweep it without a target, or sweep the target")
        # render.target_error: the point's tuned settings (searched once per scene, then read from the cache).
        return tuned_scene(scene, folders=[folder / REFERENCES, cache_root()], consent=tune, renderer=renderer,
                           progress=progress, how_to_tune=how_to_tune, below=folder)[0]

    references = ReferenceCache(folder / REFERENCES, renderer, progress, below=folder) if against else None
    points = sweep_points(axes)
    report = SweepReport(folder, [])
    start = time.perf_counter()
    with folder_lock(folder):
        try:
            _run_points(points, axes, value_keys, point_scene, folder, renderer, references, against, exposure,
                        image_format, overwrite, progress, on_point, executor, report)
            if contact_sheet and len(report.rows) <= MAX_CONTACT_SHEET_POINTS:
                write_contact_sheet(folder / CONTACT_SHEET, folder, report.rows, axes, exposure)
            elif contact_sheet:
                report.notes.append(f"no {CONTACT_SHEET}: {len(report.rows)} points, more than the "
                                    f"{MAX_CONTACT_SHEET_POINTS} it shows")
        finally:
            report.wall_s = time.perf_counter() - start
    return report


#: results.csv is rewritten at most this often while points finish (and at the end, or
#: when the run stops): rewriting it whole after every point would make a long sweep's
#: time grow with the square of its points.
RESULTS_EVERY_S = 1.0
#: A contact sheet shows at most this many points (about 150 MB of pixels at 240 wide);
#: a larger sweep writes none and says so.
MAX_CONTACT_SHEET_POINTS = 1024


def _run_points(points, axes, value_keys, point_scene, folder: Path, renderer, references, against, exposure,
                image_format, overwrite, progress, on_point, executor, report: SweepReport) -> None:
    """Every point, in `axes_execution_order`, each scene loaded when its turn comes: the
    first point renders at once, and memory holds one scene at a time."""
    earlier = {} if overwrite else _read_rows(folder / RESULTS)
    check_replaceable(folder / RESULTS)  # read or not, a link there is one line before any point
    warmed: set = set()
    rows: dict[int, dict[str, str]] = {}
    written = {"at": time.perf_counter(), "pending": False}

    def write_results() -> None:
        # Rows of an earlier run stay until this run reaches their point, so an
        # interrupted resume loses nothing.
        merged = {**{i: row for i, row in earlier.items() if i < len(points)}, **rows}
        _write_rows(folder / RESULTS, [merged[i] for i in sorted(merged)], axes)
        written.update(at=time.perf_counter(), pending=False)

    with Progress(progress, len(points), "point", "sweep") as bar:
        def to_render():
            """(point, image name, scene digest, scene) of the points to render; the others kept."""
            for point in axes_execution_order(points, axes, value_keys):
                scene = point_scene(point)
                # What the point's image depends on (`auto`: its own radiance).
                digest_hex = digest(scene_digest(scene), exposure_setting(exposure, scene)).hex()
                name = _image_name(point, len(points), image_format)
                old = earlier.get(point.index)
                if (old is not None and old.get("scene_digest") == digest_hex and old.get("image") == name
                        and old.get("image_digest") and file_digest(folder / name) == old["image_digest"]
                        and (against is None or (old.get("reference") == against.name
                                                 and old.get(ERROR_COLUMNS[0])))):
                    rows[point.index] = old
                    report.kept.append(point.index)
                    if on_point:
                        on_point(point, old)
                    bar.advance(point.label[:60])
                else:
                    yield point, name, digest_hex, scene

        if executor is None:
            outcomes = ((point, render_point(renderer, references, against, point, scene, folder, name, digest_hex,
                                             exposure, warmed)) for point, name, digest_hex, scene in to_render())
        else:
            from .distributed import render_point_task

            outcomes = ((point, row) for (point, *_), row in executor.run(
                render_point_task, [(point, scene, name, digest_hex) for point, name, digest_hex, scene in to_render()],
                dict(folder=str(folder), exposure=exposure, against=against, reuse=renderer.reuse)))
        try:
            for point, row in outcomes:
                rows[point.index] = row
                report.rendered.append(point.index)
                written["pending"] = True
                if time.perf_counter() - written["at"] >= RESULTS_EVERY_S:
                    write_results()
                if on_point:
                    on_point(point, rows[point.index])
                bar.advance(point.label[:60] + (f", {executor.busy_label()}" if executor and progress else ""))
        except BaseException:
            if written["pending"]:  # the rows of the points done, also when the run is stopped
                with contextlib.suppress(ClraysError):
                    write_results()
            raise
    report.rows = [rows[i] for i in sorted(rows)]
    _write_rows(folder / RESULTS, report.rows, axes)


# --------------------------------------------------------------------------- contact sheet


def _thumbnail(path: Path, exposure: float | str | None, width: int):
    """A point's image, `width` wide at most: a .png as written, a float one at `exposure`
    (None: 0; AUTO: its own `auto_ev`)."""
    from PIL import Image

    if exposure == AUTO and path.suffix.lower() != ".png":
        exposure = auto_ev(read_linear(path))
    image = Image.fromarray(read_srgb8(path, exposure or 0.0), mode="RGB")
    if image.width > width:
        image = image.resize((width, max(1, round(image.height * width / image.width))), Image.Resampling.LANCZOS)
    return image


def _label_lines(row: dict[str, str], axes: Sequence[Axis]) -> list[str]:
    lines = [f"{a.key}={row.get(a.key, '')}" for a in axes] + [f"#{row['index']}  {float(row['wall_ms']):.0f} ms"]
    if row.get("error_mean_pct"):
        lines.append(f"error {float(row['error_mean_pct']):.2f}%, p99 {float(row['error_p99_pct']):.1f}%")
    return lines


def write_contact_sheet(path: Path, folder: Path, rows: list[dict[str, str]], axes: Sequence[Axis],
                        exposure: float | str | None = 0.0, thumb_width: int = 240) -> Path:
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
    error = ["error_mean_pct"] if any(r.get("error_mean_pct") for r in rows) else []
    columns = [a.key for a in axes] + ["wall_ms", "reused"] + error
    buffer = io.StringIO()
    widths = [max(len(c), *(len(r.get(c, "")) for r in rows)) for c in columns]
    buffer.write("  ".join(c.ljust(w) for c, w in zip(columns, widths)).rstrip() + "\n")
    for r in rows:
        buffer.write("  ".join(r.get(c, "").ljust(w) for c, w in zip(columns, widths)).rstrip() + "\n")
    return buffer.getvalue()
