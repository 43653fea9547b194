"""Stage shade: surface term (shadow-map test, optional PCF), attenuation to the eye,
plus in-scattering, averaged over each pixel's samples. Host side of `cl/shade.cl`.

What shade takes besides the frame, the raster stage's buffers, the in-scattering and the
visibility comes as feature groups (`shade_features`, cl/shade_features.h), each with its
build defines and kernel arguments as the walk's (clrays/stages/features.py): the lights'
textures, the translucency stage's layers and its answer per sample, the camera's films and
the render passes' terms. A group the frame does not have adds nothing to the kernel.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..buffers import BufferDecl
from ..device import Device, StageTimer
from ..inputs import FrameBuffers, frame_sizes
from ..physics.light_texture import textured
from .features import WalkFeature, feature_args, feature_defines, present
from .raster import RasterResult

LANES = 8  # pixels per work-item, as float8 vectors (cl/shade.cl, cl/lanes.h)
# Work-items per work-group: PoCL's own choice ran about 10 % slower at 1280×720 than 64, and
# 256 no faster (bench/RESULTS.md history, "shade in lanes"). The last group's extra items return.
GROUP = 64

#: The image, where a pixel has several samples (with one, it takes the in-scattering's buffer).
IMAGE = BufferDecl("image", 16, lambda sizes: sizes.pixels)
#: The render passes' terms: three float4 per pixel (PassTerms).
PASS_TERMS = BufferDecl("render passes", 48, lambda sizes: sizes.pixels)


@dataclass(frozen=True)
class LightTextures:
    """Every light's texture, looked up per surface point (cl/light_texture.h): the packed
    light_texture_t per light and the texels (clrays.physics.light_texture.pack_light_textures)."""

    entries: object
    texels: object

    def defines(self) -> dict:
        return {"LIGHT_TEXTURE_LOOKUP": 1}

    def args(self) -> tuple:
        return self.entries, self.texels


@dataclass(frozen=True)
class SurfaceThrough:
    """With translucent layers: the translucency stage's transmittance per sample and light
    (float4), which shade reads in place of the layers' lookup where it is given (exact
    surface shadows: clrays.stages.translucency.surface_transmittance)."""

    buffer: object  # where not given, a small one the kernel is handed and does not read
    given: bool

    def defines(self) -> dict:
        return {}  # (built with the layers' TRANSLUCENT_LAYERS)

    def args(self) -> tuple:
        return self.buffer, np.int32(self.given)


@dataclass(frozen=True)
class Composite:
    """The camera's translucent films composited before each sample (clrays.stages.transparency
    `composite`): T(D) of the sample's layers and the light they add in front, float4 each."""

    transmittance: object
    in_front: object

    def defines(self) -> dict:
        return {"SHADE_TRANSPARENCY": 1}

    def args(self) -> tuple:
        return self.transmittance, self.in_front


@dataclass(frozen=True)
class PassTerms:
    """The render passes' terms per pixel (clrays.passes), three float4 that shade writes."""

    buffer: object

    def defines(self) -> dict:
        return {"SHADE_PASSES": 1}

    def args(self) -> tuple:
        return (self.buffer,)


def shade_features(device: Device, buffers: FrameBuffers, layers=None, surface_through=None,
                   films: tuple[object, object] | None = None) -> tuple[WalkFeature, ...]:
    """shade's feature groups but the passes (which `shade` adds), in cl/shade_features.h's
    order: the lights' textures where some light has one; `layers`, the translucency stage's
    (clrays.stages.translucency.Layers), with `surface_through` (its answer per sample and
    light with exact surface shadows, else None); `films`, the transparency stage's
    (transmittance, in_front) from `composite`, or None."""
    scene = buffers.inputs.scene
    texture = LightTextures(buffers.light_textures, buffers.texels) if any(map(textured, scene.lights)) else None
    through = None
    if layers is not None:
        given = surface_through is not None
        through = SurfaceThrough(surface_through if given else device.buffer(nbytes=16), given)
    return present(texture, layers, through, None if films is None else Composite(*films))


def shade(device: Device, buffers: FrameBuffers, rastered: RasterResult, scatter, timer: StageTimer,
          visible=None, features: tuple[WalkFeature, ...] = (), passes: bool = False, medium=None):
    """Returns linear radiance, (H, W, 3) float32. `visible`: the visibility stage's answer
    (float per sample and light), read where `render.surface_shadows` is `exact`.
    `features`: `shade_features`'s groups. `passes`: also return, per pixel, the terms of the
    render passes (clrays.passes) as (H, W, 3, 4) float32: (mean transmittance, nearest
    depth), (mean attenuated surface radiance, 0), (mean in-scattering, 0); only then is
    their buffer allocated. `medium`: the frame's MediumFeature (clrays.stages.medium)
    where the medium is bounded or heterogeneous, which then attenuates surfaces along the
    light's path and the camera ray (cl/shade_features.h's last group)."""
    image, sizes = buffers.inputs.scene.image, frame_sizes(buffers.inputs)
    pixels = image.width * image.height
    # With one sample per pixel each work-item writes its pixels where it read their
    # in-scattering, and nothing reads that after: the image takes the buffer over, which
    # spares a frame 16 bytes a pixel of fresh memory (on a CPU device, its page faults).
    out = scatter if image.spp == 1 else IMAGE.allocate(device, sizes)
    if visible is None:
        visible = device.buffer(nbytes=4)  # never read: the map decides
    terms = PASS_TERMS.allocate(device, sizes) if passes else None
    features = features + present(None if terms is None else PassTerms(terms), medium)
    defines = {"LANES": LANES}
    if rastered.depth_in_keys:  # (read only by the map's own surface test: stages/raster.py depth_in_keys)
        defines["SHADOW_DEPTH_IN_KEYS"] = 1
    work_items = -(-pixels // (LANES * GROUP)) * GROUP
    event = device.kernel("shade", "shade", feature_defines(features, defines))(
        device.queue, (work_items,), (GROUP,), buffers.params, buffers.views, buffers.lights, rastered.shadow_depth,
        rastered.camera_depth, rastered.tri_id, buffers.tri_vertices, buffers.tri_normal, buffers.tri_vertex_normals,
        buffers.tri_albedo, buffers.offsets, scatter, visible, out, *feature_args(features))
    timer.add("shade", event)
    radiance = device.read_in_place(out, (image.height, image.width, 4), np.float32)[..., :3]
    if terms is None:
        return radiance
    return radiance, device.read(terms, (image.height, image.width, 3, 4), np.float32)
