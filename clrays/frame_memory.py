"""What a frame's device buffers take, before any is allocated: the declarations
(clrays.buffers.BufferDecl) of the buffers each stage the frame runs allocates, at the
frame's sizes. clrays.session.check_device_memory refuses, in one line, a frame whose
largest buffer or whose sum the device cannot hold.

A frame that runs its lights in turn (clrays.light_turns) holds one light's maps, trees and
visibility at a time: the largest light's are counted. Where a stage's buffer depends on
what the device finds (the films a ray meets, the rays the maps leave) or on the device
itself (64-bit atomics, fp64), the larger is counted, so that the check errs on the safe
side.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .buffers import BufferDecl, FrameSizes
from .inputs import TEXTURE_TEXELS, FrameInputs, frame_sizes
from .light_turns import lights_in_turn
from .passes import per_light_indices
from .physics.light_texture import textured
from .stages import raster, rectify, sampling, shade, shadow_filter, translucency, transparency, visibility
from .stages.light_texture import TEXTURE_PREFIX
from .stages.relief_cuts import cuts_reliefs
from .stages.shaft_edges import EDGE_NEIGHBOURS, keeps_blockers
from .stages.volume_moments import MOMENT_PREFIX

#: The session's own (clrays.session): the in-scattered radiance per camera sample (float4),
#: and with a render pass per light under raymarch, one light's marched alone; with the
#: lights in turn, every light's visibility per camera sample, a column each.
IN_SCATTER = BufferDecl("in-scattering", 16, lambda sizes: sizes.samples)
ONE_LIGHT_IN_SCATTER = BufferDecl("one light's in-scattering", 16, lambda sizes: sizes.samples)
EVERY_LIGHT_VISIBILITY = BufferDecl("every light's visibility", 4, lambda sizes: sizes.samples * sizes.lights)


def frame_buffers(inputs: FrameInputs) -> list[tuple[str, BufferDecl, int]]:
    """(what, its declaration, bytes) of every device buffer one frame allocates that a
    stage declares, in the order of the frame (clrays.session)."""
    scene, sizes = inputs.scene, frame_sizes(inputs)
    render, method = scene.render, scene.render.method
    medium = bool(np.any(scene.medium.sigma_s > 0))
    in_turn = lights_in_turn(scene, method)
    # the lights whose own buffers are held at once: in turn, the one with the most texels
    held = [int(np.argmax(sizes.light_texels))] if in_turn and sizes.light_texels else range(len(scene.lights))
    several = len(sizes.light_texels) > 1 and not in_turn  # (every light's maps back to back as well)
    at_once = sizes if not in_turn else replace(sizes.for_light(held[0]), lights=1)  # a light in turn's frame
    out = []

    def add(decl: BufferDecl, at: FrameSizes = sizes, light: int | None = None) -> None:
        out.append((decl.name if light is None else f"{decl.name} of light {light}", decl, decl.nbytes(at)))

    def per_light(decl: BufferDecl, lights=held) -> None:
        for index in lights:
            add(decl, sizes.for_light(index), index)

    # raster: the camera's depths and triangles, and (counted always) the keys of the one-pass raster
    add(raster.CAMERA.depth)
    add(raster.CAMERA.triangles)
    add(raster.CAMERA.keys)
    add(IN_SCATTER)
    if scene.image.spp > 1:  # (with one sample per pixel the image takes the in-scattering's buffer)
        add(shade.IMAGE)
    if render.aovs:  # render passes: shade's terms; raymarch marches a light alone into its own
        add(shade.PASS_TERMS)
        if method == "raymarch" and per_light_indices(render.aovs):
            add(ONE_LIGHT_IN_SCATTER)
    add(TEXTURE_TEXELS)
    maps_are_keys = raster.depth_in_keys(scene)  # (their depths are the keys' words: no depth array)
    if not maps_are_keys:
        per_light(raster.SHADOW_MAP.depth)
        if several:
            add(raster.ATLAS["depth"])
    if keeps_blockers(render) and scene.lights:  # (stages/shaft_edges.py) each texel's nearest triangle,
        # counted as the 64-bit keys the maps keep where the device has 64-bit atomics (else 32-bit triangles)
        per_light(raster.SHADOW_MAP.keys)
        if several:
            add(raster.ATLAS["keys"])
        add(EDGE_NEIGHBOURS)
        if cuts_reliefs(inputs, True):  # the keys from before the reliefs, which the volume reads
            per_light(raster.SHADOW_MAP.keys_before_reliefs)
            if several:
                add(raster.ATLAS["volume"])
        if medium:
            per_light(rectify.ROW_BLOCKERS)
    if method in ("minmax", "volume_moments") and medium:
        per_light(rectify.TREE)
        if method == "minmax" and render.sampling == "epipolar":  # per line sample, one light at a time; fix-ups
            add(sampling.LINE_SAMPLES)
            add(sampling.LINE_RADIANCE)
            add(sampling.FIXUP_LIST)
        # a textured light's prefix sums (the rectified texture is not stored)
        per_light(TEXTURE_PREFIX, [index for index, light in enumerate(scene.lights) if textured(light)][:len(held)])
        if method == "volume_moments":  # (double where the device has it)
            per_light(MOMENT_PREFIX[True])
    if render.surface_shadows == "exact" and scene.lights:
        per_light(visibility.BOUND)
        per_light(visibility.WRITER)
        if several:
            add(visibility.BOUND_ATLAS)
            add(visibility.WRITER_ATLAS)
        for decl in (visibility.VISIBLE, visibility.MAP_READ, visibility.READ_MASK, visibility.RAY_ENTRIES):
            add(decl, at_once)
        if in_turn:
            add(EVERY_LIGHT_VISIBILITY)
        if at_once.entries <= visibility.TOUCHING_ENTRIES:  # a thumbnail's lists of every texel read
            per_light(visibility.TOUCHING_HEADS)
            for index in held:
                add(visibility.TOUCHING_NODES, at_once, index)
        # the lists of the triangles at the shadow rays' texels, made before the device knows
        # whether the rays take them: room for the most rays that may (stages/visibility.py)
        add(visibility.RAY_LIST_MASK, at_once)
        per_light(visibility.RAY_LIST_HEADS)
        for index in held:
            add(visibility.RAY_LIST_NODES, at_once, index)
    if scene.geometry.translucent and scene.lights:  # the translucency stage's layers (translucency.py)
        add(translucency.LAYER_DEPTH)
        add(translucency.LAYER_CLEAR)
        if method == "minmax" and medium:  # one light's at a time
            add(translucency.RECTIFIED_BETA)
            add(translucency.RECTIFIED_CLEAR)
        if render.surface_shadows == "exact":
            add(translucency.SURFACE_THROUGH)
    if scene.geometry.translucent:  # the transparency stage's films (transparency.py)
        films = replace(sizes, film_slots=transparency.film_slots_bound(scene))
        for decl in (transparency.FILM_DEPTH, transparency.FILM_TRIANGLES, transparency.FILM_SCATTER):
            add(decl, films)
        if transparency.transparency_of(scene).type == "depth_peeling":
            if medium:  # the in-scatter stages run per slot, one slot at a time
                add(transparency.SLOT_DEPTH)
                add(transparency.SLOT_SCATTER)
        else:  # the weighted walk's samples and fog
            for decl in (transparency.FILM_COUNTS, transparency.WALK_SAMPLES, transparency.WALKED_FOG):
                add(decl)
        add(transparency.FILM_TRANSMITTANCE)
        add(transparency.FILM_IN_FRONT)
    if render.surface_shadows == "filtered" and scene.lights:  # the moment maps and their blur's scratch
        chosen = shadow_filter.frame_filter(inputs)
        if chosen.type in shadow_filter.MOMENT_FILTERS and sizes.shadow_texels:
            add(shadow_filter.MOMENT_MAPS)
            if chosen.radius:
                add(shadow_filter.MOMENT_SCRATCH)
        add(shadow_filter.FILTERED_VISIBILITY)
    return out


def frame_buffer_bytes(inputs: FrameInputs) -> list[tuple[str, int]]:
    """(what, bytes) of the device buffers one frame allocates, before allocating them
    (`frame_buffers`)."""
    return [(what, size) for what, _, size in frame_buffers(inputs)]
