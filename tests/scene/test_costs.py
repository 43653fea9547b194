"""Sizes that follow the image (clrays.scene.costs): derived when unset, kept when set."""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import pytest

import numpy as np

from clrays.scene.costs import (MAX_TEXTURE_GAMMA_SAMPLES, MAX_TEXTURE_SLICES, TEXTURE_SIZES_BUDGET,
                                derived_gamma_samples, derived_slices, directional_texture_reach, texture_sizes,
                                with_derived_sizes)
from clrays.scene.fields import RENDER
from clrays.scene.load import load_scene
from clrays.scene.model import DirectionalLight, Image, LightTexture, PointLight, Render, SpotLight
from clrays.scene.camera import slice_basis, slice_fan
from tests.conftest import grid_plane, make_scene

ROOT = Path(__file__).resolve().parents[2]


def _power_of_two(value):
    return 1 << math.ceil(math.log2(value))


def _sizes(width, height, lights=None, **render):
    scene = make_scene(width=width, height=height, lights=lights)
    scene = replace(scene, image=Image(width, height, 1), render=Render(**render))
    resolved = with_derived_sizes(scene).render
    return resolved.shadow_map, resolved.slices, resolved.gamma_samples


def test_thumbnail_gets_small_sizes():
    # 16×9: 4 × diagonal 18.4 → a 128 texel map, which bounds the slices (4 × perimeter 50 →
    # 256) and the γ texels (8 × diagonal → 256).
    assert _sizes(16, 9) == (128, 128, 128)
    # A map the scene sets does not make a thumbnail rectify 1024²: the image bounds it.
    assert _sizes(16, 9, shadow_map=1024) == (1024, 256, 256)


@pytest.mark.parametrize("width, height", [(640, 360), (1280, 720), (1920, 1080), (128, 72), (96, 64)])
def test_bench_sizes_keep_the_measured_defaults(width, height):
    assert _sizes(width, height) == (1024, 1024, 1024)


def test_the_full_map_from_a_diagonal_of_100_pixels():
    """4 texels per pixel of the diagonal give 96×64 (115 px) 512², which misses 0.5 % against
    `exact` (sun 0.65, room 0.84 %; 0.34 and 0.28 % at 1024²): from a diagonal of 100 pixels
    the map is 1024², and the slices and γ texels follow it. Below, the 4 × diagonal rule."""
    assert _sizes(80, 60) == (1024, 1024, 1024)  # a diagonal of 100.0
    assert _sizes(100, 1) == (1024, 1024, 1024)  # a strip: 8 × 101 = 808 slices → 1024
    assert _sizes(79, 60) == (512, 512, 512)  # 99.2: 4 × 99.2 = 397 → 512
    assert _sizes(64, 48) == (512, 512, 512)
    assert _sizes(32, 18) == (256, 256, 256)


def test_texels_per_slice_follow_a_small_shadow_map():
    assert _sizes(640, 360, shadow_map=128) == (128, 128, 128)
    assert _sizes(64, 48, shadow_map=1024) == (1024, 1024, 1024)


def test_sizes_the_scene_sets_are_kept():
    assert _sizes(16, 9, shadow_map=512, slices=300, gamma_samples=1000) == (512, 300, 1000)


def test_field_table_documents_the_derived_defaults():
    for key in ("shadow_map", "slices", "gamma_samples"):
        assert RENDER[key].default is None and RENDER[key].shown_default.startswith("from the image")


def test_thumbnail_render_rectifies_a_small_texture(renderer):
    # A floor: the light's map is not empty. None: the sizes follow the image.
    scene = make_scene(grid_plane(), width=16, height=9, shadow_map=None, slices=None, gamma_samples=None)
    result = renderer.render(scene, reuse=False)
    assert (result.render.shadow_map, result.render.slices, result.render.gamma_samples) == (128, 128, 128)
    assert result.textures == ((128, 128),)


def _texture(side, smooth=False):
    return LightTexture(np.ones((side, side, 3), np.float32), "test", smooth=smooth)


def _spot(texture, cone_deg=28.0):
    return SpotLight(np.array([0.0, 4.0, 0.0]), np.array([0.0, -1.0, 0.0]), cone_deg, np.full(3, 30.0), texture=texture)


def test_a_textured_spot_gets_slices_and_texels_that_resolve_its_texture():
    # scenes/gobo.yaml's 256² over 28°: a texel is 2·tan 28° / 256 = 4.16 mrad at the light,
    # so 2π / 4.16e-3 = 1512 → 2048 slices and π / 4.16e-3 = 756 → 1024 γ texels.
    assert _sizes(320, 180, lights=[_spot(_texture(256))]) == (1024, 2048, 1024)
    assert _sizes(64, 36, lights=[_spot(_texture(256))]) == (512, 2048, 1024)
    # A coarse texture asks for no more than the image does; a fine one is clamped.
    assert _sizes(320, 180, lights=[_spot(_texture(16))]) == (1024, 1024, 1024)
    assert _sizes(320, 180, lights=[_spot(_texture(4096))]) == (1024, MAX_TEXTURE_SLICES, MAX_TEXTURE_GAMMA_SAMPLES)
    # Sizes the scene sets are kept.
    assert _sizes(320, 180, lights=[_spot(_texture(256))], slices=512, gamma_samples=256) == (1024, 512, 256)


def test_textures_that_ask_for_no_more_sizes():
    cube = LightTexture(np.ones((6 * 128, 128, 3), np.float32), "cube")  # faces of 2/128 rad: 403 slices
    assert _sizes(320, 180, lights=[PointLight(np.array([0.0, 4.0, 0.0]), np.full(3, 30.0), texture=cube)]) \
        == (1024, 1024, 1024)
    # A glTF cone's falloff is a slow ramp over 512² texels.
    assert _sizes(320, 180, lights=[_spot(_texture(512, smooth=True))]) == (1024, 1024, 1024)
    # A sun's 1024² texels over 40 × 40 units are 4 cm across its beam: over the floor below
    # (reach 15.2, a fan of 1.48 rad) 577 slices and 390 γ texels, no more than the image's 1024.
    assert _sizes(320, 180, lights=[_sun(_texture(1024), (40.0, 40.0))]) == (1024, 1024, 1024)
    assert _sizes(320, 180, lights=[_sun(_texture(16), (1.0, 1.0))]) == (1024, 1024, 1024)


def _sun(texture, texture_size, direction=(0.0, -1.0, 0.0)):
    return DirectionalLight(np.array(direction), np.full(3, 2.0), texture=texture, texture_size=texture_size)


def _floor_sizes(width, height, light, **settings):
    """Sizes of make_scene's camera (eye (0, 2, 8)) over a 12 × 12 floor at y = 0."""
    scene = make_scene(grid_plane(), width=width, height=height, lights=[light], **settings)
    render = {key: settings.get(key) for key in ("shadow_map", "slices", "gamma_samples")}
    resolved = with_derived_sizes(replace(scene, render=replace(scene.render, **render))).render
    return resolved.shadow_map, resolved.slices, resolved.gamma_samples


def _fan(scene, light):
    towards = -np.asarray(light.direction, dtype=float)
    towards /= np.linalg.norm(towards)
    return slice_fan(scene, towards, *slice_basis(towards))[1]


def test_a_textured_sun_gets_slices_and_texels_one_a_texel_at_its_reach():
    """A directional texture's texel is a length t across the beam; the slices fan around the
    eye's line along the light, R·Δα apart at the reach R, and γ runs over [0, R]: slices
    ≥ fan·R / t, γ texels ≥ R / t (clrays.scene.costs.texture_sizes)."""
    sun = _sun(_texture(256), (10.0, 10.0))  # t = 10 / 256 = 0.039
    scene = make_scene(grid_plane(), width=32, height=18, lights=[sun])
    # Sun overhead: the eye's line is vertical, and the floor's farthest corner (±6, 0, −6)
    # lies √(6² + 14²) = 15.23 from it, within far (30).
    fan, reach = directional_texture_reach(scene, sun)
    assert reach == pytest.approx(math.hypot(6.0, 14.0))
    assert fan == pytest.approx(_fan(scene, sun)) and 0.5 < fan < math.pi  # the antisun is off screen
    texel = 10.0 / 256
    # 1.48 · 15.23 / 0.039 = 577 slices, 15.23 / 0.039 = 390 γ texels.
    assert texture_sizes(scene) == (_power_of_two(fan * reach / texel), _power_of_two(reach / texel)) == (1024, 512)
    # The image (32×18) alone derives 256 of each; the texture raises them.
    assert _floor_sizes(32, 18, sun) == (256, 1024, 512)
    # A tile half as tall halves the shorter texel: twice each, the γ texels at their clamp.
    assert _floor_sizes(32, 18, _sun(_texture(256), (10.0, 5.0))) == (256, 2048, MAX_TEXTURE_GAMMA_SAMPLES)
    # A far plane nearer than the floor's corner bounds the reach (every ray ends there).
    near = make_scene(grid_plane(), width=32, height=18, lights=[sun], far=5.0)
    assert directional_texture_reach(near, sun)[1] == pytest.approx(5.0)
    # Sizes the scene sets are kept, and the ones it leaves still follow the texture.
    assert _floor_sizes(32, 18, sun, slices=64, gamma_samples=32) == (256, 64, 32)
    assert _floor_sizes(32, 18, sun, slices=64) == (256, 64, 512)
    assert _floor_sizes(32, 18, sun, gamma_samples=32) == (256, 1024, 32)


def test_what_a_sun_texture_asks_for_stays_within_the_budget():
    # scenes/stained_glass.yaml's texture (256² over 2.5 units: 1 cm texels) asks over the
    # floor for 2307 → 4096 slices and 1559 → 2048 γ texels, clamped to 4096 × 1024 (252 MiB
    # of prefix sums at rank 4, 60 B a texel: within the budget).
    assert _floor_sizes(320, 180, _sun(_texture(256), (2.5, 2.5))) == (1024, MAX_TEXTURE_SLICES, 1024)
    assert MAX_TEXTURE_SLICES * 1024 * 12 * (4 + 1) <= TEXTURE_SIZES_BUDGET
    # Four such suns would take 1008 MiB: the raise halves, the larger in proportion first, to
    # 1024 × 1024 (4 × 60 B × 1048576 = 240 MiB) over a 32×18 image's 256 × 256, and at
    # 320×180 to the image's own 1024 × 1024.
    four = [_sun(_texture(256), (2.5, 2.5), (0.1 * k, -1.0, 0.0)) for k in range(4)]
    for (width, height), sizes in (((32, 18), (1024, 1024)), ((320, 180), (1024, 1024))):
        scene = make_scene(grid_plane(), width=width, height=height, lights=four, shadow_map=None, slices=None,
                           gamma_samples=None)
        resolved = with_derived_sizes(scene).render
        assert (resolved.slices, resolved.gamma_samples) == sizes
    assert 1024 * 1024 * 4 * 12 * (resolved.svd_rank + 1) <= TEXTURE_SIZES_BUDGET < 2048 * 1024 * 4 * 60


@pytest.mark.parametrize("name", ["demo", "bunny", "behind", "sun"])
def test_the_bench_scenes_have_no_texture_and_keep_the_image_sizes(name):
    for width, height in ((96, 64), (320, 180), (640, 360), (1280, 720)):
        scene = load_scene(ROOT / "scenes" / f"{name}.yaml", [f"image.width={width}", f"image.height={height}"])
        assert texture_sizes(scene) == (0, 0)
        resolved = with_derived_sizes(scene).render
        assert (resolved.slices, resolved.gamma_samples) == (
            derived_slices(width, height, resolved.shadow_map),
            derived_gamma_samples(width, height, resolved.shadow_map)), (name, width, height)


def test_what_textures_ask_for_stays_within_a_budget():
    # 16 spot lights sharing a 4096² gobo in a 32×18 frame ask for 4096 × 1024 each: 3.9 GiB
    # of prefix sums. Within TEXTURE_SIZES_BUDGET the raise halves, the larger in proportion
    # first, to 512 slices × 512 γ texels (16 × 60 B × 262144 = 240 MiB); never below the image's.
    assert _sizes(32, 18, lights=[_spot(_texture(4096), 30.0)] * 16) == (256, 512, 512)
    # Two gobos at 320×180 keep their 2048 × 1024 (2 × 126 MiB); with three the slices go
    # back to the image's 1024.
    assert _sizes(320, 180, lights=[_spot(_texture(256))] * 2) == (1024, 2048, 1024)
    assert _sizes(320, 180, lights=[_spot(_texture(256))] * 3) == (1024, 1024, 1024)
