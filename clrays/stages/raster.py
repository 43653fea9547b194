"""Stage raster: triangles → camera depth and triangle ids, and every light's shadow map.

Host side of `cl/raster.cl`. Depth is stored as the uint bits of a positive float
(so `atomic_min` orders it) and starts at +inf (nothing hit).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import structs
from ..device import Device, StageTimer
from ..inputs import FrameBuffers


@dataclass
class RasterResult:
    camera_depth: object  # uint[H·W·spp]: as_uint(distance along the sample ray)
    tri_id: object  # int[H·W·spp]: nearest triangle, -1 where nothing was hit
    shadow_depth: object  # uint[shadow_texels]: every light's views, back to back


def _rasterize(device: Device, buffers: FrameBuffers, view_index: int, offsets, sample_count: int,
               depth, timer: StageTimer) -> None:
    kernel = device.kernel("raster", "raster_depth")
    count = buffers.inputs.tri_vertices.shape[0] // 3
    if count == 0:
        return
    event = kernel(device.queue, (count,), None, buffers.tri_vertices, np.int32(count),
                                 buffers.views, np.int32(view_index), offsets, np.int32(sample_count), depth)
    timer.add("raster", event)


def _atomic64(device: Device) -> bool:
    return "cl_khr_int64_extended_atomics" in device.device.extensions


def raster_camera(device: Device, buffers: FrameBuffers, timer: StageTimer) -> tuple[object, object]:
    """Camera depth and triangle id of every sample of every pixel."""
    inputs = buffers.inputs
    samples, spp = inputs.samples, inputs.scene.image.spp
    camera_depth = device.buffer(nbytes=4 * samples)
    tri_id = device.buffer(nbytes=4 * samples)
    count = inputs.tri_vertices.shape[0] // 3
    if _atomic64(device):
        # One pass: depth and triangle packed into a 64-bit key, then split.
        defines = {"RASTER_ATOMIC64": 1}
        nearest = device.buffer(nbytes=8 * samples)
        device.fill(nearest, np.uint64((int(structs.DEPTH_EMPTY) << 32) | 0xFFFFFFFF), 8 * samples, timer, "raster")
        if count:
            timer.add("raster", device.kernel("raster", "raster_nearest", defines)(
                device.queue, (count,), None, buffers.tri_vertices, np.int32(count), buffers.views, np.int32(0),
                buffers.offsets, np.int32(spp), nearest))
        timer.add("raster", device.kernel("raster", "raster_split", defines)(
            device.queue, (samples,), None, nearest, np.int32(samples), camera_depth, tri_id))
        return camera_depth, tri_id
    device.fill(camera_depth, structs.DEPTH_EMPTY, 4 * samples, timer, "raster")
    device.fill(tri_id, np.int32(-1), 4 * samples, timer, "raster")
    _rasterize(device, buffers, 0, buffers.offsets, spp, camera_depth, timer)
    if count:
        event = device.kernel("raster", "raster_resolve")(
            device.queue, (count,), None, buffers.tri_vertices, np.int32(count), buffers.views, np.int32(0),
            buffers.offsets, np.int32(spp), camera_depth, tri_id)
        timer.add("raster", event)
    return camera_depth, tri_id


def raster_shadow_maps(device: Device, buffers: FrameBuffers, timer: StageTimer):
    """Every light's shadow-map views, back to back in one depth buffer."""
    inputs = buffers.inputs
    texels = max(inputs.shadow_texels, 1)
    shadow_depth = device.buffer(nbytes=4 * texels)
    device.fill(shadow_depth, structs.DEPTH_EMPTY, 4 * texels, timer, "raster")
    centre = device.buffer(np.array([[0.5, 0.5]], dtype=np.float32), writable=False)
    for view_index in range(1, len(inputs.views)):
        _rasterize(device, buffers, view_index, centre, 1, shadow_depth, timer)
    return shadow_depth


def raster(device: Device, buffers: FrameBuffers, timer: StageTimer) -> RasterResult:
    """Rasterize the camera view (every sample of every pixel) and all shadow-map views."""
    camera_depth, tri_id = raster_camera(device, buffers, timer)
    return RasterResult(camera_depth, tri_id, raster_shadow_maps(device, buffers, timer))
