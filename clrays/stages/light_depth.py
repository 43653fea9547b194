"""Stage light_depth: for a medium with a density grid, each light's optical depth ∫ρ ds from
every node of a grid spanning the density grid's bounds to the light (docs/media.md), so the
kernels find a sample's light transmittance e^{-σt·depth} by one trilinear lookup
(cl/medium.h `light_path_depth`). Host side of `cl/light_depth.cl`.

Along each axis the optical-depth grid has LIGHT_DEPTH_INTERVALS_PER_VOXEL intervals a voxel,
between LIGHT_DEPTH_SIDE_MIN and LIGHT_DEPTH_SIDE_MAX, the first and last node on the bounds:
across light rays the optical depth varies as fast as the density does, so a fine grid needs
nodes finer than its voxels (scenes/smoke.yaml, 48×32×48 voxels, raymarch against exact: 2.8 %
with 32 intervals a side, 1.4 % with one a voxel, 1.0 % with two, where the same box without
the grid reads 0.9 %), and a coarse grid's are finer still (its depth bends within a voxel
where light rays cross it obliquely: with 16 intervals the eye's depth on a 4³ grid was 2.7 %
off at worst, with 32, 0.39 %). The largest grids are capped for cost (each node's march
crosses the whole grid). Each node marches in quarter-voxel steps (cl/light_depth.cl).

The eye has one too, after the lights' (medium_t.eye_depth_index): a camera ray's T_e to a
point in the grid is then one lookup rather than a march through every voxel on the way.
"""
from __future__ import annotations

import numpy as np

from ..device import Device, StageTimer

#: The fewest and most intervals between nodes along a side of a light's optical-depth grid.
LIGHT_DEPTH_SIDE_MIN = 32
LIGHT_DEPTH_SIDE_MAX = 96
#: Intervals between nodes per voxel of the density grid (within the bounds above).
LIGHT_DEPTH_INTERVALS_PER_VOXEL = 2


def light_depth_shape(grid_shape: tuple[int, int, int]) -> tuple[int, int, int]:
    """(nz, ny, nx) nodes of a light's optical-depth grid for a density grid of `grid_shape`."""
    return tuple(min(max(LIGHT_DEPTH_INTERVALS_PER_VOXEL * int(n), LIGHT_DEPTH_SIDE_MIN), LIGHT_DEPTH_SIDE_MAX) + 1
                 for n in grid_shape)


def light_depth(device: Device, params, density_grid, lights, light_count: int,
                shape: tuple[int, int, int], timer: StageTimer, defines: dict):
    """A device buffer of `light_count` + 1 optical-depth grids of `shape` (nz, ny, nx), float32,
    light after light and the eye's last (`params`' eye_depth_index is `light_count`); `params`
    the medium_t buffer, `density_grid` its values, `lights` the frame's light_t buffer,
    `defines` the medium's build defines (MEDIUM_GRID among them)."""
    count = int(np.prod(shape))
    out = device.buffer(nbytes=4 * count * (light_count + 1))
    kernel = device.kernel("light_depth", "light_depth", defines)
    timer.add("light_depth", kernel(device.queue, (count, light_count + 1), None, params, density_grid, lights, out))
    return out
