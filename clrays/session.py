"""A render session and the frame it runs, stage by stage (docs/design.md §4):

    raster → translucency → transparency → volume → visibility → shade

    volume, by method:  minmax          per light: rectify → minmax → integrand → light_texture → traverse
                        volume_moments  per light: rectify → integrand → light_texture → volume_moments
                        raymarch        raymarch, every light at once

    lights in turn (several lights, clrays.light_turns): raster.camera, then per light
    raster.shadow → the volume stages → visibility through one light's buffers; then shade

`Renderer._frame` is that figure, one line per stage. A stage with nothing to do in a frame
returns at once: translucency (the light side of translucent objects) and transparency
(their films before the camera) in an opaque scene and the volume without a medium, each
recorded as skipped, and light_texture for an untextured light. `traverse` samples along epipolar
lines (`render.sampling: epipolar`, the default) or walks every camera sample's rows
(`pixel`); `shadow_filter` answers for visibility with `render.surface_shadows: filtered`.
The `exact` reference renders on the host in float64 instead (clrays.reference.exact).

A `Renderer` keeps the built kernels and the stage results of recent frames (device
buffers, integrand tables) and re-runs a stage only when what it reads changed
(docs/design.md §7). `StageKeys` says, beside each stage, what that is: the shadow maps
while the lights and the geometry stand still, the camera depth while the camera and
the geometry do, the min-max trees while those and the eye–light frame do, the
integrand tables while the medium and what decides the β/γ ranges (which stay on the
device) do; a frame identical to a recent one is not rendered at all. Keys are digests of the stages' inputs (clrays.reuse), so
reuse never changes an image. `RenderResult.stage_status` says what each stage did.

Frames in flight: `Renderer.submit` does a frame's host work and enqueues its device work,
and returns before the image is read (`PendingFrame`); `result()` reads it when asked for,
with the stage times, and keeps it for an identical frame. So the host prepares frame N+1
(scene, uploads, keys) while the device works on frame N; `render` is
`submit(...).result()`. At most MAX_FRAMES_IN_FLIGHT frames are unread at once.
"""
from __future__ import annotations

import collections
import dataclasses
import time
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from .device import Device, StageTimer
from .errors import ClraysError
from .frame_memory import EVERY_LIGHT_VISIBILITY, IN_SCATTER, ONE_LIGHT_IN_SCATTER, frame_buffer_bytes
from .inputs import FrameBuffers, FrameInputs, frame_inputs, frame_sizes, upload, without_walled_off_light
from .light_skip import SKIP_BUDGET, SkippedLights, candidates, mean_luminance
from .light_turns import RaysSum, add_visibility_column, lights_in_turn, one_light_buffers
from .physics.radiometry import effective_far
from .passes import assemble, per_light_indices, samples_to_pixels
from .reuse import COMPUTED, REUSED, SKIPPED, Reuse, StageCache, StageRecord, digest, geometry_parts, scene_digest
from .scene.camera import primary_rays, ray_starts
from .scene.costs import with_derived_sizes
from .scene.model import METHODS, RENAMED_METHODS, DirectionalLight, Render, Scene
from .stages.features import walk_features
from .stages.relief_cuts import ReliefCuts, relief_cuts, relief_outlines
from .stages.shaft_edges import (EDGE_NEIGHBOURS, ShaftEdges, edge_neighbours, edge_windings, keeps_blockers,
                                  shaft_edge_sides)
from .stages.integrand import integrand, integrand_table_size
from .stages.lamp import eye_in_lamp, lamp_in_scatter
from .stages.medium import medium_feature
from .stages.light_texture import light_texture
from .physics.light_texture import textured
from .stages.minmax import minmax
from .stages.raster import (RasterResult, ShadowMap, depth_in_keys, map_is_empty, raster_camera, raster_shadow_map,
                             shadow_atlases)
from .stages.raymarch import raymarch
from .stages.rectify import Epipolar, epipolar_frame, rectify
from .stages.sampling import SampleCounts, epipolar_sampling
from .stages.shade import shade, shade_features
from .stages.shadow_filter import depth_ranges, frame_filter, shadow_filter, shadow_filter_moments
from .stages.traverse import traverse
from .stages.translucency import (opaque_occluder_buffers, rectify_layers, refuse_translucency,
                                  surface_transmittance, translucency)
from .stages.transparency import Films, composite, opaque_camera_vertices, translucent_films, translucent_triangles
from .stages.transparency_walk import transparency_march, transparency_walk
from .stages.volume_moments import refuse_varying_medium, volume_moments
from .stages.visibility import (bound_atlas, bvh_topology_of, upload_bvh, visibility, visibility_bound,
                                visibility_prepare)

#: The rectified texture of a light whose shadow map is empty (nothing casts a shadow)
#: is π everywhere whatever its size, so it is built at this size (the minimum).
UNSHADOWED_SIZE = 16

#: Every stage label a frame times, in the order of the figure (the module docstring, with the
#: labels of a stage's parts after it): results.csv's columns follow it.
STAGE_ORDER = ("raster", "relief", "translucency", "transparency", "transparency.fog", "rectify", "minmax",
               "integrand", "light_texture", "traverse", "lamp", "raymarch", "volume_moments", "visibility", "bvh",
               "shadow_filter", "shade", "exact")
#: Stage labels of the volume stages of each method, as timings and statuses name them.
VOLUME_STAGES = {"minmax": ("rectify", "minmax", "integrand", "traverse"), "raymarch": ("raymarch",),
                 "volume_moments": ("rectify", "integrand", "volume_moments")}


class InScatter:
    """The in-scattered radiance per camera sample (float4), which the volume stages add
    to and shade reads: zero until a stage adds. The zeros are written only when a stage
    adds, or shade reads, before any stage wrote every sample: epipolar sampling's gather
    writes every sample of the first light it takes instead of adding, which spares a
    1280×720 frame a 14.7 MB clear and gather as many bytes of reads."""

    def __init__(self, device: Device, inputs: FrameInputs):
        self.device, self.samples = device, inputs.samples
        self.buffer = IN_SCATTER.allocate(device, frame_sizes(inputs))
        self.holds_values = False  # zeros, or a stage's values in every sample

    def adding(self):
        """The buffer, for a stage that adds to every sample it touches (or reads)."""
        if not self.holds_values:
            self.device.fill(self.buffer, np.float32(0), 16 * self.samples)
            self.holds_values = True
        return self.buffer

    def snapshot(self) -> np.ndarray:
        """The in-scattering added so far, (samples, 4) float64 on the host (a render pass's
        per-light part is the difference of two)."""
        if not self.holds_values:
            return np.zeros((self.samples, 4))
        return self.device.read(self.buffer, (self.samples, 4), np.float32).astype(np.float64)

    def writing(self) -> tuple[object, bool]:
        """(the buffer, whether the stage writes every sample instead of adding to it)."""
        overwrite = not self.holds_values
        self.holds_values = True
        return self.buffer, overwrite


@dataclass
class RenderResult:
    image: np.ndarray  # (H, W, 3) float32 linear radiance
    method: str
    stage_ms: dict[str, float] = field(default_factory=dict)  # time per stage (device events, or host clock)
    wall_ms: float = 0.0  # from Renderer.submit to the image read (render: the whole call)
    device_bytes: int = 0  # device memory allocated for the frame
    # stage → "computed", "reused", "skipped" or "reused k of n" (per light); raster is
    # "raster.camera" and "raster.shadow"; a frame identical to a kept one is all "reused".
    stage_status: dict[str, str] = field(default_factory=dict)
    host_stages: frozenset[str] = frozenset()  # the labels of `stage_ms` timed on the host
    render: Render | None = None  # the scene's render settings with the sizes derived from the image filled in
    # (slices, γ texels) of each epipolar texture the frame used, per light that has one
    textures: tuple[tuple[int, int], ...] = ()
    samples: SampleCounts | None = None  # what epipolar sampling computed, interpolated and fixed up
    shadow_rays: int | None = None  # exact surface shadows: the entries (sample × light) the maps left to a ray
    passes: dict[str, np.ndarray] | None = None  # the render passes asked for (clrays.passes), by name; else None
    host_waits: int = 0  # times the host waited for the device within the frame (Device.host_waits), the image's read too
    skipped_lights: SkippedLights | None = None  # lights left out below the error budget (clrays.light_skip)

    def without_pixels(self) -> RenderResult:
        """This result without its image and passes (written to files): its times and counts
        alone, which a long sequence keeps for every frame, and a dask worker sends back."""
        return replace(self, image=np.zeros((0, 0, 3), np.float32), passes=None)

    @property
    def reused(self) -> list[str]:
        """The stages this frame took from an earlier one."""
        return [stage for stage, status in self.stage_status.items() if status == REUSED]

    @property
    def device_ms(self) -> float:
        """Stage time spent on the OpenCL device (host stages left out)."""
        return sum(ms for label, ms in self.stage_ms.items() if label not in self.host_stages)


#: Frames a session lets be submitted and not yet read (Renderer.submit): two let the host
#: prepare one while the device works on the other.
MAX_FRAMES_IN_FLIGHT = 2


class PendingFrame:
    """A frame in flight (Renderer.submit): its host work done, its device work enqueued, its
    image not yet read. `result()` waits for the image and returns the frame's RenderResult,
    the same object at every call; its `wall_ms` runs from the submit to the image read.

    What the frame's kernels write stays theirs until then: the image's buffer is held by the
    image itself (Device.read_in_place), and the buffers it let go of may go to a later
    frame (a CPU device's pool) only because the queue is in order, so that frame's kernels
    run after this one's."""

    def __init__(self, renderer: Renderer, unread: RenderResult, stages: tuple[str, ...], passes, reads: list,
                 timer: StageTimer, start: float, key: bytes | None, use_cache: bool):
        """`unread`: the result but for the image's contents, the passes, the times; `stages`:
        the stages that ran (the frame cache's entry); `passes`: a function that assembles
        them once `reads` are done, the passes themselves, or None."""
        self._renderer, self._unread, self._stages, self._passes, self._reads = renderer, unread, stages, passes, reads
        self._timer, self._start, self._use_cache = timer, start, use_cache
        self.key = key  # the frame cache's key, under which the image is kept once read; None: not kept
        self._result: RenderResult | None = None

    @property
    def done(self) -> bool:
        """Whether the image has been read (`result()` returns at once)."""
        return self._result is not None

    def result(self) -> RenderResult:
        """The frame's RenderResult, its image read (waiting for the device's work on it)."""
        if self._result is None:
            self._result = self._read()
        return self._result

    def _read(self) -> RenderResult:
        renderer, unread = self._renderer, self._unread
        if self in renderer._in_flight:
            renderer._in_flight.remove(self)
        host_waits = unread.host_waits
        if self._reads:  # one wait: the queue is in order, so the earlier reads are done with the last
            device = renderer.device
            before = device.host_waits
            device.wait(self._reads[-1])
            host_waits += device.host_waits - before
            self._reads = []
        passes = self._passes() if callable(self._passes) else self._passes
        # Counted on the device (visibility's RayCount), their copy done with the image's.
        rays = None if unread.shadow_rays is None else int(unread.shadow_rays)
        image = unread.image
        if self.key is not None:  # kept for an identical frame, now that it holds the image
            renderer.cache.put("frame", self.key, (image, self._stages, unread.textures, unread.samples, rays,
                                                   passes, unread.skipped_lights))
        stage_ms = self._timer.milliseconds()
        wall_ms = (time.perf_counter() - self._start) * 1e3
        # A kept frame's image is shared with the cache: the caller gets a copy to change.
        if self._use_cache:
            image = image.copy()
            passes = None if passes is None else {name: value.copy() for name, value in passes.items()}
        return replace(unread, image=image, stage_ms=stage_ms, wall_ms=wall_ms, passes=passes, host_waits=host_waits,
                       shadow_rays=rays)


@dataclass
class Frame:
    """What the stages of one frame hand each other (Renderer._frame), filled in stage by stage."""

    scene: Scene
    method: str
    buffers: FrameBuffers
    keys: StageKeys
    reuse: Reuse
    timer: StageTimer
    occluders: FrameBuffers  # `buffers` with the opaque triangles alone (visibility's shadow rays)
    rastered: RasterResult | None = None
    maps: list[ShadowMap] = field(default_factory=list)
    layers: object = None  # each light's translucent layers (stages/translucency.py), or None
    films: Films | None = None  # the camera's translucent films (stages/transparency.py), or None
    in_scatter: InScatter | None = None
    textures: list[tuple[int, int]] = field(default_factory=list)  # (slices, γ texels) per light with a texture
    samples: SampleCounts | None = None  # what epipolar sampling computed, summed over the lights
    progress: object = None  # of raymarch's march, as Renderer.render's `progress`
    reads: list = field(default_factory=list)  # events of the reads left for PendingFrame.result (shade's)
    light_scatter: dict[int, np.ndarray] = field(default_factory=dict)  # per-light passes: light → (samples, 4)
    skipped: tuple[tuple[int, ...], float] = ((), 0.0)  # lights in turn: (lights left out, their bound) (light_skip.py)
    skip_lights: bool = True  # lights in turn: whether lights below the error budget are left out (light_skip.py)


class Renderer:
    """Renders scenes on one OpenCL device: a session that keeps built kernels and, with
    `reuse` (default), recent stage results (`cache_entries` per stage and light);
    `skip_lights` (default): a frame of lights in turn leaves out the lights below the
    error budget (clrays.light_skip)."""

    def __init__(self, device: Device | str | None = None, reuse: bool = True, cache_entries: int = 3,
                 skip_lights: bool = True):
        self.skip_lights = skip_lights
        self._device = device if isinstance(device, Device) else None
        self._device_spec = device if isinstance(device, str) else None
        self.reuse = reuse
        self.cache = StageCache(cache_entries)
        self._in_flight: collections.deque[PendingFrame] = collections.deque()  # submitted, not yet read

    @property
    def device(self) -> Device:
        if self._device is None:  # created lazily: `exact` needs no device
            self._device = Device(self._device_spec)
        return self._device

    @property
    def frames_in_flight_win(self) -> bool:
        """Whether a frame in flight beside the next gains time on this session's device: on
        one that works beside the host (a GPU), not on a CPU device, whose kernels take the
        host's own cores (PoCL on two cores: level within the noise, bench/RESULTS.md
        history, "The host's waits inside a frame");
        False before the session has a device (`exact` needs none)."""
        return self._device is not None and not self._device.is_cpu

    def clear(self) -> None:
        """Forget every kept stage result (frees their device memory)."""
        self.cache.clear()

    def render(self, scene: Scene, method: str | None = None, progress: bool = False,
               reuse: bool | None = None) -> RenderResult:
        """Render one frame. `method` overrides `scene.render.method`; `reuse` overrides
        the session's `reuse` for this frame (False: compute every stage, keep nothing).
        `progress` (exact and raymarch): True for a tqdm bar, or a function that takes a
        line of text. The same as `submit(...).result()`."""
        return self.submit(scene, method, progress, reuse).result()

    def submit(self, scene: Scene, method: str | None = None, progress: bool = False,
               reuse: bool | None = None) -> PendingFrame:
        """Start one frame, as `render` takes it, and return before its image is read: the
        frame's host work is done and its device work enqueued, and `PendingFrame.result()`
        waits for the image. Meanwhile the host can prepare the next frame while the device
        works on this one. At most MAX_FRAMES_IN_FLIGHT frames are unread at once: a
        submit beyond them first reads the oldest (kept for its `result()`)."""
        method = RENAMED_METHODS.get(method, method) or scene.render.method
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
        # Sizes the scene leaves unset follow its image; resolved before any stage key is taken.
        scene = with_derived_sizes(replace(scene, render=replace(scene.render, method=method)))
        start = time.perf_counter()
        use_cache = self.reuse if reuse is None else reuse
        key = digest("frame", scene_digest(scene)) if use_cache else None
        # An identical frame still in flight is read first, so that this one finds its image
        # kept; and the oldest beyond the bound.
        for earlier in [pending for pending in self._in_flight if key is not None and pending.key == key]:
            earlier.result()
        while len(self._in_flight) >= MAX_FRAMES_IN_FLIGHT:
            self._in_flight[0].result()
        record, timer = StageRecord(), StageTimer()
        reuse = Reuse(self.cache if use_cache else None, record, max(len(scene.lights), 1))
        waits_before = self._device.host_waits if self._device is not None else 0
        if self._device is not None:
            self._device.allocated_bytes, self._device.allocated_by_name = 0, {}
        # A frame identical to a kept one: its image, and every stage counts as reused.
        found, kept = self.cache.get("frame", key) if key is not None else (False, None)
        reads = []  # the events of the frame's reads left for `result()` (Device.deferred_waits)
        image, stages, textures, samples, rays, passes, skipped = kept if found else \
            self._frame(scene, method, reuse, timer, progress, reads)
        status = record.status() or {stage: REUSED for stage in stages}
        device_bytes = self._device.allocated_bytes if self._device is not None else 0
        host_waits = self._device.host_waits - waits_before if self._device is not None else 0
        if self._device is not None:
            self._device.end_frame(device_bytes)
        unread = RenderResult(image, method, {}, 0.0, device_bytes, status, timer.host_labels, scene.render,
                              textures, samples, rays, None, host_waits, skipped)
        pending = PendingFrame(self, unread, stages, passes, reads, timer, start, None if found else key, use_cache)
        if reads:
            self._in_flight.append(pending)
            # A driver may hold enqueued commands until a wait or a flush: the device starts
            # on this frame's work now, while the host goes on.
            self.device.queue.flush()
        return pending

    def _frame(self, scene: Scene, method: str, reuse: Reuse, timer: StageTimer, progress: bool, reads: list,
               skip_lights: bool = True):
        """(image, stage labels, epipolar texture sizes, sample counts, shadow rays, render
        passes or None, the lights skipped or None) of one frame: the pipeline of the module
        docstring, one line per stage. The image's reads are enqueued, their events added to
        `reads`: the image and the passes' terms are there once the last is done, and the
        passes are a function that assembles them then. `skip_lights`: as the renderer's;
        False for the frame again with every light, where those it left out fail the check."""
        if method == "exact":
            return self._exact(scene, reuse, timer, progress)
        frame = self._upload(scene, method, reuse, timer)  # the scene in eye space, packed into device structs
        frame.progress, frame.reads, frame.skip_lights = progress, reads, skip_lights and self.skip_lights
        in_turn = lights_in_turn(frame.scene, method)  # each light's maps, trees and visibility apart (light_turns.py)
        frame.rastered, frame.maps = self._raster(frame.buffers, frame.keys, reuse, timer,  # raster: depths, maps
                                                  maps=not in_turn)
        frame.layers = self._translucency(frame.buffers, frame.keys, reuse, timer)  # translucency: light side
        frame.films = self._films(frame.buffers, frame.rastered, reuse, timer)  # transparency: camera side
        frame.in_scatter = InScatter(self.device, frame.buffers.inputs)  # in-scattering per camera sample
        if in_turn:  # per light: raster.shadow → rectify → minmax → integrand → traverse → visibility
            visible, rays = self._lights_in_turn(frame)
        else:
            VOLUME_METHODS[method](self, frame)  # raymarch; or per light rectify → minmax → integrand → traverse
            visible, rays = self._visibility(frame.occluders, frame.rastered, frame.keys, reuse, timer)  # visibility
        image, passes = self._shade(frame, visible)  # shade: surfaces, attenuation, + in-scattering
        skipped = self._skipped_lights(frame, image)  # lights in turn: those left out, checked against the image
        if frame.skipped[0] and skipped is None:  # over the budget after all (shade wrote over the in-scattering)
            return self._frame(scene, method, reuse, timer, progress, reads, skip_lights=False)
        # The stages that ran: a frame identical to this one counts them reused (not the skipped ones).
        ran = tuple(stage for stage, status in reuse.record.status().items() if status != SKIPPED)
        return image, ran, tuple(frame.textures), frame.samples, rays, passes, skipped

    def _upload(self, scene: Scene, method: str, reuse: Reuse, timer: StageTimer) -> Frame:
        """The frame's inputs checked against the device and uploaded, with their stage keys."""
        scene = without_walled_off_light(scene)  # a light a closed solid keeps from the eye: dark, exactly
        inputs = frame_inputs(scene)
        check_device_memory(self.device, inputs)
        refuse_translucency(scene, method)  # (volume_moments: no transmittance term)
        refuse_varying_medium(scene, method)  # (volume_moments: the homogeneous integrand only)
        buffers = upload(self.device, inputs)
        occluders = opaque_occluder_buffers(self.device, buffers)  # (translucent triangles block no shadow ray)
        return Frame(scene, method, buffers, StageKeys(buffers.inputs), reuse, timer, occluders)

    def _raymarch_volume(self, frame: Frame) -> None:
        """Method raymarch's volume stage, the brute-force reference: every light at once."""
        if self._no_medium(frame):
            return
        device, buffers, timer, layers = self.device, frame.buffers, frame.timer, frame.layers
        frame.reuse.record.note("raymarch", COMPUTED)
        raymarch(device, buffers, frame.rastered, frame.in_scatter.adding(), timer, layers, progress=frame.progress)
        for index in per_light_indices(frame.scene.render.aovs):  # a render pass per light: that light marched alone
            alone = ONE_LIGHT_IN_SCATTER.allocate(device, frame_sizes(buffers.inputs))
            raymarch(device, buffers, frame.rastered, alone, timer, layers, only_light=index)
            frame.light_scatter[index] = device.read(alone, (frame.in_scatter.samples, 4), np.float32)
        self._films_in_scatter(frame, lambda r, s, t: raymarch(device, buffers, r, s, t, layers),
                               lambda: transparency_march(device, buffers, frame.rastered, frame.films, timer, layers))

    def _epipolar_volume(self, frame: Frame) -> None:
        """The volume stages of methods minmax and volume_moments, light by light."""
        if self._no_medium(frame):
            return
        for index in range(len(frame.scene.lights)):
            self._epipolar_light(frame, index)
        frame.reuse.record.note(VOLUME_STAGES[frame.method][-1], COMPUTED)

    def _epipolar_light(self, frame: Frame, index: int, alone: Frame | None = None) -> None:
        """Light `index`'s volume stages, added to the frame's in-scattering: in `frame`, or
        (lights in turn) in `alone`, the frame with that light alone."""
        part, at = (frame, index) if alone is None else (alone, 0)
        light = part.scene.lights[at]
        # a render pass of this light alone (float32 sums differ exactly in float64: the parts add up to the whole)
        before = frame.in_scatter.snapshot() if index in per_light_indices(frame.scene.render.aovs) else None
        if eye_in_lamp(part.scene, light):  # d_el → 0: no epipolar frame, nothing visible is shadowed
            self._lamp_in_scatter(part, light)
        else:
            self._light_volume(part, at, light)
        if before is not None:
            frame.light_scatter[index] = frame.in_scatter.snapshot() - before

    def _lights_in_turn(self, frame: Frame):
        """Each light's raster.shadow → volume → visibility through its own buffers, one
        light at a time (clrays.light_turns): its in-scattering added to the frame's, its
        visibility copied into the frame's column for it. Returns (visibility per sample
        and light, shadow rays) as `_visibility`."""
        lights = len(frame.scene.lights)
        visible = EVERY_LIGHT_VISIBILITY.allocate(self.device, frame_sizes(frame.buffers.inputs))
        # lights whose bound is below the error budget take no turn: visibility 0, no in-scattering
        # (not where a render pass shows a light alone)
        frame.skipped = candidates(frame.scene, frame.skip_lights and not per_light_indices(frame.scene.render.aovs))
        if frame.skipped[0]:
            self.device.fill(visible, np.float32(0), 4 * frame.buffers.inputs.samples * lights)
        medium = not self._no_medium(frame)
        kept = {}  # the BVH: over the frame's triangles, the same for every light, built once a frame

        def frame_bvh(buffers: FrameBuffers, keys: StageKeys):
            if "bvh" not in kept:
                kept["bvh"] = self._bvh(buffers, keys, frame.reuse, frame.timer)
            return kept["bvh"]

        rays = [self._light_in_turn(frame, index, medium, visible, frame_bvh) for index in range(lights)
                if index not in frame.skipped[0]]
        if medium:
            frame.reuse.record.note(VOLUME_STAGES[frame.method][-1], COMPUTED)
        return visible, RaysSum(rays)

    def _skipped_lights(self, frame: Frame, image: np.ndarray) -> SkippedLights | None:
        """The lights the frame left out (clrays.light_skip), where their bound is within
        SKIP_BUDGET of the kept lights' mean luminance: that waits for the image. None where
        none was left out, or the bound is over (then the frame renders again with them)."""
        indices, bound = frame.skipped
        if not indices:
            return None
        for event in frame.reads[-1:]:  # the queue is in order: the last read holds the image
            self.device.wait(event)
        allowed = SKIP_BUDGET * mean_luminance(image)
        return SkippedLights(indices, len(frame.scene.lights), bound, allowed) if bound <= allowed else None

    def _light_in_turn(self, frame: Frame, index: int, medium: bool, visible, frame_bvh) -> int:
        """One light of `_lights_in_turn`; what it allocates goes when it returns (on a
        CPU device, back to the pool for the next light), but the frame's BVH (`frame_bvh`).
        Returns its shadow rays."""
        device, reuse, timer = self.device, frame.reuse, frame.timer
        shadow_map = reuse.stage("raster.shadow", lambda: frame.keys.shadow[index],
                                 lambda: raster_shadow_map(device, frame.buffers, index, timer), per_light=True)
        buffers = one_light_buffers(device, frame.buffers, index)
        depth, blockers, volume = shadow_atlases(device, buffers, [shadow_map])  # (one map: its own buffers)
        # shade reads no map with exact surface shadows: the flags alone, for the same build of its kernel
        frame.rastered = replace(frame.rastered, blocker_keys=shadow_map.keys, depth_in_keys=shadow_map.depth_in_keys)
        rastered = replace(frame.rastered, shadow_depth=depth, shadow_blockers=blockers, volume_blockers=volume)
        alone = replace(frame, scene=buffers.inputs.scene, buffers=buffers, keys=StageKeys(buffers.inputs),
                        occluders=buffers, rastered=rastered, maps=[shadow_map])
        if medium:
            self._epipolar_light(frame, index, alone)
            frame.samples = alone.samples
        part, rays = self._visibility(buffers, rastered, alone.keys, reuse, timer,
                                      bvh=lambda: frame_bvh(buffers, alone.keys))
        add_visibility_column(device, visible, part, index, len(frame.scene.lights), buffers.inputs.samples)
        return rays

    def _no_medium(self, frame: Frame) -> bool:
        """Whether the scene has no medium: then no volume stage runs at all."""
        if np.any(frame.scene.medium.sigma_s > 0):
            return False
        frame.reuse.skip(*VOLUME_STAGES[frame.method])
        return True

    def _lamp_in_scatter(self, frame: Frame, light) -> None:
        """A light whose lamp holds the eye: its in-scattering on the host (stages/lamp.py)."""
        device, buffers = self.device, frame.buffers
        lamp_in_scatter(device, buffers, frame.rastered, light, frame.in_scatter.adding(), frame.timer)
        self._films_in_scatter(frame, lambda r, s, t: lamp_in_scatter(device, buffers, r, light, s, t))

    def _light_volume(self, frame: Frame, index: int, light) -> None:
        """One light's rectify → minmax → integrand → traverse (or volume_moments)."""
        device, buffers, keys, reuse, timer = self.device, frame.buffers, frame.keys, frame.reuse, frame.timer
        # A relief the walks cut per ray stays out of the volume's map (stages/relief_cuts.py);
        # where its outline does not fit the bins, the map holds it.
        reliefs = self._relief_cuts(buffers, frame.rastered, keys, index, reuse)
        rastered = frame.rastered if reliefs is not None else replace(frame.rastered, volume_blockers=None)
        epipolar = self._rectify(buffers, rastered, frame.maps, keys, index, reuse, timer,  # rectify: S[α, γ]
                                 reliefs is not None)
        frame.textures.append((int(epipolar.params["slices"]), int(epipolar.params["gamma_samples"])))
        if frame.method == "minmax":
            self._minmax(epipolar, reuse, timer)  # minmax: the 1D min-max mipmap of every row
        tables = reuse.stage("integrand", lambda: keys.integrand(index),  # integrand: lit run → radiance
                             lambda: integrand(device, frame.scene, light, epipolar, timer), per_light=True)
        texture = reuse.stage("light_texture", lambda: keys.light_texture(index),  # light_texture: T·Γ_i sums
                              lambda: light_texture(device, buffers, index, epipolar, tables, timer),
                              per_light=True) if textured(light) else None
        if frame.method == "volume_moments":  # prefix sums of moments, one reconstruction per ray
            volume_moments(device, buffers, frame.rastered, epipolar, tables, frame.in_scatter.adding(), timer,
                           walk_features(texture, None))
            return
        edges = None if epipolar.unshadowed else self._shaft_edges(buffers, epipolar, keys, reuse, timer)
        features = walk_features(  # what the walks carry (stages/features.py, cl/walk_features.h)
            texture, None if frame.layers is None else rectify_layers(device, buffers, frame.layers, epipolar, timer),
            edges, reliefs, medium_feature(device, buffers, timer))  # (a bounded or heterogeneous medium)
        # A relief's shafts, finer than the lines are apart, run along them: a camera sample
        # between two lines is neither's, and walks its own rays (docs/design.md §4.5).
        if frame.scene.render.sampling == "epipolar" and not epipolar.unshadowed and reliefs is None:  # traverse
            counts = epipolar_sampling(device, buffers, frame.rastered, epipolar, tables, *frame.in_scatter.writing(),
                                       timer, features)
            frame.samples = counts if frame.samples is None else frame.samples + counts
        else:  # per camera sample; and a light that casts no shadow, whose 16 slices are too few to sample
            traverse(device, buffers, frame.rastered, epipolar, tables, frame.in_scatter.adding(), timer, features)
            if frame.scene.render.sampling == "epipolar" and reliefs is not None:  # (--stats: every one walked)
                walked = SampleCounts(fixed_up=buffers.inputs.samples)
                frame.samples = walked if frame.samples is None else frame.samples + walked
        self._films_in_scatter(frame, lambda r, s, t: traverse(device, buffers, r, epipolar, tables, s, t, features),
                               lambda: transparency_walk(device, buffers, frame.films, epipolar, tables, timer,
                                                         features))

    def _shaft_edges(self, buffers: FrameBuffers, epipolar, keys: StageKeys, reuse: Reuse,
                     timer: StageTimer) -> ShaftEdges | None:
        """What places the walks' run ends on the blockers' silhouettes (stages/shaft_edges.py):
        None where the rows keep no blockers (`render.shaft_edges: texels`, `keeps_blockers`),
        which is also where the frame may not carry every triangle's vertices
        (`carries_relief_triangles`)."""
        geometry = buffers.inputs.scene.geometry
        if epipolar.triangles is None:
            return None
        neighbours = reuse.keep("edge_neighbours", lambda: digest("edge_neighbours", keys.geometry),
                                lambda: EDGE_NEIGHBOURS.upload(self.device, edge_neighbours(geometry),
                                                               frame_sizes(buffers.inputs)))
        windings = reuse.keep("edge_windings", lambda: digest("edge_windings", keys.geometry),
                              lambda: self.device.buffer(edge_windings(geometry), writable=False))
        sides = shaft_edge_sides(self.device, epipolar, buffers.tri_vertices, windings, geometry.count, timer)
        return ShaftEdges(epipolar.triangles, buffers.tri_vertices, neighbours, sides)

    def _relief_cuts(self, buffers: FrameBuffers, rastered: RasterResult, keys: StageKeys, index: int,
                     reuse: Reuse) -> ReliefCuts | None:
        """What the walks of light `index` cut of the frame's reliefs (stages/relief_cuts.py);
        None where the frame does not cut them (`cuts_reliefs`: no map without them) or their
        outline does not fit the bins. The outline is kept while the geometry and the light
        are, its bins while the eye is too (about 5 and 15 ms a frame of host work on
        scenes/lattice.yaml)."""
        if rastered.volume_blockers is None:
            return None
        scene = buffers.inputs.scene
        light = scene.lights[index]
        pose = np.asarray(light.direction if isinstance(light, DirectionalLight) else light.position, np.float64)
        outline = reuse.keep("relief_outline", lambda: digest("relief_outline", keys.geometry, pose),
                             lambda: relief_outlines(scene, light), per_light=True)
        eye = np.asarray(buffers.inputs.eye_ws, np.float64)  # (with the pose, it fixes the epipolar frame's axes)
        return reuse.keep("relief_cuts", lambda: digest("relief_cuts", keys.geometry, pose, eye),
                          lambda: relief_cuts(self.device, scene, index, outline, eye,
                                              epipolar_frame(scene, buffers, index)), per_light=True)

    def _films_in_scatter(self, frame: Frame, per_film, weighted=None) -> None:
        """The in-scattering a volume stage just added for the camera samples, added for the
        translucent films too: by MBOIT's one weighted walk where the films have it (and the
        stage has one, `weighted`), else by the same stage run up to each film (`per_film`)."""
        films = frame.films
        if films is None:
            return
        if films.walked is not None and weighted is not None:
            weighted()
        else:
            films.add_in_scatter(self.device, frame.timer, per_film)

    def _shade(self, frame: Frame, visible):
        """The shade stage, with what translucent objects add before it: the exact edges of
        their shadows on surfaces, and the camera's films composited in front of the opaque
        samples."""
        device, buffers, rastered, layers, timer = self.device, frame.buffers, frame.rastered, frame.layers, frame.timer
        through = None if layers is None or frame.scene.render.surface_shadows != "exact" else \
            surface_transmittance(device, buffers, rastered, layers, timer)  # (translucent shadows' exact edges)
        films = None if frame.films is None else composite(device, buffers, rastered, frame.films, timer, layers)
        features = shade_features(device, buffers, layers, through, films)  # (stages/shade.py, cl/shade_features.h)
        aovs = frame.scene.render.aovs
        with device.deferred_waits(frame.reads):  # the image is read when the frame's result is asked for
            image = shade(device, buffers, rastered, frame.in_scatter.adding(), timer, visible, features,
                          passes=bool(aovs), medium=medium_feature(device, buffers, timer))
        frame.reuse.record.note("shade", COMPUTED)
        if not aovs:
            return image, None
        image, terms = image
        size = frame.scene.image
        gain = _near_gain(frame.scene)  # (shade scales the frame's in-scattering so, cl/shade.cl)
        per_light = {index: samples_to_pixels(gain * frame.light_scatter.get(index, np.zeros((frame.in_scatter.samples, 4))),
                                              size.height, size.width, size.spp)
                     for index in per_light_indices(aovs)}
        return image, lambda: assemble(aovs, terms[..., 0, :3], terms[..., 1, :3], terms[..., 2, :3],
                                       terms[..., 0, 3], per_light)

    def _films(self, buffers: FrameBuffers, rastered: RasterResult, reuse: Reuse, timer: StageTimer) -> Films | None:
        """The transparency stage's films (clrays.stages.transparency); None, and the stage
        skipped, when every object is opaque: then nothing of it runs."""
        if not buffers.inputs.scene.geometry.translucent:
            reuse.skip("transparency")
            return None
        reuse.record.note("transparency", COMPUTED)
        return translucent_films(self.device, buffers, rastered, timer)

    def _translucency(self, buffers: FrameBuffers, keys: StageKeys, reuse: Reuse, timer: StageTimer):
        """The translucency stage, kept while the shadow maps' inputs and the layer count
        are (the opacities are in `keys.geometry`); skipped, None, in an opaque-only scene."""
        scene = buffers.inputs.scene
        if not scene.geometry.translucent or not scene.lights:
            reuse.skip("translucency")
            return None
        return reuse.stage("translucency",
                           lambda: digest("translucency", tuple(keys.shadow), scene.render.translucent_layers),
                           lambda: translucency(self.device, buffers, timer))

    def _bvh(self, buffers: FrameBuffers, keys: StageKeys, reuse: Reuse, timer: StageTimer):
        """The visibility stage's BVH: its tree kept while the geometry is, its boxes while
        the eye-space triangles are (geometry and eye position; not where the camera looks).
        Asked for only when some sample needs a shadow ray (stages/visibility.py)."""
        topology = reuse.keep("bvh.topology", lambda: digest("bvh.topology", keys.geometry),
                              lambda: bvh_topology_of(self.device, buffers.inputs, timer))
        return reuse.keep("bvh", lambda: digest("bvh", keys.geometry, buffers.inputs.eye_ws),
                          lambda: upload_bvh(self.device, buffers, topology, timer))

    def _visibility(self, buffers: FrameBuffers, rastered: RasterResult, keys: StageKeys, reuse: Reuse,
                    timer: StageTimer, bvh=None):
        """The visibility stage: each light's bound map kept while its shadow map is, and the
        frame's BVH (`_bvh`, or `bvh` where given) when a shadow ray needs it. Returns (visibility, shadow rays
        cast); visibility is None unless `render.surface_shadows` is exact (or filtered:
        then the shadow_filter stage answers instead), and the rays None but for exact."""
        scene = buffers.inputs.scene
        if scene.render.surface_shadows == "filtered" and scene.lights:
            return self._shadow_filter(buffers, rastered, keys, reuse, timer), None
        if scene.render.surface_shadows != "exact" or not scene.lights:
            return None, None
        device = self.device
        # The bound maps are drawn only where the camera's samples read them: kept while the
        # light's shadow map, the camera samples and the surfaces' normals are.
        prepared = visibility_prepare(device, buffers, rastered, timer)
        bounds = [reuse.keep("visibility.bound",
                             lambda index=index: digest("bound", keys.shadow[index], keys.camera, keys.surfaces),
                             lambda index=index: visibility_bound(device, buffers, index, timer, prepared),
                             per_light=True)
                  for index in range(len(scene.lights))]
        # (one light's atlas is its own bound map, kept with it)
        atlas = bounds[0] if len(bounds) == 1 else reuse.keep(
            "bound_atlas", lambda: digest("bound", tuple(keys.shadow), keys.camera, keys.surfaces),
            lambda: bound_atlas(device, buffers, bounds))
        reuse.record.note("visibility", COMPUTED)
        bvh = bvh or (lambda: self._bvh(buffers, keys, reuse, timer))
        return visibility(device, buffers, rastered, prepared, atlas, bvh, timer, bounds)

    def _shadow_filter(self, buffers: FrameBuffers, rastered: RasterResult, keys: StageKeys, reuse: Reuse,
                       timer: StageTimer):
        """The shadow_filter stage: the blurred moment maps kept while the shadow maps and the
        filter's type and radius are, then the visibility of every camera sample."""
        device, chosen = self.device, frame_filter(buffers.inputs)
        key = lambda: digest("moment_shadow_maps", tuple(keys.shadow), chosen.type, chosen.radius,
                             depth_ranges(buffers.inputs))
        maps = reuse.keep("shadow_filter.moment_maps", key, lambda: shadow_filter_moments(device, buffers, rastered, timer))
        reuse.record.note("shadow_filter", COMPUTED)
        return shadow_filter(device, buffers, rastered, maps, timer)

    def _exact(self, scene: Scene, reuse: Reuse, timer: StageTimer, progress: bool):
        """The float64 reference, one host stage."""
        from .reference.exact import render_exact

        start = time.perf_counter()
        parts = {} if scene.render.aovs else None
        image = render_exact(scene, progress=progress, parts=parts).astype(np.float32)
        timer.add_host("exact", (time.perf_counter() - start) * 1e3)
        reuse.record.note("exact", COMPUTED)
        passes = None
        if parts is not None:
            lights = parts["lights"]
            passes = assemble(scene.render.aovs, parts["transmittance"], parts["attenuated_surface"], lights.sum(axis=0),
                              parts["depth"], dict(enumerate(lights)))
        return image, ("exact",), (), None, None, passes, None

    def _raster(self, buffers: FrameBuffers, keys: StageKeys, reuse: Reuse, timer: StageTimer, maps: bool = True):
        """The raster stage, each part kept while its inputs are: the camera's depth and
        triangle ids, and each light's shadow map (anchored at the light, so a moving
        camera keeps it). Returns the frame's RasterResult and the per-light maps;
        `maps=False` (lights in turn, which raster each map in its turn): the camera's alone."""
        device = self.device
        camera_buffers, camera_key = buffers, lambda: keys.camera
        if buffers.inputs.scene.geometry.translucent:  # the camera depth is the opaque one (stages/transparency.py)
            camera_buffers = replace(buffers, tri_vertices=None)
            camera_key = lambda: digest(keys.camera, "opaque", translucent_triangles(buffers.inputs.scene))

        def camera():
            if camera_buffers.tri_vertices is None:
                opaque = device.buffer(opaque_camera_vertices(buffers.inputs), writable=False)
                return raster_camera(device, replace(camera_buffers, tri_vertices=opaque), timer)
            return raster_camera(device, camera_buffers, timer)

        camera_depth, tri_id = reuse.stage("raster.camera", camera_key, camera)
        if not maps:
            return RasterResult(camera_depth, tri_id, device.buffer(nbytes=4)), []
        maps = [reuse.stage("raster.shadow", lambda index=index: keys.shadow[index],
                            lambda index=index: raster_shadow_map(device, buffers, index, timer), per_light=True)
                for index in range(len(buffers.inputs.scene.lights))]
        atlas = reuse.keep("shadow_atlas", lambda: digest(tuple(keys.shadow)),
                           lambda: shadow_atlases(device, buffers, maps))
        return RasterResult(camera_depth, tri_id, *atlas[:2], bool(maps) and maps[0].keys, atlas[2],
                            bool(maps) and maps[0].depth_in_keys), maps

    def _rectify(self, buffers: FrameBuffers, rastered: RasterResult, maps: list[ShadowMap], keys: StageKeys,
                 index: int, reuse: Reuse, timer: StageTimer, cut_reliefs: bool = False) -> Epipolar:
        """The rectify stage of one light, kept while `keys.trees` is the same and the walks
        cut the reliefs or not (`cut_reliefs`: the map without them). A light whose
        map is empty casts no shadow anywhere: its texture is π everywhere and the tree walk
        finds one lit run at any texture size, so a minimal texture gives the same radiance
        (up to float32 rounding where the run is clipped) without rectifying the full one."""
        device, key = self.device, lambda: digest(keys.trees(index), cut_reliefs)
        # A textured light keeps its full texture size: the texture is rectified on its rows.
        # So does a light with translucent layers: its texture carries their transmittance.
        if not textured(buffers.inputs.scene.lights[index]) \
                and not buffers.inputs.scene.geometry.translucent and map_is_empty(device, maps[index]):
            render = buffers.inputs.scene.render
            small = replace(buffers.inputs.scene, render=replace(render, slices=UNSHADOWED_SIZE,
                                                                   gamma_samples=UNSHADOWED_SIZE))
            small_buffers = replace(buffers, inputs=replace(buffers.inputs, scene=small))
            reuse.skip("rectify", "minmax")
            return reuse.keep("unshadowed", lambda: digest("unshadowed", key()),
                              lambda: self._unshadowed_trees(small_buffers, rastered, index, timer), per_light=True)
        return reuse.stage("rectify", key, lambda: rectify(device, buffers, rastered, index, timer), per_light=True)

    def _unshadowed_trees(self, buffers: FrameBuffers, rastered: RasterResult, index: int, timer: StageTimer):
        epipolar = rectify(self.device, buffers, rastered, index, timer)
        minmax(self.device, epipolar, timer)
        epipolar.unshadowed = True
        return epipolar

    def _minmax(self, epipolar: Epipolar, reuse: Reuse, timer: StageTimer) -> None:
        """The minmax stage: builds the tree levels in place, unless these trees were kept
        from an earlier frame with their levels already built."""
        if epipolar.unshadowed:
            return  # built with the minimal texture, recorded as skipped
        if epipolar.levels_built:
            reuse.record.note("minmax", REUSED)
            return
        minmax(self.device, epipolar, timer)
        reuse.record.note("minmax", COMPUTED)


#: Each method's volume stages (`exact` renders on the host instead: Renderer._exact).
VOLUME_METHODS = {"minmax": Renderer._epipolar_volume, "volume_moments": Renderer._epipolar_volume,
                  "raymarch": Renderer._raymarch_volume}


def check_device_memory(device: Device, inputs: FrameInputs) -> None:
    """Refuse, in one line naming the limit, a frame whose buffers the device cannot hold:
    one larger than its largest allocation, or all together more than its memory."""
    scene = inputs.scene
    image = scene.image
    what = (f"{image.width}×{image.height} at {image.spp} spp, {len(scene.lights)} light(s) with "
            f"{scene.render.shadow_map}² shadow maps")
    where = f"{scene.source}: " if scene.source else ""
    sizes = frame_buffer_bytes(inputs)
    name, largest = max(sizes, key=lambda item: item[1])
    limit = int(device.device.max_mem_alloc_size)
    if largest > limit:
        raise ClraysError(f"{where}the frame ({what}) needs a {largest / 2**20:.0f} MiB buffer for the {name}, "
                          f"more than the device's largest allocation of {limit / 2**20:.0f} MiB ({device.name}); "
                          f"lower the image size, the light count or render.shadow_map")
    total, memory = sum(size for _, size in sizes), int(device.device.global_mem_size)
    if total > memory:
        raise ClraysError(f"{where}the frame ({what}) needs {total / 2**30:.1f} GiB of device memory, more than "
                          f"the device's {memory / 2**30:.1f} GiB ({device.name}); lower the image size, the "
                          f"light count or render.shadow_map")


def _near_gain(scene: Scene) -> np.ndarray | float:
    """(samples, 4), e^{σt·t0} per camera sample and channel (w: 1): what makes in-scattering
    gathered from each ray's start t0 (`camera.near`), attenuated from the eye, attenuated from
    t0. 1.0 without near."""
    if scene.camera.near == 0.0:
        return 1.0
    if not scene.medium.homogeneous:  # its gain is 1/T_e(t0), which only shade has (cl/shade.cl)
        raise ClraysError(f"{scene.source or 'scene'}: render.aovs: the per-light in-scattering passes with "
                          f"camera.near > 0 need a homogeneous medium (no medium.bounds or medium.density)")
    starts = ray_starts(scene.camera, primary_rays(scene.camera, scene.image).reshape(-1, 3))
    gain = np.ones((len(starts), 4))
    gain[:, :3] = np.exp(np.outer(starts, scene.medium.sigma_t))
    return gain


class StageKeys:
    """Digests of exactly what each stage of one frame reads, each made when first asked
    for: a frame that keeps nothing (`reuse=False`) asks for none."""

    def __init__(self, inputs: FrameInputs):
        self.inputs = inputs

    @cached_property
    def geometry(self) -> bytes:
        """The triangles (a relief's by its texels and placement, clrays.reuse.geometry_parts),
        which are pre-warped, how many the device buffers carry, and what their rows carry
        besides (the solids' faces a view may skip, the convex parts: clrays.inputs.vertex_rows)."""
        inputs, scene = self.inputs, self.inputs.scene
        geometry = digest(*geometry_parts(scene.geometry, triangles_only=True), inputs.raster_triangles,
                          len(inputs.tri_vertices), scene.geometry.outward, scene.geometry.convex_part)
        if scene.geometry.translucent:  # which triangles are opaque occluders, and what the others let through
            geometry = digest(geometry, scene.geometry.opacity)
        return geometry

    @cached_property
    def surfaces(self) -> bytes:
        """visibility's bound maps: the triangles with their shading normals, which decide the
        texels the camera's samples read (cl/visibility_prepare.cl)."""
        return digest("surfaces", *geometry_parts(self.inputs.scene.geometry))

    @cached_property
    def camera(self) -> bytes:
        """raster.camera: the eye-space triangles (geometry and eye), the camera view, the sample offsets."""
        inputs = self.inputs
        return digest("camera", self.geometry, inputs.eye_ws, inputs.views[:1], inputs.offsets)

    @cached_property
    def shadow(self) -> list[bytes]:
        """raster.shadow, per light: the geometry, the light's views relative to its anchor,
        which of them the frame reads (cube faces outside the camera's view are left empty),
        whether the map keeps its blocking triangles and whether its depths are read from them."""
        inputs, shadow = self.inputs, []
        for index, (first, count) in enumerate(inputs.light_views):
            views = inputs.views[first:first + count].copy()
            views["origin"], views["depth_offset"] = 0.0, 0
            shadow.append(digest("shadow", self.geometry, inputs.light_anchor_ws[index], views,
                                 inputs.lights[index]["type"], inputs.view_needed[first:first + count],
                                 keeps_blockers(inputs.scene.render), depth_in_keys(inputs.scene)))
        return shadow

    def _light_geometry(self, index: int) -> dict:
        """The light's fields but its power, which neither rectify nor minmax reads."""
        light = self.inputs.scene.lights[index]
        return {f.name: getattr(light, f.name) for f in dataclasses.fields(light)
                if f.name not in ("intensity", "irradiance")}

    def trees(self, index: int) -> bytes:
        """rectify + minmax of one light: the camera depth, the light's map, the epipolar
        frame (eye, light, camera, image) and the texture size. Not the medium, the
        light's power or the shading options, which neither stage reads."""
        inputs, scene = self.inputs, self.inputs.scene
        first, count = inputs.light_views[index]
        return digest("trees", index, self.camera, self.shadow[index], self._light_geometry(index), inputs.eye_ws,
                      inputs.views[:1], inputs.views[first:first + count], scene.camera, scene.image,
                      scene.render.slices, scene.render.gamma_samples)

    def ranges(self, index: int) -> bytes:
        """The β and γ ranges of one light's visible rays, which rectify reduces and keeps on
        the device (clrays.stages.rectify.VisibleRanges): not their values, which the host
        never reads, but what decides them: the camera depth (geometry, eye, camera view,
        sample offsets), the light's position or direction, the camera and the image."""
        inputs, scene = self.inputs, self.inputs.scene
        return digest("ranges", index, self.camera, self._light_geometry(index), inputs.eye_ws, scene.camera,
                      scene.image)

    def light_texture(self, index: int) -> bytes:
        """light_texture of one light: the trees' key (the epipolar frame and texture size,
        the light with its texture), the integrand's (the medium, the β range) and the rank."""
        return digest("light_texture", self.trees(index), self.integrand(index), self.inputs.eye_ws,
                      self.inputs.scene.render.svd_rank)

    def integrand(self, index: int) -> bytes:
        """integrand of one light: the medium, the light, the β and γ ranges of the visible
        rays (by `ranges`, which also decides the eye–light distance), the integrand mode
        and rank, the camera's far, the table size (it follows the image)."""
        scene = self.inputs.scene
        return digest("tables", scene.medium, scene.lights[index], scene.render.integrand, scene.render.svd_rank,
                      effective_far(scene), integrand_table_size(scene.image.width, scene.image.height),
                      self.ranges(index))


_renderers: dict[str | None, Renderer] = {}


def render(scene: Scene, method: str | None = None, device: str | None = None, stats: bool = False,
           progress: bool = False, reuse: bool = True):
    """Render a scene; returns (H, W, 3) float32 linear radiance, or a RenderResult with
    per-stage times and stage status when `stats=True`. `method` overrides
    `scene.render.method`; `device` is a device spec as for `--device`. Calls share one
    session per device, so consecutive frames reuse what did not change (`reuse=False`:
    compute every stage)."""
    renderer = _renderers.setdefault(device, Renderer(device))
    result = renderer.render(scene, method, progress=progress, reuse=reuse)
    return result if stats else result.image
