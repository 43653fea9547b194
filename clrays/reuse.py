"""What a render session keeps between frames: stage results keyed by a digest of
exactly the inputs each stage reads (docs/design.md §7 "Doing only the work a frame needs").

A key is a BLAKE2b digest of numbers, strings, numpy arrays (dtype, shape and bytes)
and dataclasses (field by field), so two frames share a stage result only when every
input the stage reads is bit-identical; the stages are deterministic, so a reused
result is the result the stage would compute again, and reuse never changes an image.
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import replace
from typing import Any, Callable

from .digest import digest
from .scene.model import Render
from .scene.relief_frame import other_rows, relief_digest_parts

#: A stage's outcome in one frame, as `RenderResult.stage_status` reports it.
COMPUTED, REUSED, SKIPPED = "computed", "reused", "skipped"


def scene_digest(scene, *, render: bool = True) -> bytes:
    """Everything about a scene that can change an image (not its source path or its
    animation, which only make other scenes). `render=False` leaves out the render
    settings, for references whose own settings are given separately."""
    # Opacity only where some object is translucent, so an opaque-only scene keeps its digest.
    translucent = (scene.geometry.opacity,) if scene.geometry.translucent else ()
    # What the renderer's kernels know of the triangles besides (clrays.inputs.vertex_rows): not the references'.
    carried = (scene.geometry.outward, scene.geometry.convex_part) if render else ()
    # Exposure encodes the radiance in 8 bits and changes none of it: the files that hold
    # it digest the stops they were written at (frame_manifest.frame_digest, sweep points).
    settings = replace(scene.render, exposure=Render.exposure) if render else None
    return digest(scene.image, scene.camera, scene.lights, scene.medium, scene.background,
                  *geometry_parts(scene.geometry), settings, *translucent, *carried)


def geometry_parts(geometry, triangles_only: bool = False) -> tuple:
    """What fixes a Geometry's triangles, albedo and normals (`triangles_only`: its
    triangles), to digest: the digest of its arrays, a relief's rows by its texels and
    placement instead (clrays.scene.relief_frame), so a frame does not hash its millions of
    triangles. Made once per Geometry (`Geometry.kept`: its arrays do not change): a frame
    whose camera moves over a still mesh hashed it four times before (the bunny's 8 MB, 34
    ms a frame at 320×180 on the 2-core machine)."""
    return (geometry.kept(("digest", triangles_only), lambda: digest(*_geometry_arrays(geometry, triangles_only))),)


def _geometry_arrays(geometry, triangles_only: bool) -> tuple:
    if not geometry.reliefs:
        if triangles_only:
            return (geometry.triangles,)
        return geometry.triangles, geometry.albedo, geometry.normals, geometry.smooth
    albedo = None if triangles_only else geometry.albedo
    parts = [relief_digest_parts(record, geometry.triangles, albedo) for record in geometry.reliefs]
    parts += [(rows.start, geometry.triangles[rows]) if triangles_only else
              (rows.start, geometry.triangles[rows], geometry.albedo[rows], geometry.normals[rows],
               geometry.smooth[rows]) for rows in other_rows(geometry.count, geometry.reliefs)]
    return ("reliefs", geometry.count, tuple(parts))


class StageCache:
    """Least-recently-used results per stage label, a few entries each.

    `capacity` entries per stage and light: a sequence needs one (the previous frame),
    a sweep a few (its inner parameter's values), so the default keeps 3."""

    def __init__(self, capacity: int = 3):
        if capacity < 1:
            raise ValueError(f"cache capacity: expected >= 1, got {capacity}")
        self.capacity = capacity
        self._entries: dict[str, OrderedDict[bytes, Any]] = {}

    def get(self, stage: str, key: bytes) -> tuple[bool, Any]:
        entries = self._entries.get(stage)
        if entries is None or key not in entries:
            return False, None
        entries.move_to_end(key)
        return True, entries[key]

    def put(self, stage: str, key: bytes, value: Any, scale: int = 1) -> None:
        """Keep `value`; `scale` multiplies the capacity (per-light stages pass the light count)."""
        entries = self._entries.setdefault(stage, OrderedDict())
        entries[key] = value
        entries.move_to_end(key)
        while len(entries) > self.capacity * max(scale, 1):
            entries.popitem(last=False)

    def clear(self) -> None:
        self._entries.clear()

    def __len__(self) -> int:
        return sum(len(entries) for entries in self._entries.values())


class StageRecord:
    """Which stages of one frame were computed, reused or skipped, light by light."""

    def __init__(self):
        self._outcomes: dict[str, list[str]] = {}

    def note(self, stage: str, outcome: str) -> None:
        self._outcomes.setdefault(stage, []).append(outcome)

    def status(self) -> dict[str, str]:
        """stage → "computed", "reused", "skipped" or "reused k of n" (per-light stages)."""
        status = {}
        for stage, outcomes in self._outcomes.items():
            ran = [o for o in outcomes if o != SKIPPED]
            if not ran:
                status[stage] = SKIPPED
            elif all(o == REUSED for o in ran):
                status[stage] = REUSED
            elif all(o == COMPUTED for o in ran):
                status[stage] = COMPUTED
            else:
                status[stage] = f"{REUSED} {ran.count(REUSED)} of {len(ran)}"
        return status


#: The most lights a frame may have and still keep its per-light stage results (shadow maps,
#: trees, bound maps) for later frames. Each light's take tens of MB at the default sizes
#: (a 1024² cube's keys alone are 48 MB), so a frame of more lights, which runs them in
#: turn through one light's buffers (clrays.light_turns), keeps none: its memory stays one
#: light's, and each frame recomputes every light's stages.
LIGHTS_KEPT = 2


class Reuse:
    """The reuse decisions of one frame: a cache (or None: compute everything), the record,
    and the light count (per-light stages keep that many times more entries; none beyond
    LIGHTS_KEPT lights)."""

    def __init__(self, cache: StageCache | None, record: StageRecord, lights: int = 1):
        self.cache, self.record, self.lights = cache, record, max(lights, 1)

    def stage(self, stage: str | tuple[str, ...], key: bytes | Callable[[], bytes], compute: Callable[[], Any], *,
              per_light: bool = False) -> Any:
        """The stage's result for `key` (a digest, or a function that makes it, called only
        when a cache is kept): the kept one, or `compute()` (then kept). A tuple of stage
        labels records one outcome for stages kept together (rectify + minmax)."""
        labels = (stage,) if isinstance(stage, str) else stage
        found, value = self._get_or_compute(labels[0], key, compute, per_light)
        for label in labels:
            self.record.note(label, REUSED if found else COMPUTED)
        return value

    def keep(self, name: str, key: bytes | Callable[[], bytes], compute: Callable[[], Any], *,
             per_light: bool = False) -> Any:
        """Like `stage`, for intermediate results that are no stage of their own (not recorded)."""
        return self._get_or_compute(name, key, compute, per_light)[1]

    def _get_or_compute(self, name: str, key: bytes | Callable[[], bytes], compute: Callable[[], Any],
                        per_light: bool) -> tuple[bool, Any]:
        if self.cache is None or (per_light and self.lights > LIGHTS_KEPT):  # nothing kept: no key needed
            return False, compute()  # (digesting a mesh costs milliseconds)
        key = key() if callable(key) else key
        found, value = self.cache.get(name, key)
        if not found:
            value = compute()
            self.cache.put(name, key, value, self.lights if per_light else 1)
        return found, value

    def skip(self, *stages: str) -> None:
        for stage in stages:
            self.record.note(stage, SKIPPED)
