"""The eye inside a point or spot light's lamp (docs/design.md §6, d_el → 0): the minmax
method's in-scattering for that light, without epipolar coordinates, on the host in
float64. Timed as the stage `lamp`."""
from __future__ import annotations

import time

import numpy as np

from ..device import Device, StageTimer
from ..inputs import FrameBuffers
from ..physics.light_texture import textured, textured_in_scatter
from ..physics.radiometry import effective_far, in_scatter_segments, lamp_radius
from ..scene.camera import from_ray_starts, primary_rays, ray_starts
from ..scene.model import DirectionalLight
from .raster import RasterResult


def eye_in_lamp(scene, light) -> bool:
    """The eye is inside a point or spot light's lamp (`radiometry.lamp_radius`): d_el is
    below the lamp radius, and may be 0."""
    if isinstance(light, DirectionalLight):
        return False
    return float(np.linalg.norm(light.position - scene.camera.position)) < lamp_radius(scene)


def lamp_in_scatter(device: Device, buffers: FrameBuffers, rastered: RasterResult, light, scatter,
                    timer: StageTimer) -> None:
    """Add one light's in-scattering with the eye inside its lamp (docs/design.md §6, d_el → 0).

    Epipolar coordinates need an eye–light axis, which d_el → 0 takes away; and they are not
    needed: every point the eye sees, the light sees too, so nothing visible is shadowed.
    What is left is the unshadowed integral of each sample ray over [where it leaves the
    lamp, its depth] (within the cone for a spot light), which `physics.geometry.lit_intervals` and
    `radiometry.in_scatter_segments` give in float64 on the host. The configuration is rare
    and the cost is one quadrature per sample, like `exact` without occluders."""
    from ..physics.geometry import lit_intervals

    start = time.perf_counter()
    scene, samples = buffers.inputs.scene, buffers.inputs.samples
    eye = np.asarray(scene.camera.position, dtype=np.float64)
    depth = device.read(rastered.camera_depth, samples, np.uint32).view(np.float32)
    distance = np.minimum(depth.astype(np.float64), effective_far(scene))
    dirs = primary_rays(scene.camera, scene.image).reshape(-1, 3)  # sample order: pixel·spp + sample
    ray, a, b = lit_intervals(eye, dirs, distance, light, np.zeros((0, 3, 3)), lamp_radius=lamp_radius(scene))
    ray, a, b = from_ray_starts(ray, a, b, ray_starts(scene.camera, dirs))  # camera.near (shade: e^{σt·t0})
    if textured(light):  # docs/light-textures.md: exact's integral, cut at texel centres
        segments = textured_in_scatter(light, scene.medium, eye, dirs[ray], a, b)
    else:
        segments = in_scatter_segments(light, scene.medium, eye, dirs[ray], a, b)
    radiance = device.read(scatter, (samples, 4), np.float32)
    for channel in range(3):
        radiance[:, channel] += np.bincount(ray, weights=segments[:, channel], minlength=samples)
    device.cl.enqueue_copy(device.queue, scatter, radiance)
    timer.add_host("lamp", (time.perf_counter() - start) * 1e3)
