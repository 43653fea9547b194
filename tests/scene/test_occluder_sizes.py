"""A derived shadow map grows until the thinnest closed solid spans OCCLUDER_TEXELS texels
seen from its light (clrays.scene.costs.occluder_shadow_map)."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from clrays.scene.costs import (MAX_OCCLUDER_SHADOW_MAP, OCCLUDER_MAP_GROWTH, OCCLUDER_TEXELS, thinnest_solid,
                                with_derived_sizes)
from clrays.scene.geometry import box_triangles
from clrays.scene.load import load_scene
from conftest import DirectionalLight, PointLight, SpotLight, grid_plane, make_scene, v3, with_closed_solid

SCENES = Path(__file__).resolve().parents[2] / "scenes"
UNSET = dict(shadow_map=None, slices=None, gamma_samples=None)


def _slat_scene(light, width=0.01, image=(320, 180)):
    """A floor and one slat `width` wide (x), 0.2 deep, 3 long, its top 2.8 below y = 6."""
    floor = grid_plane(0.0, 6.0, 2)
    slat = box_triangles([-width / 2, 3.0, -1.5], [width / 2, 3.2, 1.5])
    scene = make_scene(np.concatenate([floor, slat]), [light], width=image[0], height=image[1], **UNSET)
    return with_closed_solid(scene, slice(len(floor), None))


def test_a_slat_below_a_point_light():
    scene = _slat_scene(PointLight(v3(0, 6, 0), np.full(3, 30.0)))
    # seen from the light: 1 cm at 2.8 below, in tangents; a cube face spans 2 of them
    assert thinnest_solid(scene.geometry, scene.lights[0]) == pytest.approx(0.01 / 2.8 / 2, rel=1e-9)
    # 1.8 texels of a 1024² face: 6 texels need 3360, a power of two 4096
    assert with_derived_sizes(scene).render.shadow_map == 4096
    wide = _slat_scene(PointLight(v3(0, 6, 0), np.full(3, 30.0)), width=0.1)  # 18 texels already
    assert with_derived_sizes(wide).render.shadow_map == 1024


def test_a_slat_below_a_spot_and_the_sun():
    spot = _slat_scene(SpotLight(v3(0, 6, 0), v3(0, -1, 0), 30.0, np.full(3, 30.0)))
    side = 2 * math.tan(math.radians(30.0))
    assert thinnest_solid(spot.geometry, spot.lights[0]) == pytest.approx(0.01 / 2.8 / side, rel=1e-9)
    sun = _slat_scene(DirectionalLight(v3(0, -1, 0), np.full(3, 2.0)))
    lo, hi = sun.geometry.bounds()
    sphere = 2 * np.linalg.norm(hi - lo) / 2 * 1.01  # the directional map's side (inputs.frame_inputs)
    assert thinnest_solid(sun.geometry, sun.lights[0]) == pytest.approx(0.01 / sphere, rel=1e-6)


def test_growth_is_bounded_by_the_image_and_the_largest_map():
    light = PointLight(v3(0, 6, 0), np.full(3, 30.0))
    thumbnail = with_derived_sizes(_slat_scene(light, width=1e-4, image=(16, 9))).render.shadow_map
    assert thumbnail == OCCLUDER_MAP_GROWTH * 128  # 16×9 derives 128 from the image
    assert with_derived_sizes(_slat_scene(light, width=1e-4)).render.shadow_map == MAX_OCCLUDER_SHADOW_MAP
    assert OCCLUDER_TEXELS == 6
    many = _slat_scene(light, width=1e-4)
    for count, side in ((2, 2048), (4, 2048), (5, 1024), (64, 1024)):  # all lights' maps within one 4096² cube
        lights = tuple(PointLight(v3(0.1 * k, 6, 0), np.full(3, 30.0)) for k in range(count))
        assert with_derived_sizes(dataclasses.replace(many, lights=lights)).render.shadow_map == side, count


def test_what_is_no_thin_occluder():
    """No solid, a solid that holds the light, an open surface: the image's size."""
    light = PointLight(v3(0, 6, 0), np.full(3, 30.0))
    bare = make_scene(grid_plane(0.0, 6.0, 2), [light], width=320, height=180, **UNSET)
    assert thinnest_solid(bare.geometry, light) is None
    assert with_derived_sizes(bare).render.shadow_map == 1024
    around = with_closed_solid(make_scene(box_triangles([-1, 5.99, -1], [1, 6.01, 1]), [light], **UNSET), slice(None))
    assert thinnest_solid(around.geometry, light) is None
    soup = make_scene(box_triangles([-0.005, 3.0, -1.5], [0.005, 3.2, 1.5]), [light], width=320, height=180, **UNSET)
    assert with_derived_sizes(soup).render.shadow_map == 1024  # not marked closed: not measured


@pytest.mark.parametrize("size", [(320, 180), (640, 360), (1280, 720)])
def test_only_the_grate_grows(size):
    """Of the scenes in scenes/, only the grate's solids are thinner than 6 texels of a
    1024² map (its slats 2.1; the next, sun's and stained_glass's mullions, 14.8)."""
    for path in sorted(SCENES.glob("*.yaml")):
        scene = load_scene(path, overrides=[f"image.width={size[0]}", f"image.height={size[1]}"])
        expected = 4096 if path.stem == "grate" else 1024
        assert with_derived_sizes(scene).render.shadow_map == expected, path.stem
