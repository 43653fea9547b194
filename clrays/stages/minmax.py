"""Stage minmax: the 1D min-max mipmap of every rectified row, by parallel reduction
on the device, one launch per level. Host side of `cl/minmax.cl`."""
from __future__ import annotations

import numpy as np

from ..device import Device, StageTimer
from .rectify import Epipolar


def minmax(device: Device, epipolar: Epipolar, timer: StageTimer) -> None:
    """Fill levels 1..log2(N) of `epipolar.tree` from level 0, in place."""
    n, slices = int(epipolar.params["gamma_samples"]), int(epipolar.params["slices"])
    kernel = device.kernel("minmax", "minmax_reduce")
    for level in range(1, int(epipolar.params["levels"]) + 1):
        event = kernel(device.queue, (n >> level, slices), None, epipolar.buffer, np.int32(level), epipolar.tree)
        timer.add("minmax", event)
    epipolar.levels_built = True
