"""Stage shade: surface term (shadow-map test, optional PCF), attenuation to the eye,
plus in-scattering, averaged over each pixel's samples. Host side of `cl/shade.cl`."""
from __future__ import annotations

import numpy as np

from ..device import Device, StageTimer
from ..inputs import FrameBuffers
from .raster import RasterResult

LANES = 8  # pixels per work-item, as float8 vectors (cl/shade.cl, cl/lanes.h)
# Work-items per work-group: PoCL's own choice ran about 10 % slower at 1280×720 than 64, and
# 256 no faster (bench/RESULTS.md, "shade in lanes"). The last group's extra items return.
GROUP = 64


def shade(device: Device, buffers: FrameBuffers, rastered: RasterResult, scatter, timer: StageTimer,
          visible=None, layers=None, surface_through=None, transparency=None, passes: bool = False, medium=None):
    """Returns linear radiance, (H, W, 3) float32. `visible`: the visibility stage's answer
    (float per sample and light), read where `render.surface_shadows` is `exact`.
    `transparency`: the transparency stage's (transmittance, in_front) buffers, which a scene
    with translucent objects composites with (clrays.stages.transparency); None otherwise.
    `passes`: also return, per pixel, the terms of the render passes (clrays.passes) as
    (H, W, 3, 4) float32: (mean transmittance, nearest depth), (mean attenuated surface
    radiance, 0), (mean in-scattering, 0); only then is their buffer allocated.
    `medium`: the frame's MediumFeature (clrays.stages.medium) where the medium is bounded or
    heterogeneous, which then attenuates surfaces along the light's path and the camera ray."""
    image = buffers.inputs.scene.image
    pixels = image.width * image.height
    # With one sample per pixel each work-item writes its pixels where it read their
    # in-scattering, and nothing reads that after: the image takes the buffer over, which
    # spares a frame 16 bytes a pixel of fresh memory (on a CPU device, its page faults).
    out = scatter if image.spp == 1 else device.buffer(nbytes=16 * pixels)
    if visible is None:
        visible = device.buffer(nbytes=4)  # never read: the map decides
    # A scene with translucent objects: the light's transmittance per surface sample (translucency stage).
    # `surface_through`: the translucency stage's per sample and light, with exact surface shadows.
    defines, extra = None, ()
    if layers is not None:
        given = surface_through is not None
        defines = layers.defines()
        extra = layers.args() + (surface_through if given else device.buffer(nbytes=16), np.int32(given))
    if transparency is not None:  # the camera's translucent films (clrays.stages.transparency)
        defines = {**(defines or {}), "SHADE_TRANSPARENCY": 1}
        extra = extra + tuple(transparency)
    terms = None
    if passes:
        terms = device.buffer(nbytes=48 * pixels)
        defines, extra = {**(defines or {}), "SHADE_PASSES": 1}, extra + (terms,)
    if medium is not None:
        defines, extra = {**(defines or {}), **medium.defines()}, extra + medium.args()
    work_items = -(-pixels // (LANES * GROUP)) * GROUP
    if rastered.depth_in_keys:  # (read only by the map's own surface test: stages/raster.py depth_in_keys)
        defines = {**(defines or {}), "SHADOW_DEPTH_IN_KEYS": 1}
    event = device.kernel("shade", "shade", {**(defines or {}), "LANES": LANES})(
        device.queue, (work_items,), (GROUP,), buffers.params, buffers.views, buffers.lights, rastered.shadow_depth,
        rastered.camera_depth, rastered.tri_id, buffers.tri_vertices, buffers.tri_normal, buffers.tri_vertex_normals,
        buffers.tri_albedo, buffers.offsets, scatter, visible, buffers.light_textures, buffers.texels, out, *extra)
    timer.add("shade", event)
    radiance = device.read_in_place(out, (image.height, image.width, 4), np.float32)[..., :3]
    if terms is None:
        return radiance
    return radiance, device.read(terms, (image.height, image.width, 3, 4), np.float32)
