"""Stage transparency_walk: the gathered films' fog in front of the opaque depth in one walk per
camera sample that meets translucent films, each stretch of fog weighted by the films'
transmittance in front of it (exact for `gathered`, MBOIT's estimate for `mboit`) less T(D) (docs/design.md, translucent surfaces: the camera side).
Host side of `cl/transparency_walk.cl` (minmax: the min-max rows' walk) and of `cl/raymarch.cl`
built with TRANSPARENCY_WEIGHTED_WALK (raymarch). Timed as transparency.fog, the work it
replaces: the in-scatter stages run up to each film (Films.add_in_scatter)."""
from __future__ import annotations

import numpy as np

from ..device import Device, StageTimer
from ..inputs import FrameBuffers
from ..scene.model import TRAVERSALS
from .integrand import DeviceIntegrand
from .features import WalkFeature, feature_args, feature_defines
from .raster import RasterResult
from .raymarch import raymarch
from .rectify import Epipolar
from .transparency import FOG_LABEL, Films, depth_range, transparency_of

#: Pieces of the ray between a sample's nearest and farthest film, even in MBOIT's warp, over
#: each of which the fog takes one weight (bench/RESULTS.md history, the camera side: the error against
#: 8-layer peeling by piece count).
WALK_PIECES = 4


def _walk_defines(buffers: FrameBuffers) -> dict:
    settings = transparency_of(buffers.inputs.scene)
    return {"TRANSPARENCY_WEIGHTED_WALK": 1, "TRANSPARENCY_LOG_WARP": int(settings.warp == "log"),
            "TRANSPARENCY_GATHERED": int(settings.type == "gathered"),
            "WALK_PIECES": WALK_PIECES}


def _film_args(buffers: FrameBuffers, films: Films) -> tuple:
    """walk_samples … moment_bias: the arguments both walks share."""
    inputs = buffers.inputs
    return (films.walk_samples, np.int32(films.walk_count), np.int32(films.slots), films.depth, films.tri,
            films.opacity, np.array(depth_range(inputs), np.float32),
            np.float32(transparency_of(inputs.scene).moment_bias))


def transparency_walk(device: Device, buffers: FrameBuffers, films: Films, epipolar: Epipolar,
                      integrand: DeviceIntegrand, timer: StageTimer, features: tuple[WalkFeature, ...] = ()) -> None:
    """Add one light's weighted fog into `films.walked` for the samples with films, walking the
    min-max rows as traverse does; `features` as for traverse."""
    if not films.walk_count:
        return
    defines = {"TRAVERSAL": TRAVERSALS.index(buffers.inputs.scene.render.traversal), **_walk_defines(buffers)}
    timer.add(FOG_LABEL, device.kernel("transparency_walk", "transparency_walk", feature_defines(features, defines))(
        device.queue, (films.walk_count,), None, buffers.params, buffers.views, buffers.lights, epipolar.buffer,
        epipolar.tree, integrand.params, integrand.data, buffers.offsets, *_film_args(buffers, films), films.walked,
        *feature_args(features)))


def transparency_march(device: Device, buffers: FrameBuffers, rastered: RasterResult, films: Films,
                       timer: StageTimer, layers=None) -> None:
    """Write every light's weighted fog into `films.walked` for the samples with films, marching
    as raymarch does, with its step spacing (`layers`: the translucency stage's, as for raymarch)."""
    if not films.walk_count:
        return
    raymarch(device, buffers, rastered, films.walked, timer, layers,
             walk=(films.walk_count, _walk_defines(buffers), _film_args(buffers, films), FOG_LABEL))
