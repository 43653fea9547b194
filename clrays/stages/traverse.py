"""Stage traverse: per camera sample, walk the min-max trees of the two nearest slices
and add the lit runs' radiance into the scatter buffer. Host side of `cl/traverse.cl`."""
from __future__ import annotations

from ..device import Device, StageTimer
from ..inputs import FrameBuffers
from ..scene.model import TRAVERSALS
from .integrand import DeviceIntegrand
from .light_texture import TextureTables, untextured_tables
from .raster import RasterResult
from .rectify import Epipolar


def traverse(device: Device, buffers: FrameBuffers, rastered: RasterResult, epipolar: Epipolar,
             integrand: DeviceIntegrand, scatter, timer: StageTimer,
             texture: TextureTables | None = None, layers=None) -> None:
    """Add one light's in-scattered radiance into `scatter` (float4 per camera sample);
    `texture`: the light's texture tables (stage light_texture; None: an untextured light);
    `layers`: its rectified translucent layers (stage translucency; None: an opaque-only scene)."""
    texture = texture if texture is not None else untextured_tables(device)
    traversal = TRAVERSALS.index(buffers.inputs.scene.render.traversal)  # TRAVERSAL 0: tree, 1: scan
    defines, extra = ({"TRAVERSAL": traversal}, ()) if layers is None else \
        ({"TRAVERSAL": traversal, **layers.defines()}, layers.args())
    kernel = device.kernel("traverse", "traverse", defines)
    event = kernel(device.queue, (buffers.inputs.samples,), None, buffers.params, buffers.views, buffers.lights,
                   epipolar.buffer, epipolar.tree, integrand.params, integrand.data, rastered.camera_depth,
                   buffers.offsets, texture.params, texture.basis, texture.prefix, scatter, *extra)
    timer.add("traverse", event)
