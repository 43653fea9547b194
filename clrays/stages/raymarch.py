"""Reference raymarch: in-scattering by `render.steps` uniform samples per camera ray,
a shadow-map lookup per sample. Host side of `cl/raymarch.cl`."""
from __future__ import annotations

from ..device import Device, StageTimer
from ..inputs import FrameBuffers
from .raster import RasterResult


def raymarch(device: Device, buffers: FrameBuffers, rastered: RasterResult, scatter, timer: StageTimer,
             layers=None) -> None:
    """Write every camera sample's in-scattered radiance (float4, rgb) into `scatter`.
    `layers`: the translucency stage's, looked up per step (None: an opaque-only scene)."""
    samples = buffers.inputs.samples
    defines, extra = (layers.defines(), layers.args()) if layers is not None else (None, ())
    event = device.kernel("raymarch", "raymarch", defines)(
        device.queue, (samples,), None, buffers.params, buffers.views, buffers.lights,
        rastered.shadow_depth, rastered.camera_depth, buffers.offsets, buffers.light_textures, buffers.texels, scatter,
        *extra)
    timer.add("raymarch", event)
