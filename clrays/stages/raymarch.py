"""Reference raymarch: in-scattering by `render.steps` uniform samples per camera ray,
a shadow-map lookup per sample. Host side of `cl/raymarch.cl`."""
from __future__ import annotations

from ..device import Device, StageTimer
from ..inputs import FrameBuffers
from .raster import RasterResult


def raymarch(device: Device, buffers: FrameBuffers, rastered: RasterResult, scatter, timer: StageTimer) -> None:
    """Write every camera sample's in-scattered radiance (float4, rgb) into `scatter`."""
    samples = buffers.inputs.samples
    event = device.kernel("raymarch", "raymarch")(
        device.queue, (samples,), None, buffers.params, buffers.views, buffers.lights,
        rastered.shadow_depth, rastered.camera_depth, buffers.offsets, buffers.light_textures, buffers.texels, scatter)
    timer.add("raymarch", event)
