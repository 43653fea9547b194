"""A derived shadow map grows until the thinnest closed solid spans OCCLUDER_TEXELS texels
seen from its light (clrays.scene.costs.occluder_shadow_map)."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from clrays.scene.costs import (MAX_OCCLUDER_SHADOW_MAP, MAX_TEXTURE_GAMMA_SAMPLES, MAX_TEXTURE_SLICES, OCCLUDER_MAP_GROWTH, OCCLUDER_TEXELS, thinnest_solid,
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
    # the directional map's longer side: the box's outline seen from above, 1 % larger (scene/light_views.py)
    outline = max(hi[0] - lo[0], hi[2] - lo[2]) * 1.01
    assert thinnest_solid(sun.geometry, sun.lights[0]) == pytest.approx(0.01 / outline, rel=1e-6)


def test_a_spot_grows_its_map_only_for_a_slat_its_cone_can_reach():
    """The slat below a 30° spot: the map grows (3.1 texels of 1024 across it: 2048) when the
    spot looks down at it, also with the spot tilted 40° so that the slat's ends lie outside the
    cone but its middle inside; not when the spot looks up, away from it."""
    down = _slat_scene(SpotLight(v3(0, 6, 0), v3(0, -1, 0), 30.0, np.full(3, 30.0)))
    tilted = _slat_scene(SpotLight(v3(0, 6, 0), v3(0, -math.cos(math.radians(40)), math.sin(math.radians(40))),
                                   30.0, np.full(3, 30.0)))
    away = _slat_scene(SpotLight(v3(0, 6, 0), v3(0, 1, 0), 30.0, np.full(3, 30.0)))
    assert [with_derived_sizes(s).render.shadow_map for s in (down, tilted, away)] == [2048, 2048, 1024]
    assert thinnest_solid(away.geometry, away.lights[0]) is None


def test_a_vanishing_texel_is_bounded_by_the_caps():
    """A texture tiled 1e-320 wide makes an infinite ratio of texels to the light's reach:
    the derived sizes stop at their caps, with no overflow on the way."""
    scene = load_scene(SCENES / "stained_glass.yaml", overrides=["image.width=32", "image.height=18",
                                                                   "lights.0.texture_size=[1e-320, 1e-320]"])
    render = with_derived_sizes(scene).render
    assert (render.slices, render.gamma_samples) == (MAX_TEXTURE_SLICES, MAX_TEXTURE_GAMMA_SAMPLES)


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


@pytest.mark.parametrize("size", [(96, 64), (320, 180), (640, 360), (1280, 720)])
def test_only_the_grate_grows(size):
    """Of the scenes in scenes/, only the grate's solids are thinner than 6 texels of a
    1024² map (its slats 2.1; the next, sun's and stained_glass's mullions, 14.8); from a
    diagonal of 100 pixels (96×64) every image derives that map."""
    for path in sorted(SCENES.glob("*.yaml")):
        scene = load_scene(path, overrides=[f"image.width={size[0]}", f"image.height={size[1]}"])
        expected = 4096 if path.stem == "grate" else 1024
        assert with_derived_sizes(scene).render.shadow_map == expected, path.stem
