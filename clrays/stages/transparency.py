"""Stage transparency: the translucent surfaces in front of each camera sample's opaque depth,
the fog's in-scattering up to each of them, and their composite (docs/design.md, translucent
surfaces: the camera side). Host side of `cl/transparency.cl`.

    layers (peel or gather) → in-scatter up to each layer (the method's own stage) → composite

The gathered types (`gathered`, `mboit`) replace the in-scatter runs up to each layer by one walk
of the fog per sample that meets films, weighted by the films' transmittance: the exact product
over the sample's list, or MBOIT's estimate (stages/transparency_walk.py).

A scene whose objects are all opaque runs none of it: the session skips the stage, and the
camera raster, which draws the opaque triangles only here, draws them all there.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from ..buffers import BufferDecl, FrameSizes
from ..device import Device, StageTimer
from ..inputs import FrameBuffers, frame_sizes
from ..scene.model import Scene, Transparency
from .features import feature_args, feature_defines, present
from .raster import RasterResult

LABEL = "transparency"
FOG_LABEL = "transparency.fog"  # the in-scatter stages run up to each layer, timed apart
#: A film's light takes a shadow ray through the translucent triangles (exact surface
#: shadows) while they are at most this many; past it, the translucency layers' lookup, as
#: before: each ray tests every one of them, for every film and light of every sample
#: (glass_row's panes split into 640 triangles: 529 against 405 ms of the stage through the
#: lookup, docs/design.md), and a translucent mesh of a million would not finish.
FILM_SHADOW_RAY_TRIANGLES = 1024
#: Most slots gathered and mboit films are counted as (`film_slots_bound`): the most layers peeling takes.
GATHERED_SLOTS_COUNTED = 64

#: Per slot and camera sample, slot-major: a film's depth, its triangle and the in-scattering up to it
#: (`FrameSizes.film_slots`: the slots the frame finds, at most peeling's layers).
FILM_DEPTH = BufferDecl("translucent films' depths", 4, lambda sizes: sizes.film_slots * sizes.samples, bound=True)
FILM_TRIANGLES = BufferDecl("translucent films' triangles", 4, lambda sizes: sizes.film_slots * sizes.samples,
                            bound=True)
FILM_SCATTER = BufferDecl("translucent films' in-scattering", 16, lambda sizes: sizes.film_slots * sizes.samples,
                          bound=True)
#: gathered and mboit: the films each camera sample meets, and the samples that meet one (MBOIT's walk).
FILM_COUNTS = BufferDecl("translucent films per sample", 4, lambda sizes: sizes.samples)
WALK_SAMPLES = BufferDecl("samples with films", 4, lambda sizes: sizes.samples, bound=True)
WALKED_FOG = BufferDecl("films' walked fog", 16, lambda sizes: sizes.samples)
#: One slot's depth and in-scattering at a time, where the in-scatter stages run per slot.
SLOT_DEPTH = BufferDecl("one film slot's depth", 4, lambda sizes: sizes.samples)
SLOT_SCATTER = BufferDecl("one film slot's in-scattering", 16, lambda sizes: sizes.samples)
#: What shade composites: T(D) of each sample's films, and the light they add in front.
FILM_TRANSMITTANCE = BufferDecl("films' transmittance", 16, lambda sizes: sizes.samples)
FILM_IN_FRONT = BufferDecl("films' light in front", 16, lambda sizes: sizes.samples)


def transparency_of(scene: Scene) -> Transparency:
    """The scene's `render.transparency`, its defaults when left out."""
    return scene.render.transparency or Transparency()


def film_slots_bound(scene: Scene) -> int:
    """The film slots a frame is counted to take per camera sample before it runs: peeling's
    layers bound them; gathered and mboit take every film a ray meets, counted as at most
    GATHERED_SLOTS_COUNTED or the translucent triangles, the fewer."""
    settings = transparency_of(scene)
    if settings.type == "depth_peeling":
        return settings.layers
    return min(len(translucent_triangles(scene)), GATHERED_SLOTS_COUNTED)


def translucent_triangles(scene: Scene) -> np.ndarray:
    """Indices of the triangles that let light through (opacity below 1 in any channel)."""
    if scene.geometry.opacity is None:
        return np.zeros(0, np.int32)
    return np.flatnonzero((scene.geometry.opacity < 1.0).any(axis=1)).astype(np.int32)


def film_triangles(inputs) -> np.ndarray:
    """The translucent triangles the camera sees as films: not a relief's, which its pre-warp
    draws into the camera depth as an opaque surface (docs/design.md)."""
    indices = translucent_triangles(inputs.scene)
    if inputs.raster_triangles is not None:
        indices = indices[indices < inputs.raster_triangles]
    return indices


def films_take_shadow_rays(inputs, films: np.ndarray) -> bool:
    """Whether the films' light comes by shadow rays through the translucent triangles
    (`render.surface_shadows: exact`, and no more than FILM_SHADOW_RAY_TRIANGLES of them),
    else by the translucency layers' lookup."""
    return inputs.scene.render.surface_shadows == "exact" and len(films) <= FILM_SHADOW_RAY_TRIANGLES


def opaque_camera_vertices(inputs) -> np.ndarray:
    """The frame's eye-space vertices with every translucent triangle collapsed onto its first
    vertex: the camera raster meets none of them (a zero-area triangle has no ray hit), so the
    camera depth is the opaque depth D the layers lie in front of."""
    vertices = inputs.tri_vertices.reshape(-1, 3, 4).copy()
    translucent = film_triangles(inputs)
    vertices[translucent] = vertices[translucent, :1]
    return vertices.reshape(-1, 4)


def depth_range(inputs) -> tuple[float, float]:
    """(nearest, farthest) distance from the eye of any point of a translucent triangle: the
    range MBOIT's warp maps to [0, 1]. The nearest is the distance to their bounding box (a
    lower bound), kept off 0 for the log warp."""
    vertices = inputs.tri_vertices.reshape(-1, 3, 4)[film_triangles(inputs), :, :3].astype(np.float64)
    points = vertices.reshape(-1, 3)
    if len(points) == 0:  # no film: the composite has nothing to warp
        return 1.0, 2.0
    far = float(np.linalg.norm(points, axis=1).max())
    lo, hi = points.min(axis=0), points.max(axis=0)
    near = float(np.linalg.norm(np.maximum(np.maximum(lo, -hi), 0.0)))
    return max(near, 1e-4 * far), max(far * (1.0 + 1e-5), near * 1.001)


class _Relabelled:
    """A StageTimer that books every event under one label: the in-scatter stages run for the
    layers count as transparency.fog, not as the frame's own raymarch or traverse."""

    def __init__(self, timer: StageTimer, label: str):
        self.timer, self.label = timer, label

    def add(self, label: str, event) -> None:
        self.timer.add(self.label, event)

    def add_host(self, label: str, milliseconds: float) -> None:
        self.timer.add_host(self.label, milliseconds)


@dataclass
class Films:
    """The translucent hits of every camera sample, slot-major (cl/transparency.cl), and the
    in-scattered radiance L(0, z_k) up to each."""

    slots: int  # slots per sample that any sample fills (0: no ray meets a translucent surface)
    depth: object  # uint[slots·samples]: as_uint(z_k), 0 in an empty slot
    tri: object  # int[slots·samples]: the layer's triangle, −1 in an empty slot
    scatter: object  # float4[slots·samples]: L(0, z_k)
    samples: int
    rastered: RasterResult
    opacity: object  # float4[triangles]: every triangle's opacity (rgb), 1 for an opaque one
    sizes: FrameSizes  # the frame's (its slot scratch: add_in_scatter)
    # MBOIT's one weighted walk (stages/transparency_walk.py; None: the in-scatter runs per slot):
    walked: object = None  # float4[samples]: ∫(T(s) − T(D)) dL(0, s), summed over the walked lights
    walk_samples: object = None  # int[walk_count]: the samples that meet a film
    walk_count: int = 0

    def add_in_scatter(self, device: Device, timer: StageTimer,
                       in_scatter: Callable[[RasterResult, object, StageTimer], None]) -> None:
        """Add one light's in-scattering up to every layer: `in_scatter(rastered, scatter,
        timer)` is the method's own stage (raymarch, traverse…) run with each slot's depths as
        the camera depth, so the layers see the fog exactly as the opaque depth does."""
        relabelled = _Relabelled(timer, FOG_LABEL)
        depth, scatter = SLOT_DEPTH.allocate(device, self.sizes), SLOT_SCATTER.allocate(device, self.sizes)
        for slot in range(self.slots):
            device.cl.enqueue_copy(device.queue, depth, self.depth, byte_count=4 * self.samples,
                                   src_offset=4 * slot * self.samples)
            device.cl.enqueue_copy(device.queue, scatter, self.scatter, byte_count=16 * self.samples,
                                   src_offset=16 * slot * self.samples)
            in_scatter(replace(self.rastered, camera_depth=depth), scatter, relabelled)
            device.cl.enqueue_copy(device.queue, self.scatter, scatter, byte_count=16 * self.samples,
                                   dst_offset=16 * slot * self.samples)


def _layer_args(buffers: FrameBuffers, rastered: RasterResult, translucent, count: int) -> tuple:
    return (buffers.params, buffers.views, buffers.offsets, rastered.camera_depth, buffers.tri_vertices, translucent,
            np.int32(count))


def translucent_films(device: Device, buffers: FrameBuffers, rastered: RasterResult, timer: StageTimer,
                      weighted_walk: bool = True) -> Films:
    """Each camera sample's translucent hits in front of its opaque depth: the `layers` nearest
    in order (depth_peeling), or all of them in no order (gathered, mboit). `weighted_walk`:
    list the samples with films for the one weighted walk of the fog (mboit, gathered);
    False: the in-scatter runs per slot, as peeling's (the tests' reference)."""
    inputs = buffers.inputs
    settings = transparency_of(inputs.scene)
    samples, sizes = inputs.samples, frame_sizes(inputs)
    indices = film_triangles(inputs)
    translucent = device.buffer(indices, writable=False)
    args = _layer_args(buffers, rastered, translucent, len(indices))
    used = device.buffer(np.zeros(1, np.int32))
    walk = {}
    if settings.type == "depth_peeling":
        slots = settings.layers
        depth, tri = _film_slots(device, sizes, slots)
        timer.add(LABEL, device.kernel("transparency", "transparency_peel")(
            device.queue, (samples,), None, *args, np.int32(slots), depth, tri, used))
        slots = int(device.read(used, 1, np.int32)[0])  # peeling stops where no sample finds another layer
    else:
        counts = FILM_COUNTS.allocate(device, sizes)
        timer.add(LABEL, device.kernel("transparency", "transparency_count")(
            device.queue, (samples,), None, *args, counts, used))
        slots = int(device.read(used, 1, np.int32)[0])
        depth, tri = _film_slots(device, sizes, slots)
        if slots:
            timer.add(LABEL, device.kernel("transparency", "transparency_gather")(
                device.queue, (samples,), None, *args, counts, np.int32(slots), depth, tri))
        if slots and weighted_walk:
            walk = films_to_walk(device, counts, sizes, timer)
    scatter = FILM_SCATTER.allocate(device, replace(sizes, film_slots=slots))
    if slots:
        device.fill(scatter, np.float32(0), 16 * slots * samples, timer, LABEL)
    # The in-scatter stages read the layers' depths as the camera depth: the same shadow maps,
    # the same camera, a slot's depth instead of the opaque one.
    opacity = np.zeros((inputs.scene.geometry.count, 4), np.float32)
    opacity[:, :3] = inputs.scene.geometry.opacity_or_ones()
    return Films(slots, depth, tri, scatter, samples, rastered, device.buffer(opacity, writable=False), sizes,
                 **walk)


def _film_slots(device: Device, sizes: FrameSizes, slots: int) -> tuple[object, object]:
    """The films' depths and triangles, `slots` per camera sample."""
    slotted = replace(sizes, film_slots=slots)
    return FILM_DEPTH.allocate(device, slotted), FILM_TRIANGLES.allocate(device, slotted)


def films_to_walk(device: Device, counts, sizes: FrameSizes, timer: StageTimer) -> dict:
    """The Films fields of MBOIT's weighted walk: the samples whose count of hits is not 0, in
    order (a host compaction of one int per sample: the fog is walked for these only), and
    their fog, zero until the walks add each light's. (The compaction counts in the frame's
    wall time, not in a stage's device time.)"""
    listed = np.flatnonzero(device.read(counts, sizes.samples, np.int32)).astype(np.int32)
    walked = WALKED_FOG.allocate(device, sizes)
    device.fill(walked, np.float32(0), WALKED_FOG.nbytes(sizes), timer, LABEL)
    return {"walked": walked, "walk_samples": WALK_SAMPLES.upload(device, listed, sizes), "walk_count": len(listed)}


def composite(device: Device, buffers: FrameBuffers, rastered: RasterResult, layers: Films,
              timer: StageTimer, light_layers=None) -> tuple[object, object]:
    """(transmittance, in_front), float4 per camera sample: T(D) of the sample's layers, and the
    light they add in front of the opaque sample (cl/transparency.cl); shade composites them.
    `light_layers`: the translucency stage's layers (clrays.stages.translucency), through which
    the light reaches each film; None: a scene without lights."""
    inputs = buffers.inputs
    settings = transparency_of(inputs.scene)
    samples = inputs.samples
    defines = {"TRANSPARENCY_MOMENTS": int(settings.type != "depth_peeling"),
               "TRANSPARENCY_GATHERED": int(settings.type == "gathered"),
               "TRANSPARENCY_LOG_WARP": int(settings.warp == "log")}
    features = present(light_layers)
    defines, light_args = feature_defines(features, defines), feature_args(features)
    films = film_triangles(inputs)  # the shadow rays' triangles (FILM_SHADOW_RAYS)
    if films_take_shadow_rays(inputs, films):  # a film's coloured shadow edges where exact has them
        defines["FILM_SHADOW_RAYS"] = 1
    if layers.walked is not None:  # the films' fog, walked once per sample (stages/transparency_walk.py)
        defines["TRANSPARENCY_WEIGHTED_WALK"] = 1
        light_args = (*light_args, layers.walked)
    sizes = frame_sizes(inputs)
    transmittance, in_front = FILM_TRANSMITTANCE.allocate(device, sizes), FILM_IN_FRONT.allocate(device, sizes)
    near, far = depth_range(inputs)
    timer.add(LABEL, device.kernel("transparency", "transparency_composite", defines)(
        device.queue, (samples,), None, buffers.params, buffers.views, buffers.offsets, buffers.lights,
        rastered.shadow_depth, buffers.tri_vertices, buffers.tri_normal, buffers.tri_albedo,
        layers.opacity, buffers.light_textures, buffers.texels, np.int32(layers.slots),
        layers.depth, layers.tri, layers.scatter, np.array([near, far], np.float32),
        np.float32(settings.moment_bias), device.buffer(films if len(films) else np.zeros(1, np.int32), writable=False),
        np.int32(len(films)), transmittance, in_front, *light_args))
    return transmittance, in_front
