"""Stage minmax: the 1D min-max mipmap of every rectified row, reduced on the device,
one work-item per row and one launch for all levels. Host side of `cl/minmax.cl`."""
from __future__ import annotations

from ..device import Device, StageTimer
from .rectify import Epipolar


def minmax(device: Device, epipolar: Epipolar, timer: StageTimer) -> None:
    """Fill levels 1..log2(N) of `epipolar.tree` from level 0, in place."""
    slices = int(epipolar.params["slices"])
    # One work-item per slice, all levels (cl/minmax.cl).
    event = device.kernel("minmax", "minmax_reduce")(device.queue, (slices,), None, epipolar.buffer, epipolar.tree)
    timer.add("minmax", event)
    epipolar.levels_built = True
