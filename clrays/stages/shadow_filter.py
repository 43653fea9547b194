"""Stage shadow_filter: filtered surface shadows (`render.surface_shadows: filtered`, the
filter `render.shadow_filter`). Host side of `cl/shadow_filter.cl` (docs/design.md §9).

After raster, for the moment filters (`vsm`, `msm_hamburger`, `msm_hausdorff`), each
light's shadow map becomes a map of moment vectors (z, z², z³, z⁴) of its depths
normalised to the light's [near, far], prefiltered on the device by a separable box blur
of `radius` texels, across cube faces' seams. Then, per camera sample and light, the
visibility is reconstructed from the blurred moments of the sample's texel (or, for
`hard` and `pcf`, taken from the depths themselves), and shade reads it as it reads the
visibility stage's answer.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import structs
from ..buffers import BufferDecl
from ..device import Device, StageTimer
from ..inputs import FrameBuffers, FrameInputs, frame_sizes
from ..scene.model import ShadowFilter
from .raster import RasterResult

#: `render.shadow_filter.type` → cl/shadow_filter.cl's SHADOW_FILTER option.
FILTER_CODES = {"hard": structs.SHADOW_FILTER_HARD, "pcf": structs.SHADOW_FILTER_PCF,
                "vsm": structs.SHADOW_FILTER_VSM, "msm_hamburger": structs.SHADOW_FILTER_MSM_HAMBURGER,
                "msm_hausdorff": structs.SHADOW_FILTER_MSM_HAUSDORFF}
MOMENT_FILTERS = ("vsm", "msm_hamburger", "msm_hausdorff")
#: Every light's moment maps (float4 per texel of the shadow atlas), and their blur's scratch.
MOMENT_MAPS = BufferDecl("moment maps", 16, lambda sizes: sizes.shadow_texels)
MOMENT_SCRATCH = BufferDecl("moment maps' blur scratch", 16, lambda sizes: sizes.shadow_texels)
#: The lit fraction of each camera sample for each light.
FILTERED_VISIBILITY = BufferDecl("filtered visibility", 4, lambda sizes: sizes.entries)

#: The normalised far end sits this much past the farthest vertex, so that an empty
#: texel (z = 1) is behind every receiver, even one on the farthest vertex.
FAR_MARGIN = 1.01


def frame_filter(inputs: FrameInputs) -> ShadowFilter:
    """The frame's filter: `render.shadow_filter`, or its defaults where a scene built in
    Python asks for `surface_shadows: filtered` without one."""
    return inputs.scene.render.shadow_filter or ShadowFilter()


def depth_ranges(inputs: FrameInputs) -> np.ndarray:
    """(lights, 2) float32: each light's (near, 1 / (far − near)), which map its map's
    depths onto [0, 1] for the moments. Depth is the distance from the light (perspective
    views; near = 0, since a plane can pass nearer than any vertex) or the distance along
    the view's forward (orthographic: exact from the vertices, depth being linear)."""
    vertices = inputs.tri_vertices[:, :3].astype(np.float64)
    ranges = np.zeros((max(len(inputs.scene.lights), 1), 2), dtype=np.float32)
    ranges[:, 1] = 1.0
    for index, (first, _) in enumerate(inputs.light_views):
        view = inputs.views[first]
        origin = view["origin"][:3].astype(np.float64)
        if not len(vertices):
            continue
        if view["projection"] == structs.PROJECTION_ORTHOGRAPHIC:
            depth = (vertices - origin) @ view["forward"][:3].astype(np.float64)
            near = float(depth.min())
        else:
            depth = np.linalg.norm(vertices - origin, axis=1)
            near = 0.0
        far = near + max(float(depth.max()) - near, 1e-6) * FAR_MARGIN
        ranges[index] = near, 1.0 / (far - near)
    return ranges


@dataclass
class MomentMaps:
    """The blurred moment maps of every light, an atlas indexed as the shadow depths are."""

    moments: object  # float4 per shadow texel
    depth_range: object  # float2 per light: (near, 1 / (far − near))


def view_needed_buffer(device: Device, inputs: FrameInputs):
    """int per view: 1 where raster drew it (the frame reads it), as the kernels test it."""
    return device.buffer(inputs.view_needed.astype(np.int32), writable=False)


def shadow_filter_moments(device: Device, buffers: FrameBuffers, rastered: RasterResult,
                          timer: StageTimer) -> MomentMaps:
    """Write and prefilter the moment maps of every light (none are written for `hard` and
    `pcf`, which read the depths: then `moments` is a placeholder)."""
    inputs = buffers.inputs
    chosen = frame_filter(inputs)
    ranges = depth_ranges(inputs)
    depth_range = device.buffer(ranges, writable=False)
    if chosen.type not in MOMENT_FILTERS or not inputs.shadow_texels:
        return MomentMaps(device.buffer(nbytes=16), depth_range)
    sizes = frame_sizes(inputs)
    moments = MOMENT_MAPS.allocate(device, sizes)
    scratch = MOMENT_SCRATCH.allocate(device, sizes) if chosen.radius else None
    needed = view_needed_buffer(device, inputs)
    write = device.kernel("shadow_filter", "shadow_filter_moments")
    blur = device.kernel("shadow_filter", "shadow_filter_blur")
    for index, (first, count) in enumerate(inputs.light_views):
        views = inputs.views[first:first + count]
        first_texel, texels = int(views["depth_offset"][0]), int((views["width"] * views["height"]).sum())
        timer.add("shadow_filter", write(device.queue, (texels,), None, rastered.shadow_depth, np.int32(first_texel),
                                         np.int32(texels), np.float32(ranges[index, 0]), np.float32(ranges[index, 1]),
                                         moments))
        if not chosen.radius:
            continue
        # Rows of every view first, then columns: a column pass across a seam reads the
        # neighbouring face's rows already blurred. Faces the frame does not read are skipped.
        for axis, source, target in ((0, moments, scratch), (1, scratch, moments)):
            for view_index in range(first, first + count):
                if not inputs.view_needed[view_index]:
                    continue
                face_texels = int(inputs.views[view_index]["width"] * inputs.views[view_index]["height"])
                timer.add("shadow_filter", blur(device.queue, (face_texels,), None, buffers.views, buffers.lights,
                                                needed, np.int32(index), np.int32(view_index),
                                                np.int32(chosen.radius), np.int32(axis), source, target))
    return MomentMaps(moments, depth_range)


def shadow_filter(device: Device, buffers: FrameBuffers, rastered: RasterResult, maps: MomentMaps,
                  timer: StageTimer):
    """float[samples × lights]: the lit fraction of each camera sample for each light."""
    inputs = buffers.inputs
    chosen = frame_filter(inputs)
    visible = FILTERED_VISIBILITY.allocate(device, frame_sizes(inputs))
    kernel = device.kernel("shadow_filter", "shadow_filter_visibility", {"SHADOW_FILTER": FILTER_CODES[chosen.type]})
    event = kernel(device.queue, (inputs.samples,), None, buffers.params, buffers.views,
                   view_needed_buffer(device, inputs), buffers.lights,
                   rastered.shadow_depth, maps.moments, maps.depth_range, rastered.camera_depth, rastered.tri_id,
                   buffers.tri_normal, buffers.offsets, np.int32(chosen.radius), np.float32(chosen.depth_bias),
                   np.float32(chosen.moment_bias), visible)
    timer.add("shadow_filter", event)
    return visible
