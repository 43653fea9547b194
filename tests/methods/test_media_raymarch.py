"""raymarch in a bounded or heterogeneous medium (cl/raymarch.cl with cl/medium.h,
docs/media.md) against `exact` (clrays/reference/media.py): the in-scattering pass of each
method, on small scenes with a floor and an occluder, the march at fine steps. The surface
term is the shade stage's and is compared elsewhere.

Tolerances are on relative RMSE of luminance over the pixels that see fog, about twice what
was measured on Intel's CPU runtime (in the comments); with the eye in the box the error is
the homogeneous march's own there (0.44 %: the shadow map's texels at the occluder)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from clrays.reference.metrics import image_error
from clrays.scene.geometry import box_triangles
from clrays.scene.model import Box, GridDensity, HeightDensity
from conftest import DirectionalLight, PointLight, grid_plane, make_scene, v3

BOX = Box(v3(-2.0, 0.0, -2.0), v3(2.0, 3.0, 2.0))
GRID = GridDensity(np.random.default_rng(5).random((6, 5, 4)).astype(np.float32) * 1.5, BOX)
SUN = DirectionalLight(v3(0.3, -1.0, 0.2) / np.linalg.norm([0.3, -1.0, 0.2]), np.full(3, 2.0))
LAMP = PointLight(v3(0.3, 3.6, 0.2), np.full(3, 30.0))


def _scene(light, bounds=None, density=None, position=(0, 1.8, 5.5), steps=512):
    triangles = np.concatenate([grid_plane(0.0, 6.0, 2), box_triangles([-0.5, 1.6, -0.4], [0.4, 1.9, 0.5])])
    # (smaller in a grid, where exact's light paths cross every voxel plane)
    width, height = (20, 12) if isinstance(density, GridDensity) else (32, 20)
    scene = make_scene(triangles, [light], width=width, height=height, sigma_s=0.25, sigma_a=0.05, position=position,
                       look_at=(0, 1, 0), steps=steps, aovs=("in_scatter",), shadow_map=1024)
    return replace(scene, medium=replace(scene.medium, bounds=bounds, density=density))


def _error(renderer, scene):
    reference = renderer.render(scene, "exact").passes["in_scatter"]
    marched = renderer.render(scene, "raymarch").passes["in_scatter"]
    assert np.isfinite(marched).all()
    return image_error(marched, reference)


@pytest.mark.parametrize("light, bounds, density, position, bound", [
    # measured: 0.022 %, 0.46 %, 0.031 %, 0.27 %, 0.068 %, 0.17 % (the grid's light
    # depths are trilinear between the light_depth stage's nodes; 0.24 % and 0.62 % with
    # 17 of them a side)
    (LAMP, BOX, None, (0, 1.8, 5.5), 0.004),
    (LAMP, BOX, None, (0.3, 1.2, 0.8), 0.009),  # the eye inside the box
    (LAMP, None, HeightDensity(0.5, 1.2), (0, 1.8, 5.5), 0.004),
    (SUN, BOX, HeightDensity(0.5, 1.2), (0, 1.8, 5.5), 0.006),
    (LAMP, None, GRID, (0, 1.8, 5.5), 0.006),
    (SUN, None, GRID, (0, 1.8, 5.5), 0.012),
], ids=["box-point", "box-point-inside", "height-point", "box-height-sun", "grid-point", "grid-sun"])
def test_raymarch_matches_exact_in_a_varying_medium(renderer, light, bounds, density, position, bound):
    error = _error(renderer, _scene(light, bounds, density, position))
    print(error)
    assert error.rmse <= bound, str(error)


def test_raymarch_converges_to_exact_with_more_steps(renderer):
    """Not a fixed error: halving the step length lowers it (height fog, point light)."""
    errors = [_error(renderer, _scene(LAMP, BOX, HeightDensity(0.5, 1.2), steps=steps)).rmse for steps in (32, 512)]
    assert errors[1] < 0.5 * errors[0], errors


def test_a_box_around_everything_marches_as_the_unbounded_medium(renderer):
    """The box's kernel (MEDIUM_BOUNDED) against the homogeneous one, with a point light whose
    light and every ray stay inside the box: the same in-scattering to float32 rounding and
    the two marches' quadratures."""
    unbounded = _scene(LAMP)
    bounded = replace(unbounded, medium=replace(unbounded.medium, bounds=Box(v3(-50, -50, -50), v3(50, 50, 50))))
    a = renderer.render(unbounded, "raymarch").passes["in_scatter"]
    b = renderer.render(bounded, "raymarch").passes["in_scatter"]
    assert image_error(b, a).rmse <= 1e-3


def test_fog_outside_the_view_adds_nothing(renderer):
    """A box the camera rays never meet: no in-scattering (the light's path crosses it)."""
    scene = _scene(LAMP, Box(v3(20, 0, 20), v3(30, 5, 30)))
    assert np.all(renderer.render(scene, "raymarch").passes["in_scatter"] == 0.0)


@pytest.mark.parametrize("light", [LAMP, SUN], ids=["point", "sun"])
def test_the_light_depth_stage_matches_exact_optical_depths(device, light):
    """Stage light_depth against numpy: each node's optical depth to the light, marched on the
    device in half-voxel steps, against exact's piecewise Gauss–Legendre (media.light_depth)."""
    from clrays.device import StageTimer
    from clrays.inputs import frame_inputs, upload
    from clrays.reference.media import light_depth
    from clrays.stages.light_depth import light_depth_shape
    from clrays.stages.medium import medium_feature

    scene = _scene(light, Box(v3(-2.0, 0.0, -2.0), v3(2.0, 2.6, 2.0)), GRID)  # the box cuts the grid's top
    buffers = upload(device, frame_inputs(scene))
    feature = medium_feature(device, buffers, StageTimer())
    assert medium_feature(device, buffers, StageTimer()) is feature  # made once a frame
    shape = light_depth_shape(GRID.values.shape)
    assert shape == (33, 33, 33)
    marched = device.read(feature.light_depth_grid, shape, np.float32)
    axes = [np.linspace(GRID.bounds.min[axis], GRID.bounds.max[axis], n) for axis, n in zip((2, 1, 0), shape)]
    z, y, x = np.meshgrid(*axes, indexing="ij")
    nodes = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    expected = light_depth(light, scene.medium, nodes).reshape(shape)
    # measured: 2.5e-3 of the largest depth at most, 2.6e-4 on average (the midpoint rule across
    # the voxel-centre kinks of a random grid)
    error = np.abs(marched - expected) / expected.max()
    assert error.max() <= 5e-3 and error.mean() <= 5e-4, (error.max(), error.mean())
