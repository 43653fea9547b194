"""One sweep point, rendered in this process or on a dask worker: its image and its
results.csv row (clrays.runs.sweep lists the points, clrays.runs.distributed sends them to
workers; both call `render_point`)."""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from ..exposure import exposure_setting, resolve
from ..image_io import check_finite, write_frame
from ..scene.model import Scene
from ..session import Renderer, RenderResult
from .references import ReferenceCache

#: The sweep folder's cache of reference images (`clrays.runs.references`).
REFERENCES = ".references"
#: The error columns of results.csv, in percent (as the contact sheet shows them): mean
#: and 99th percentile of the relative luminance error, relative RMSE (`ImageError`).
ERROR_COLUMNS = ("error_mean_pct", "error_p99_pct", "error_rmse_pct")
#: Host time a point spent on the reference image and on the depth-edge map that the error
#: leaves out (`ReferenceCache.last_ms`): empty where an earlier point had computed them.
REFERENCE_COLUMNS = ("reference_ms", "edges_ms")


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


def _row(point: SweepPoint, image_name: str, result: RenderResult, digest_hex: str, error, reference,
         warmup_ms: float = 0.0, reference_ms: dict[str, float] | None = None, build_ms: float = 0.0,
         image_digest: str = "") -> dict:
    """A results.csv row. `warmup_ms`: the untimed render before this point's (`_warm_up`);
    `build_ms`: kernel programs built during this point's render, left out of its wall_ms;
    `reference_ms`: the host time of the reference and its depth-edge map, where this
    point computed them (REFERENCE_COLUMNS); `image_digest`: the `file_digest` of the
    image written, which ties the file to the row."""
    row = {"index": str(point.index), "image": image_name, **dict(point.settings), "method": result.method,
           "wall_ms": f"{result.wall_ms - build_ms:.2f}", "device_ms": f"{result.device_ms:.2f}",
           "warmup_ms": f"{warmup_ms:.2f}", "build_ms": f"{build_ms:.2f}",
           "reused": " ".join(s for s, v in result.stage_status.items() if v == "reused"),
           "computed": " ".join(s for s, v in result.stage_status.items() if v == "computed"),
           "scene_digest": digest_hex, "image_digest": image_digest}
    row.update({f"{stage}_ms": f"{ms:.2f}" for stage, ms in result.stage_ms.items()})
    row.update({column: f"{reference_ms[column]:.2f}" for column in REFERENCE_COLUMNS if column in (reference_ms or {})})
    if error is not None:
        row.update({"reference": reference, "error_pixels": str(error.pixels),
                    **{column: f"{100 * value:.6g}" for column, value in
                       zip(ERROR_COLUMNS, (error.mean, error.p99, error.rmse))}})
    return row


def _warm_up(renderer: Renderer, scene: Scene, warmed: set) -> float:
    """Render `scene` once, untimed and keeping nothing, if no earlier point ran its kernels
    (method, traversal, integrand, light types; on a CPU device also at its sizes): opening
    the device, building the programs and the device's first launches are the session's
    cost, not a point's, and would otherwise make the first point look several times
    slower than the rest. PoCL compiles a kernel again for each work-group size it has
    not cached, and on a CPU device work-groups follow the launch sizes, which follow the
    image and the render sizes: a sweep over render.slices paid 0.8 s at its first point of
    1024 slices. Returns the milliseconds spent (0 when nothing was new), as warmup_ms."""
    render = scene.render
    kind = (render.method, render.traversal, render.integrand, tuple(type(light).__name__ for light in scene.lights))
    if render.method == "exact":
        return 0.0
    if renderer.device.is_cpu:
        kind += (scene.image.width, scene.image.height, scene.image.spp, render.slices, render.gamma_samples,
                 render.shadow_map, render.steps)
    if kind in warmed:
        return 0.0
    warmed.add(kind)
    start = time.perf_counter()
    renderer.render(scene, reuse=False)
    return (time.perf_counter() - start) * 1e3


def render_point(renderer: Renderer, references: ReferenceCache | None, against, point: SweepPoint, scene: Scene,
                 folder: Path, name: str, digest_hex: str, exposure: float | str | None,
                 warmed: set) -> dict[str, str]:
    """Render one point (after a warm-up if its kernels are new to this session, `_warm_up`),
    write its image (atomically) and return its results.csv row; in this process or on a
    dask worker (`clrays.runs.distributed`), each with its own `warmed` set. exposure:
    stops, AUTO (the point's own `auto_ev`), or None (its scene's render.exposure)."""
    warmup_ms = _warm_up(renderer, scene, warmed)
    # A program the warm-up's kinds did not cover (a shadow filter, a light texture, a relief)
    # is built during the render: its build is the session's cost, not the point's.
    built_before = _build_ms(renderer)
    result = renderer.render(scene)
    build_ms = _build_ms(renderer) - built_before
    setting = exposure_setting(exposure, scene)
    stops = resolve(setting, result.image) if name.lower().endswith(".png") else 0.0
    image_digest = write_frame(folder / name, check_finite(result.image, point.label), stops)
    error = references.error(scene, against, result.image) if references else None
    return _row(point, name, result, digest_hex, error, against.name if against else None, warmup_ms,
                references.last_ms if references else {}, build_ms, image_digest)


def _build_ms(renderer: Renderer) -> float:
    device = renderer._device  # not `renderer.device`, which would open one for `exact`
    return device.build_ms if device is not None else 0.0
