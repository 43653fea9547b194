"""The 1D min-max mipmap method (Chen et al. 2011), per light:
rectify → minmax → integrand → traverse, accumulated into one scatter buffer."""
from __future__ import annotations

import time

import numpy as np

from .device import Device, StageTimer
from .errors import ClraysError
from .frame import FrameBuffers
from .integrand import build_integrand
from .minmax import minmax
from .raster import RasterResult
from .rectify import rectify
from .scene import DirectionalLight
from .traverse import traverse


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
            s_max=scene.camera.far if directional and render.integrand != "analytic" else None)
    except ValueError as exc:  # e.g. `analytic` where no closed form exists
        where = f"{scene.source}: " if scene.source else ""
        raise ClraysError(f"{where}render.integrand: {str(exc).removeprefix('integrand: ')}") from exc
    timer.add_host("integrand", (time.perf_counter() - start) * 1e3)
    return tables


def minmax_in_scatter(device: Device, buffers: FrameBuffers, rastered: RasterResult, timer: StageTimer):
    """In-scattered radiance per camera sample (float4 buffer), summed over lights."""
    scene, samples = buffers.inputs.scene, buffers.inputs.samples
    scatter = device.buffer(nbytes=16 * samples)
    device.fill(scatter, np.float32(0), 16 * samples)
    for index, light in enumerate(scene.lights):
        epipolar = rectify(device, buffers, rastered, index, timer)  # rectify: S[α, γ] from the shadow map
        if epipolar is None:
            continue
        minmax(device, epipolar, timer)  # minmax: the 1D min-max mipmap of every row
        tables = integrand(scene, light, epipolar, timer)  # integrand: lit interval → radiance tables
        traverse(device, buffers, rastered, epipolar, tables, scatter, timer)  # traverse: walk the trees
    return scatter
