"""Stage volume_moments (method `moments`): per rectified row, prefix sums of the moment
vector of S (mapped from the visible rays' β range to [0, 1]) along γ; per camera sample, the lit fraction of its γ range reconstructed
from the mean moments (4MSM, Hamburger) times the range's unshadowed radiance. Host side
of `cl/volume_moments.cl` (docs/design.md §9, the volume).

Its cost does not depend on how many shadow edges a ray crosses; its error is the
reconstruction's (light leaks where blockers at several β share a ray's range) and the
assumption that the lit texels carry the range's mean radiance.
"""
from __future__ import annotations

import numpy as np

from ..buffers import BufferDecl
from ..device import Device, StageTimer
from ..errors import ClraysError
from ..inputs import FrameBuffers, frame_sizes
from .features import WalkFeature, feature_args, feature_defines
from .integrand import DeviceIntegrand
from .raster import RasterResult
from .rectify import Epipolar

#: The moment bias of the volume's reconstruction (docs/design.md §9): as the surface
#: filters' default, the float32 mean moments being as precise as theirs.
VOLUME_MOMENT_BIAS = 3e-6
#: Equal parts of a ray's γ range, each with its own lit fraction (cl/volume_moments.cl):
#: within a part the lit texels are taken to carry the part's mean radiance, which the
#: integrand's variation along γ (extinction, phase) breaks. Measured on the single-step
#: scenes of tests/methods/test_moments.py, rel. RMSE against raymarch, directional /
#: point / spot: 1 part 42 / 13 / 11 %, 4 parts 4.1 / 3.1 / 3.5 %, 8 parts 1.3 / 2.1 /
#: 1.1 %, 16 parts 0.5 / 0.9 / 0.9 %; the cost grows with the parts.
MOMENT_CHUNKS = 8
#: Per slice and γ cell boundary, the prefix sums of the moment vector: double where the
#: device has it, else float.
MOMENT_PREFIX = {
    True: BufferDecl("moment prefix sums (double)", 32, lambda sizes: sizes.slices * (sizes.tree_gamma + 1)),
    False: BufferDecl("moment prefix sums", 16, lambda sizes: sizes.slices * (sizes.tree_gamma + 1))}


def refuse_varying_medium(scene, method: str) -> None:
    """One line for volume_moments in a bounded or heterogeneous medium (docs/media.md): its
    reconstruction weights a ray's lit fraction by the range's unshadowed radiance from the
    homogeneous integrand tables, which such a medium does not have."""
    if method == "volume_moments" and not scene.medium.homogeneous:
        raise ClraysError(f"{scene.source or 'scene'}: render.method volume_moments: medium.bounds and "
                          "medium.density need method minmax (or raymarch, exact)")


def _double_prefix(device: Device) -> bool:
    return "cl_khr_fp64" in device.device.extensions


def volume_moments(device: Device, buffers: FrameBuffers, rastered: RasterResult, epipolar: Epipolar,
                   integrand: DeviceIntegrand, scatter, timer: StageTimer, features: tuple[WalkFeature, ...] = (),
                   chunks: int = MOMENT_CHUNKS) -> None:
    """Add one light's in-scattered radiance into `scatter` (float4 per camera sample); a
    textured light's tables (`features`, stage light_texture) weight each part's radiance."""
    params = epipolar.params
    slices = int(params["slices"])
    double = _double_prefix(device)
    defines = {"PREFIX_DOUBLE": int(double), "MOMENT_CHUNKS": chunks}
    scatter_defines = feature_defines(features, defines)
    prefix = MOMENT_PREFIX[double].allocate(device, frame_sizes(buffers.inputs))
    # z = (S − β_min) / (β_max − β_min): the visible rays' β range, as wide as [0, 1] can hold
    # it, which the kernels read on the device (`epipolar.visible`).
    event = device.kernel("volume_moments", "volume_moments_prefix", defines)(
        device.queue, (slices,), None, epipolar.buffer, epipolar.tree, epipolar.visible.ranges, prefix)
    timer.add("volume_moments", event)
    event = device.kernel("volume_moments", "volume_moments_scatter", scatter_defines)(
        device.queue, (buffers.inputs.samples,), None, buffers.params, buffers.views, buffers.lights,
        epipolar.buffer, prefix, integrand.params, integrand.data, rastered.camera_depth, buffers.offsets,
        epipolar.visible.ranges, np.float32(VOLUME_MOMENT_BIAS), scatter, *feature_args(features))
    timer.add("volume_moments", event)
