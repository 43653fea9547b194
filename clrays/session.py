"""One frame, stage by stage: raster → (raymarch | rectify → minmax → integrand →
traverse) → shade. The `exact` reference runs on the host in float64 instead.

A `Renderer` is a render session: besides the built kernels it keeps the stage
results of recent frames (device buffers, integrand tables) and re-runs a stage only
when what it reads changed (DESIGN §7): the shadow maps while the lights and the
geometry are static, the camera depth while the camera and the geometry are, the
min-max trees while those and the eye–light frame are, the integrand tables while the
medium and the β/γ ranges are; a frame identical to a recent one is not rendered at
all. Keys are digests of the stages' inputs (`clrays.reuse`), so reuse never changes
an image. `RenderResult.stage_status` says what each stage did.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field, replace

import numpy as np

from . import structs
from .device import Device, StageTimer
from .inputs import FrameBuffers, FrameInputs, frame_inputs, light_pass_inputs, upload
from .stages.raster import RasterResult, raster_camera, raster_shadow_maps
from .stages.raymarch import raymarch
from .reuse import COMPUTED, REUSED, Reuse, StageCache, StageRecord, digest, scene_digest
from .scene.model import Scene
from .stages.shade import shade

METHODS = ("raymarch", "exact", "minmax")

#: The rectified texture of a light whose shadow map is empty (nothing casts a shadow)
#: is π everywhere whatever its size, so it is built at this size (the minimum).
UNSHADOWED_SIZE = 16


@dataclass
class RenderResult:
    image: np.ndarray  # (H, W, 3) float32 linear radiance
    method: str
    stage_ms: dict[str, float] = field(default_factory=dict)  # device time per stage
    wall_ms: float = 0.0
    device_bytes: int = 0  # device memory allocated for the frame
    # stage → "computed", "reused", "skipped" or "reused k of n" (per light); raster is
    # "raster.camera" and "raster.shadow"; a frame identical to a kept one is all "reused".
    stage_status: dict[str, str] = field(default_factory=dict)

    @property
    def reused(self) -> list[str]:
        """The stages this frame took from an earlier one."""
        return [stage for stage, status in self.stage_status.items() if status == REUSED]


@dataclass
class _ShadowMap:
    """One light's shadow map, in its own buffer (views anchored at the light)."""

    depth: object  # uint[texels]
    texels: int
    triangles: int  # scene triangles: with none, the map is empty without looking
    empty: bool | None = None  # nothing rasterized: filled in when first asked


class Renderer:
    """Renders scenes on one OpenCL device: a session that keeps built kernels and, with
    `reuse` (default), recent stage results (`cache_entries` per stage and light)."""

    def __init__(self, device: Device | str | None = None, reuse: bool = True, cache_entries: int = 3):
        self._device = device if isinstance(device, Device) else None
        self._device_spec = device if isinstance(device, str) else None
        self.reuse = reuse
        self.cache = StageCache(cache_entries)
        self._skip_unshadowed = True  # tests switch it off to compare against the full path

    @property
    def device(self) -> Device:
        if self._device is None:  # created lazily: `exact` needs no device
            self._device = Device(self._device_spec)
        return self._device

    def clear(self) -> None:
        """Forget every kept stage result (frees their device memory)."""
        self.cache.clear()

    def render(self, scene: Scene, method: str | None = None, progress: bool = False,
               reuse: bool | None = None) -> RenderResult:
        """Render one frame. `method` overrides `scene.render.method`; `reuse` overrides
        the session's `reuse` for this frame (False: compute every stage, keep nothing)."""
        method = method or scene.render.method
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
        scene = replace(scene, render=replace(scene.render, method=method))
        start = time.perf_counter()
        record, timer = StageRecord(), StageTimer()
        use_cache = self.reuse if reuse is None else reuse
        reuse = Reuse(self.cache if use_cache else None, record, max(len(scene.lights), 1))
        if self._device is not None:
            self._device.allocated_bytes = 0
        # A frame identical to a kept one: its image, and every stage counts as reused.
        image, stages = reuse.keep("frame", digest("frame", scene_digest(scene)),
                                   lambda: self._frame(scene, method, reuse, timer, progress))
        status = record.status() or {stage: REUSED for stage in stages}
        device_bytes = self._device.allocated_bytes if self._device is not None else 0
        wall_ms = (time.perf_counter() - start) * 1e3
        return RenderResult(image.copy(), method, timer.milliseconds(), wall_ms, device_bytes, status)

    def _frame(self, scene: Scene, method: str, reuse: Reuse, timer: StageTimer, progress: bool):
        """(image, stage labels) of one frame."""
        if method == "exact":
            from .reference.exact import render_exact

            reuse.record.note("exact", COMPUTED)
            return render_exact(scene, progress=progress).astype(np.float32), ("exact",)

        device = self.device
        buffers = upload(device, frame_inputs(scene))  # the scene in eye space, packed into device structs
        keys = _Keys(buffers.inputs)  # digests of what each stage reads
        camera_depth, tri_id = reuse.stage(  # raster: camera depth + triangle ids
            "raster.camera", keys.camera, lambda: raster_camera(device, buffers, timer))
        maps = [reuse.stage(  # raster: each light's shadow map, anchored at the light
            "raster.shadow", keys.shadow[i], lambda i=i: self._shadow_map(buffers, i, timer), per_light=True)
            for i in range(len(scene.lights))]
        rastered = RasterResult(camera_depth, tri_id, self._shadow_atlas(buffers, maps, keys, reuse))
        scatter = self._in_scatter(method, buffers, rastered, maps, keys, reuse, timer)  # in-scattering per sample
        image = shade(device, buffers, rastered, scatter, timer)  # shade: surfaces, attenuation, + scatter
        reuse.record.note("shade", COMPUTED)
        return image, tuple(reuse.record.status())

    def _shadow_map(self, buffers: FrameBuffers, light_index: int, timer: StageTimer) -> _ShadowMap:
        """Rasterize one light's views from the geometry translated to the light (float64 on
        the host), so the depths do not depend on the eye and a static light's map is kept
        while the camera moves."""
        device = self.device
        inputs = light_pass_inputs(buffers.inputs, light_index)
        light_buffers = replace(buffers, inputs=inputs,
                                views=device.buffer(inputs.views, writable=False),
                                lights=device.buffer(inputs.lights, writable=False),
                                tri_vertices=device.buffer(inputs.tri_vertices, writable=False))
        depth = raster_shadow_maps(device, light_buffers, timer)
        return _ShadowMap(depth, inputs.shadow_texels, inputs.scene.geometry.count)

    def _shadow_atlas(self, buffers: FrameBuffers, maps: list[_ShadowMap], keys: "_Keys", reuse: Reuse):
        """Every light's map back to back, as the views' depth offsets expect."""
        if len(maps) == 1:
            return maps[0].depth
        device = self.device

        def build():
            texels = max(buffers.inputs.shadow_texels, 1)
            atlas = device.buffer(nbytes=4 * texels)
            for (first, _), entry in zip(buffers.inputs.light_views, maps):
                offset = 4 * int(buffers.inputs.views[first]["depth_offset"])
                device.cl.enqueue_copy(device.queue, atlas, entry.depth, byte_count=4 * entry.texels,
                                       dst_offset=offset)
            return atlas

        return reuse.keep("shadow_atlas", digest(tuple(keys.shadow)), build)

    def _map_is_empty(self, entry: _ShadowMap) -> bool:
        """Whether nothing at all was rasterized into a light's map (read back once)."""
        if entry.empty is None:
            entry.empty = entry.triangles == 0 or bool(
                (self.device.read(entry.depth, entry.texels, np.uint32) == structs.DEPTH_EMPTY).all())
        return entry.empty

    def _in_scatter(self, method, buffers, rastered, maps, keys, reuse, timer):
        device, inputs = self.device, buffers.inputs
        if not np.any(inputs.scene.medium.sigma_s > 0):
            # No medium: no volume stages at all, just a zero scatter buffer.
            reuse.skip(*(("raymarch",) if method == "raymarch" else ("rectify", "minmax", "integrand", "traverse")))
            scatter = device.buffer(nbytes=16 * inputs.samples)
            device.fill(scatter, np.float32(0), 16 * inputs.samples)
            return scatter
        if method == "raymarch":
            reuse.record.note("raymarch", COMPUTED)
            return raymarch(device, buffers, rastered, timer)  # raymarch: the brute-force reference
        from .stages.minmax_path import minmax_in_scatter

        scatter = minmax_in_scatter(device, buffers, rastered, timer,
                                    reuse=_MinmaxReuse(self, buffers, maps, keys, reuse))
        reuse.record.note("traverse", COMPUTED)
        return scatter


class _Keys:
    """Digests of exactly what each stage of one frame reads."""

    def __init__(self, inputs: FrameInputs):
        scene = inputs.scene
        self.inputs = inputs
        self.geometry = digest(scene.geometry.triangles)
        # raster.camera: the eye-space triangles (geometry and eye), the camera view, the sample offsets.
        self.camera = digest("camera", self.geometry, inputs.eye_ws, inputs.views[:1], inputs.offsets)
        # raster.shadow: the geometry and the light's views relative to its anchor.
        self.shadow = []
        for index, (first, count) in enumerate(inputs.light_views):
            views = inputs.views[first:first + count].copy()
            views["origin"], views["depth_offset"] = 0.0, 0
            self.shadow.append(digest("shadow", self.geometry, inputs.light_anchor_ws[index], views,
                                      inputs.lights[index]["type"]))

    def trees(self, index: int) -> bytes:
        """rectify + minmax of one light: the camera depth, the light's map, the epipolar
        frame (eye, light, camera, image) and the texture size. Not the medium, the
        light's power or the shading options, which neither stage reads."""
        inputs, scene = self.inputs, self.inputs.scene
        light = scene.lights[index]
        geometry_of_light = {f.name: getattr(light, f.name) for f in dataclasses.fields(light)
                             if f.name not in ("intensity", "irradiance")}
        first, count = inputs.light_views[index]
        return digest("trees", index, self.camera, self.shadow[index], geometry_of_light, inputs.eye_ws,
                      inputs.views[:1], inputs.views[first:first + count], scene.camera, scene.image,
                      scene.render.slices, scene.render.gamma_samples)

    def tables(self, index: int, epipolar) -> bytes:
        """integrand of one light: the medium, the light, the eye–light distance, the β and
        γ ranges of the visible rays, the integrand mode and rank, the camera's far."""
        scene = self.inputs.scene
        return digest("tables", scene.medium, scene.lights[index], scene.render.integrand, scene.render.svd_rank,
                      scene.camera.far, epipolar.params["d_el"], epipolar.beta_min, epipolar.beta_max,
                      epipolar.gamma_max)


class _MinmaxReuse:
    """What `minmax_in_scatter` asks the session for, light by light: the min-max trees
    (rectify → minmax) and the integrand tables, kept ones where the inputs match."""

    def __init__(self, renderer: Renderer, buffers: FrameBuffers, maps: list[_ShadowMap], keys: _Keys, reuse: Reuse):
        self.renderer, self.buffers, self.maps, self.keys, self.reuse = renderer, buffers, maps, keys, reuse

    def trees(self, index: int, build):
        """`build(buffers)` runs rectify and minmax. A light whose map is empty casts no
        shadow anywhere: its texture is π everywhere, the tree walk finds one lit run at
        any texture size, so a minimal texture gives the same radiance (up to float32
        rounding where the run is clipped) without rectifying the full one (DESIGN §7)."""
        key, buffers = self.keys.trees(index), self.buffers
        if self.renderer._skip_unshadowed and self.renderer._map_is_empty(self.maps[index]):
            render = buffers.inputs.scene.render
            small = replace(buffers.inputs.scene, render=replace(render, slices=UNSHADOWED_SIZE,
                                                                   gamma_samples=UNSHADOWED_SIZE))
            epipolar = self.reuse.keep("unshadowed", digest("unshadowed", key),
                                       lambda: build(replace(buffers, inputs=replace(buffers.inputs, scene=small))),
                                       per_light=True)
            self.reuse.skip("rectify", "minmax")
            return epipolar
        return self.reuse.stage(("rectify", "minmax"), key, lambda: build(buffers), per_light=True)

    def tables(self, index: int, epipolar, build):
        """`build()` runs the integrand stage."""
        return self.reuse.stage("integrand", self.keys.tables(index, epipolar), build, per_light=True)


_renderers: dict[str | None, Renderer] = {}


def render(scene: Scene, method: str | None = None, device: str | None = None, stats: bool = False,
           progress: bool = False, reuse: bool = True):
    """Render a scene; returns (H, W, 3) float32 linear radiance, or a RenderResult with
    per-stage device times and stage status when `stats=True`. `method` overrides
    `scene.render.method`; `device` is a device spec as for `--device`. Calls share one
    session per device, so consecutive frames reuse what did not change (`reuse=False`:
    compute every stage)."""
    renderer = _renderers.setdefault(device, Renderer(device))
    result = renderer.render(scene, method, progress=progress, reuse=reuse)
    return result if stats else result.image
