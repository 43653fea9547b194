"""Reference raymarch: in-scattering by `render.steps` samples per camera ray and light,
equiangular about a point or spot light or uniform (`render.step_spacing`), a shadow-map
lookup per sample. Host side of `cl/raymarch.cl`."""
from __future__ import annotations

from ..device import Device, StageTimer
from ..inputs import FrameBuffers
from ..scene.model import STEP_SPACINGS
from .features import feature_args, feature_defines, present
from .raster import RasterResult


def raymarch(device: Device, buffers: FrameBuffers, rastered: RasterResult, scatter, timer: StageTimer,
             layers=None, walk=None, only_light: int | None = None) -> None:
    """Write every camera sample's in-scattered radiance (float4, rgb) into `scatter`.
    `layers`: the translucency stage's, looked up per step (None: an opaque-only scene).
    `walk`: (work items, defines, arguments, label) of MBOIT's weighted fog march
    (clrays.stages.transparency_walk), which marches only the samples with films.
    `only_light`: march that light alone (a render pass of its in-scattering)."""
    work_items, label = buffers.inputs.samples, "raymarch"
    # STEP_SPACING 0: equiangular, 1: uniform (clrays.structs.STEP_SPACING_*)
    features = present(layers)
    defines = feature_defines(features, {"STEP_SPACING": STEP_SPACINGS.index(buffers.inputs.scene.render.step_spacing)})
    extra = feature_args(features)
    if only_light is not None:
        defines = {**defines, "ONLY_LIGHT": only_light}
    if walk is not None:
        work_items, walk_defines, walk_args, label = walk
        defines, extra = {**defines, **walk_defines}, (*extra, *walk_args)
    event = device.kernel("raymarch", "raymarch", defines)(
        device.queue, (work_items,), None, buffers.params, buffers.views, buffers.lights,
        rastered.shadow_depth, rastered.camera_depth, buffers.offsets, buffers.light_textures, buffers.texels, scatter,
        *extra)
    timer.add(label, event)
