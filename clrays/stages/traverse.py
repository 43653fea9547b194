"""Stage traverse: per camera sample, walk the min-max trees of the two nearest slices
and add the lit runs' radiance into the scatter buffer. Host side of `cl/traverse.cl`."""
from __future__ import annotations

from ..device import Device, StageTimer
from ..inputs import FrameBuffers
from ..scene.model import TRAVERSALS
from .integrand import DeviceIntegrand
from .features import WalkFeature, feature_args, feature_defines
from .raster import RasterResult
from .rectify import Epipolar


def traverse(device: Device, buffers: FrameBuffers, rastered: RasterResult, epipolar: Epipolar,
             integrand: DeviceIntegrand, scatter, timer: StageTimer, features: tuple[WalkFeature, ...] = ()) -> None:
    """Add one light's in-scattered radiance into `scatter` (float4 per camera sample);
    `features`: what the walk carries (clrays/stages/features.py: the light's texture, its
    rectified translucent layers), in `walk_features`'s order."""
    traversal = TRAVERSALS.index(buffers.inputs.scene.render.traversal)  # TRAVERSAL 0: tree, 1: scan
    kernel = device.kernel("traverse", "traverse", feature_defines(features, {"TRAVERSAL": traversal}))
    event = kernel(device.queue, (buffers.inputs.samples,), None, buffers.params, buffers.views, buffers.lights,
                   epipolar.buffer, epipolar.tree, integrand.params, integrand.data, rastered.camera_depth,
                   buffers.offsets, scatter, *feature_args(features))
    timer.add("traverse", event)
