"""A bounded or heterogeneous medium as a feature of the kernels that sample the medium
(docs/media.md; the device side is cl/medium.h): its build defines (MEDIUM_BOUNDED,
MEDIUM_HEIGHT, MEDIUM_GRID) and its kernel arguments (MEDIUM_ARGS: the medium_t, the density
grid, the lights' and the eye's optical-depth grids), as the features of clrays.stages.features offer them.

A homogeneous medium (`Medium.homogeneous`) has no feature: `medium_feature` returns None,
the kernels build without the defines and keep their bits.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import structs
from ..device import Device, StageTimer
from ..inputs import FrameBuffers
from ..scene.model import GridDensity, HeightDensity, Medium
from .light_depth import light_depth, light_depth_shape


@dataclass
class MediumFeature:
    """The medium on the device: `params` (medium_t), `density_grid` (float, the grid's
    values or one unused float) and `light_depth_grid` (each light's optical depths, then the
    eye's, or one unused float), made for the light_t buffer `lights`."""

    build_defines: dict
    params: object
    density_grid: object
    light_depth_grid: object
    lights: object

    def defines(self) -> dict:
        return self.build_defines

    def args(self) -> tuple:
        """MEDIUM_ARGS, appended after a kernel's own."""
        return self.params, self.density_grid, self.light_depth_grid


#: The walk's nodes a ray (cl/medium_walk.h MEDIUM_NODES) in a grid: WALK_NODES_PER_VOXEL for
#: each voxel along the grid's longest side, between the header's 32 and WALK_NODES_MAX (private
#: memory: 36 bytes a node). On scenes/smoke.yaml (48 voxels) 32 nodes were 7.6 % off exact
#: with pixel sampling, 256 0.62 % (docs/media.md, "The walk").
WALK_NODES_PER_VOXEL = 6
WALK_NODES_MIN = 32
WALK_NODES_MAX = 256


def walk_nodes(grid_shape: tuple[int, int, int]) -> int:
    """MEDIUM_NODES of the walk's per-ray table for a density grid of `grid_shape` (nz, ny, nx)."""
    return min(max(WALK_NODES_PER_VOXEL * max(int(n) for n in grid_shape), WALK_NODES_MIN), WALK_NODES_MAX)


def medium_defines(medium: Medium) -> dict:
    """The -D options of a kernel that samples `medium` (empty when homogeneous); a grid's
    also sets the walk's nodes a ray (`walk_nodes`)."""
    defines = {}
    if medium.bounds is not None:
        defines["MEDIUM_BOUNDED"] = 1
    if isinstance(medium.density, HeightDensity):
        defines["MEDIUM_HEIGHT"] = 1
    if isinstance(medium.density, GridDensity):
        defines["MEDIUM_GRID"] = 1
        defines["MEDIUM_NODES"] = walk_nodes(medium.density.values.shape)
    return defines


def medium_params(medium: Medium, eye_ws: np.ndarray) -> np.ndarray:
    """The medium_t of `medium` in eye space (world space less `eye_ws`)."""
    params = np.zeros((), dtype=structs.medium_dtype)
    eye_ws = np.asarray(eye_ws, dtype=np.float64)
    if medium.bounds is not None:
        params["box_min"] = structs.float4(np.asarray(medium.bounds.min) - eye_ws)
        params["box_max"] = structs.float4(np.asarray(medium.bounds.max) - eye_ws)
    density = medium.density
    if isinstance(density, HeightDensity):
        params["height_base"] = density.base - eye_ws[1]
        params["scale_height"] = density.scale_height
    if isinstance(density, GridDensity):
        params["grid_min"] = structs.float4(np.asarray(density.bounds.min) - eye_ws)
        params["grid_max"] = structs.float4(np.asarray(density.bounds.max) - eye_ws)
        params["grid_nz"], params["grid_ny"], params["grid_nx"] = density.values.shape
        params["depth_nz"], params["depth_ny"], params["depth_nx"] = light_depth_shape(density.values.shape)
    return params


def medium_feature(device: Device, buffers: FrameBuffers, timer: StageTimer) -> MediumFeature | None:
    """The frame's medium on the device (None when homogeneous), made once per frame and kept
    on `buffers`: the stages that sample the medium (raymarch, the walk) share it. A grid's
    optical-depth grids are computed here (stage light_depth), again for other lights."""
    medium = buffers.inputs.scene.medium
    if medium.homogeneous:
        return None
    if buffers.medium is not None and buffers.medium.lights is buffers.lights:  # (not a light turn's buffers)
        return buffers.medium
    defines = medium_defines(medium)
    params_host = medium_params(medium, buffers.inputs.eye_ws)
    light_count = int(buffers.inputs.params["light_count"])
    params_host["eye_depth_index"] = light_count
    params = device.buffer(params_host.reshape(1), writable=False)
    unused = lambda: device.buffer(np.zeros(1, np.float32), writable=False)
    if isinstance(medium.density, GridDensity):
        density_grid = device.buffer(np.ascontiguousarray(medium.density.values, dtype=np.float32), writable=False)
        shape = light_depth_shape(medium.density.values.shape)
        depth_grid = light_depth(device, params, density_grid, buffers.lights, light_count, shape, timer, defines)
    else:
        density_grid, depth_grid = unused(), unused()
    buffers.medium = MediumFeature(defines, params, density_grid, depth_grid, buffers.lights)
    return buffers.medium
