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


def _trees(device: Device, buffers: FrameBuffers, rastered: RasterResult, index: int, timer: StageTimer):
    """One light's min-max trees, or None when no visible ray has any extent in γ."""
    epipolar = rectify(device, buffers, rastered, index, timer)  # rectify: S[α, γ] from the shadow map
    if epipolar is not None:
        minmax(device, epipolar, timer)  # minmax: the 1D min-max mipmap of every row
    return epipolar


def minmax_in_scatter(device: Device, buffers: FrameBuffers, rastered: RasterResult, timer: StageTimer,
                      reuse=None):
    """In-scattered radiance per camera sample (float4 buffer), summed over lights.

    `reuse` (a render session's, see `clrays.renderer`) may hand back a light's trees
    (`reuse.trees(index, build)`, build(buffers) runs rectify → minmax) or integrand
    tables (`reuse.tables(index, epipolar, build)`) kept from an earlier frame whose
    inputs to those stages were the same."""
    scene, samples = buffers.inputs.scene, buffers.inputs.samples
    scatter = device.buffer(nbytes=16 * samples)
    device.fill(scatter, np.float32(0), 16 * samples)
    for index, light in enumerate(scene.lights):
        build_trees = lambda b, i=index: _trees(device, b, rastered, i, timer)  # noqa: E731
        epipolar = reuse.trees(index, build_trees) if reuse else build_trees(buffers)  # rectify → minmax
        if epipolar is None:
            continue
        build_tables = lambda: integrand(scene, light, epipolar, timer)  # noqa: E731
        tables = reuse.tables(index, epipolar, build_tables) if reuse else build_tables()  # integrand: tables
        traverse(device, buffers, rastered, epipolar, tables, scatter, timer)  # traverse: walk the trees
    return scatter
