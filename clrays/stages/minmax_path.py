"""The 1D min-max mipmap method (Chen et al. 2011), per light:
rectify → minmax → integrand → traverse, accumulated into one scatter buffer."""
from __future__ import annotations

import time

import numpy as np

from ..scene.camera import primary_rays
from ..device import Device, StageTimer
from ..errors import ClraysError
from ..inputs import FrameBuffers
from .integrand import build_integrand
from .minmax import minmax
from ..reference.radiometry import in_scatter_segments, lamp_radius
from .raster import RasterResult
from .rectify import rectify
from ..scene.model import DirectionalLight
from .traverse import traverse


#: Integrand table size per light and frame: at 128 × 512 a segment's error is at most
#: 2e-3 (median ~1e-6, whole rays ≤ 1e-3; docs/integrand.md), far below the method's
#: visibility error, and the tables build 4× faster than at 256 × 1024.
INTEGRAND_ROWS = 128
INTEGRAND_COLUMNS = 512


def integrand(scene, light, epipolar, timer: StageTimer):
    """Stage integrand: the per-frame tables of one light, built on the host in float64."""
    start = time.perf_counter()
    render, medium = scene.render, scene.medium
    directional = isinstance(light, DirectionalLight)
    try:
        tables = build_integrand(
            render.integrand, "directional" if directional else "point", medium.sigma_s, medium.sigma_t,
            medium.phase, light.irradiance if directional else light.intensity, float(epipolar.params["d_el"]),
            epipolar.beta_min, epipolar.beta_max, epipolar.gamma_max, rank=render.svd_rank,
            n_beta=INTEGRAND_ROWS, n_gamma=INTEGRAND_COLUMNS,
            s_max=scene.camera.far if directional and render.integrand != "analytic" else None)
    except ValueError as exc:  # e.g. `analytic` where no closed form exists
        where = f"{scene.source}: " if scene.source else ""
        raise ClraysError(f"{where}render.integrand: {str(exc).removeprefix('integrand: ')}") from exc
    timer.add_host("integrand", (time.perf_counter() - start) * 1e3)
    return tables


def eye_in_lamp(scene, light) -> bool:
    """The eye is inside a point or spot light's lamp (`radiometry.lamp_radius`): d_el is
    below the lamp radius, and may be 0."""
    if isinstance(light, DirectionalLight):
        return False
    return float(np.linalg.norm(light.position - scene.camera.position)) < lamp_radius(scene)


def lamp_in_scatter(device: Device, buffers: FrameBuffers, rastered: RasterResult, light, scatter,
                    timer: StageTimer) -> None:
    """Add one light's in-scattering with the eye inside its lamp (DESIGN §6, d_el → 0).

    Epipolar coordinates need an eye–light axis, which d_el → 0 takes away; and they are not
    needed: every point the eye sees, the light sees too, so nothing visible is shadowed.
    What is left is the unshadowed integral of each sample ray over [where it leaves the
    lamp, its depth] (within the cone for a spot light), which `exact.lit_intervals` and
    `radiometry.in_scatter_segments` give in float64 on the host. The configuration is rare
    and the cost is one quadrature per sample, like `exact` without occluders."""
    from ..reference.exact import lit_intervals

    start = time.perf_counter()
    scene, samples = buffers.inputs.scene, buffers.inputs.samples
    eye = np.asarray(scene.camera.position, dtype=np.float64)
    depth = device.read(rastered.camera_depth, samples, np.uint32).view(np.float32)
    distance = np.minimum(depth.astype(np.float64), scene.camera.far)
    dirs = primary_rays(scene.camera, scene.image).reshape(-1, 3)  # sample order: pixel·spp + sample
    ray, a, b = lit_intervals(eye, dirs, distance, light, np.zeros((0, 3, 3)), lamp_radius=lamp_radius(scene))
    segments = in_scatter_segments(light, scene.medium, eye, dirs[ray], a, b)
    radiance = device.read(scatter, (samples, 4), np.float32)
    for channel in range(3):
        radiance[:, channel] += np.bincount(ray, weights=segments[:, channel], minlength=samples)
    device.cl.enqueue_copy(device.queue, scatter, radiance)
    timer.add_host("integrand", (time.perf_counter() - start) * 1e3)


def _trees(device: Device, buffers: FrameBuffers, rastered: RasterResult, index: int, timer: StageTimer):
    """One light's min-max trees, or None when no visible ray has any extent in γ."""
    epipolar = rectify(device, buffers, rastered, index, timer)  # rectify: S[α, γ] from the shadow map
    if epipolar is not None:
        minmax(device, epipolar, timer)  # minmax: the 1D min-max mipmap of every row
    return epipolar


def minmax_in_scatter(device: Device, buffers: FrameBuffers, rastered: RasterResult, timer: StageTimer,
                      reuse=None):
    """In-scattered radiance per camera sample (float4 buffer), summed over lights.

    `reuse` (a render session's, see `clrays.session`) may hand back a light's trees
    (`reuse.trees(index, build)`, build(buffers) runs rectify → minmax) or integrand
    tables (`reuse.tables(index, epipolar, build)`) kept from an earlier frame whose
    inputs to those stages were the same."""
    scene, samples = buffers.inputs.scene, buffers.inputs.samples
    scatter = device.buffer(nbytes=16 * samples)
    device.fill(scatter, np.float32(0), 16 * samples)
    for index, light in enumerate(scene.lights):
        if eye_in_lamp(scene, light):  # d_el → 0: no epipolar frame, nothing visible is shadowed
            lamp_in_scatter(device, buffers, rastered, light, scatter, timer)
            continue
        build_trees = lambda b, i=index: _trees(device, b, rastered, i, timer)  # noqa: E731
        epipolar = reuse.trees(index, build_trees) if reuse else build_trees(buffers)  # rectify → minmax
        if epipolar is None:
            continue
        build_tables = lambda: integrand(scene, light, epipolar, timer)  # noqa: E731
        tables = reuse.tables(index, epipolar, build_tables) if reuse else build_tables()  # integrand: tables
        traverse(device, buffers, rastered, epipolar, tables, scatter, timer)  # traverse: walk the trees
    return scatter
