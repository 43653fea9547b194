"""Stage light_depth: for a medium with a density grid, each light's optical depth ∫ρ ds from
every voxel centre of a grid over the density grid's bounds to the light (docs/media.md), so
the kernels find a sample's light transmittance e^{-σt·depth} by one trilinear lookup
(cl/medium.h `light_path_depth`). Host side of `cl/light_depth.cl`.

The optical-depth grid has the density grid's voxels, each side at most LIGHT_DEPTH_SIDE_MAX
(a coarser grid over the same bounds beyond it): optical depth along light rays is smoother
than the density (an integral of it), and the march per voxel crosses the whole grid.
"""
from __future__ import annotations

import numpy as np

from ..device import Device, StageTimer

#: The most voxels along a side of a light's optical-depth grid.
LIGHT_DEPTH_SIDE_MAX = 64


def light_depth_shape(grid_shape: tuple[int, int, int]) -> tuple[int, int, int]:
    """(nz, ny, nx) of a light's optical-depth grid for a density grid of `grid_shape`."""
    return tuple(min(int(n), LIGHT_DEPTH_SIDE_MAX) for n in grid_shape)


def light_depth(device: Device, params, density_grid, lights, light_count: int,
                shape: tuple[int, int, int], timer: StageTimer, defines: dict):
    """A device buffer of `light_count` optical-depth grids of `shape` (nz, ny, nx), float32,
    light after light; `params` the medium_t buffer, `density_grid` its values, `lights` the
    frame's light_t buffer, `defines` the medium's build defines (MEDIUM_GRID among them)."""
    count = int(np.prod(shape))
    out = device.buffer(nbytes=4 * count * max(light_count, 1))
    kernel = device.kernel("light_depth", "light_depth", defines)
    timer.add("light_depth", kernel(device.queue, (count, light_count), None, params, density_grid, lights, out))
    return out
