"""The walk's nodes a ray and the optical-depth grids' nodes follow the density grid's voxels
(docs/media.md, "How many" and "Where the nodes are"): scenes/smoke.yaml's 48×32×48 noise was
8.4 % off `exact` with 32 nodes and 33³ depth grids, 2.2 % with the rules below (0.78 % with
pixel sampling; bench/errors.py smoke --pixels 400)."""
from __future__ import annotations

import numpy as np
import pytest

from clrays.scene.model import Box, GridDensity, HeightDensity, Medium
from clrays.stages.light_depth import light_depth_shape
from clrays.stages.medium import medium_defines, walk_nodes

BOX = Box(np.array([-3.0, 0.0, -3.0]), np.array([3.0, 4.0, 3.0]))


def _grid(shape) -> GridDensity:
    return GridDensity(np.ones(shape, dtype=np.float32), BOX)


@pytest.mark.parametrize("grid_shape, nodes", [
    ((4, 4, 4), (33, 33, 33)),          # a coarse grid keeps the least: its depth bends inside a voxel
    ((48, 32, 48), (97, 65, 97)),       # the smoke's: two intervals a voxel
    ((12, 20, 40), (33, 41, 81)),
    ((128, 128, 128), (97, 97, 97)),    # capped: each node's march crosses the grid
])
def test_the_depth_grids_have_two_intervals_a_voxel_within_their_bounds(grid_shape, nodes):
    assert light_depth_shape(grid_shape) == nodes


@pytest.mark.parametrize("grid_shape, nodes", [
    ((4, 4, 4), 32),
    ((12, 12, 12), 72),
    ((48, 32, 48), 256),
    ((128, 128, 128), 256),
])
def test_the_walk_takes_six_nodes_a_voxel_of_the_longest_side_within_bounds(grid_shape, nodes):
    assert walk_nodes(grid_shape) == nodes


def test_only_a_grid_sets_the_walk_nodes():
    """Box and height fog keep the header's 32 nodes and so their kernels' bits."""
    sigma = (0.5, 0.5, 0.5)
    grid = Medium(sigma, sigma, bounds=BOX, density=_grid((48, 32, 48)))
    assert medium_defines(grid)["MEDIUM_NODES"] == 256
    assert "MEDIUM_NODES" not in medium_defines(Medium(sigma, sigma, bounds=BOX))
    height = Medium(sigma, sigma, density=HeightDensity(base=0.0, scale_height=2.0))
    assert "MEDIUM_NODES" not in medium_defines(height)
