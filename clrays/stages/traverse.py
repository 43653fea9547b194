"""Stage traverse: per camera sample, walk the min-max trees of the two nearest slices
and add the lit runs' radiance into the scatter buffer. Host side of `cl/traverse.cl`."""
from __future__ import annotations

import numpy as np

from .. import structs
from ..device import Device, StageTimer
from ..inputs import FrameBuffers
from .integrand import C_AMPLITUDE, C_D_EL, C_G, C_S_END, C_SIGMA_T, IntegrandTables
from .raster import RasterResult
from .rectify import Epipolar

_MODES = {"table": structs.INTEGRAND_TABLE, "svd": structs.INTEGRAND_SVD, "analytic": structs.INTEGRAND_ANALYTIC}
_TRAVERSALS = {"tree": 0, "scan": 1}


def pack_integrand(tables: IntegrandTables) -> tuple[np.ndarray, np.ndarray]:
    """integrand_t and the flat float32 table data that `cl/integrand.h` reads."""
    c = tables.constants
    params = np.zeros((), dtype=structs.integrand_dtype)
    params["amplitude"] = structs.float4(c[:, C_AMPLITUDE])
    params["sigma_t"] = structs.float4(c[:, C_SIGMA_T])
    params["s_end"] = structs.float4(c[:, C_S_END])
    params["beta_min"], params["beta_max"] = tables.beta_min, tables.beta_max
    params["d_el"], params["g"] = c[0, C_D_EL], c[0, C_G]
    params["mode"] = _MODES[tables.mode]
    params["n_beta"], params["n_gamma"], params["rank"] = tables.n_beta, tables.n_gamma, tables.rank
    params["light_type"] = structs.LIGHT_DIRECTIONAL if tables.light_kind == "directional" else structs.LIGHT_POINT
    if tables.mode == "table":
        data = tables.prefix.ravel()
    elif tables.mode == "svd":
        data = np.concatenate([tables.basis_beta.ravel(), tables.prefix_gamma.ravel()])
    else:
        data = np.zeros(1)
    return params, np.ascontiguousarray(data, dtype=np.float32)


def traverse(device: Device, buffers: FrameBuffers, rastered: RasterResult, epipolar: Epipolar,
             tables: IntegrandTables, scatter, timer: StageTimer) -> None:
    """Add one light's in-scattered radiance into `scatter` (float4 per camera sample)."""
    params, data = pack_integrand(tables)
    traversal = _TRAVERSALS[buffers.inputs.scene.render.traversal]
    kernel = device.kernel("traverse", "traverse", {"TRAVERSAL": traversal})
    event = kernel(device.queue, (buffers.inputs.samples,), None, buffers.params, buffers.views, buffers.lights,
                   epipolar.buffer, epipolar.tree, device.buffer(params.reshape(1), writable=False),
                   device.buffer(data, writable=False), rastered.camera_depth, buffers.offsets, scatter)
    timer.add("traverse", event)
