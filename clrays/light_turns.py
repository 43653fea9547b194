"""Lights in turn (docs/design.md §4.9): a frame of several lights runs each light's stages,
raster.shadow → volume → visibility, through one light's buffers at a time and adds what
the light gives to the frame's in-scattering and visibility, so its device memory follows
one light's shadow map, bound maps and trees, not the light count.

Each light's stages see the frame as if that light were its only one (`one_light_inputs`):
the same kernels on the same values, so every light's in-scattering and visibility, and
the image, are the bits of the frame that holds all its lights at once. Shade then runs
once over every light, reading each one's visibility from the frame's (samples × lights)
buffer, as before.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .device import Device
from .inputs import FrameBuffers, FrameInputs
from .scene.model import Scene


def lights_in_turn(scene: Scene, method: str) -> bool:
    """Whether a frame runs its lights in turn: with more than one light, for the epipolar
    methods (minmax, volume_moments) with exact surface shadows, in an opaque scene without
    reliefs. Otherwise the frame holds every light's maps at once, as shade's own map test
    (`map`, `pcf`), the moment maps (`filtered`), raymarch's march over every light, the
    translucent layers and a relief's cuts read them all together."""
    return (len(scene.lights) > 1 and method in ("minmax", "volume_moments")
            and scene.render.surface_shadows == "exact" and not scene.geometry.translucent
            and not scene.geometry.reliefs)


def one_light_inputs(inputs: FrameInputs, index: int) -> FrameInputs:
    """The frame's inputs with light `index` alone, in eye space: the camera view, then the
    light's views with depth offsets from 0 (its own shadow map's addresses), one light
    whose views start at 1, `light_count` 1 and the light's texture record. Kept on
    `inputs` per light (not a field: `replace` starts afresh)."""
    kept = inputs.__dict__.setdefault("_one_light", {})
    if index not in kept:
        first, count = inputs.light_views[index]
        views = inputs.views[first:first + count].copy()
        views["depth_offset"] -= views["depth_offset"][0]
        light = inputs.lights[index:index + 1].copy()
        light["first_view"] = 1
        params = inputs.params.copy()
        params["light_count"] = 1
        textures = None if inputs.light_textures is None else inputs.light_textures[index:index + 1].copy()
        kept[index] = replace(
            inputs, scene=replace(inputs.scene, lights=(inputs.scene.lights[index],)),
            views=np.concatenate([inputs.views[:1], views]),
            view_needed=np.concatenate([[True], inputs.view_needed[first:first + count]]),
            lights=light, params=params, shadow_texels=int((views["width"] * views["height"]).sum()),
            light_anchor_ws=inputs.light_anchor_ws[index:index + 1], light_textures=textures)
    return kept[index]


def one_light_buffers(device: Device, buffers: FrameBuffers, index: int) -> FrameBuffers:
    """The frame's buffers with light `index` alone (`one_light_inputs`): its own views,
    light, frame parameters and texture record; the triangles and texels are the frame's."""
    inputs = one_light_inputs(buffers.inputs, index)
    upload = lambda array: device.buffer(array, writable=False)
    return replace(buffers, inputs=inputs, views=upload(inputs.views), lights=upload(inputs.lights),
                   params=upload(inputs.params.reshape(1)),
                   light_textures=None if inputs.light_textures is None else upload(inputs.light_textures))


def add_visibility_column(device: Device, whole, part, index: int, lights: int, samples: int) -> None:
    """Copy one light's visibility (float per sample) into column `index` of the frame's
    (float per sample and light, sample-major: what shade reads), on the device."""
    device.cl.enqueue_copy(device.queue, whole, part, src_origin=(0, 0), dst_origin=(4 * index, 0),
                           region=(4, samples), src_pitches=(4,), dst_pitches=(4 * lights,))


class RaysSum:
    """The shadow rays of every light's visibility (ints, or counts read from the device
    when asked for: clrays.stages.visibility.RayCount)."""

    def __init__(self, parts: list):
        self.parts = parts

    def __int__(self) -> int:
        return sum(int(part) for part in self.parts)
