"""Reference raymarch: in-scattering by `render.steps` uniform samples per camera ray,
a shadow-map lookup per sample. Host side of `cl/raymarch.cl`."""
from __future__ import annotations

from ..device import Device, StageTimer
from ..inputs import FrameBuffers
from .raster import RasterResult


def raymarch(device: Device, buffers: FrameBuffers, rastered: RasterResult, timer: StageTimer):
    """Returns the scatter buffer: one float4 (rgb radiance) per camera sample."""
    samples = buffers.inputs.samples
    scatter = device.buffer(nbytes=16 * samples)
    event = device.kernel("raymarch", "raymarch")(
        device.queue, (samples,), None, buffers.params, buffers.views, buffers.lights,
        rastered.shadow_depth, rastered.camera_depth, buffers.offsets, scatter)
    timer.add("raymarch", event)
    return scatter
