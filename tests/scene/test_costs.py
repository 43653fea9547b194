"""Sizes that follow the image (clrays.scene.costs): derived when unset, kept when set."""
from __future__ import annotations

from dataclasses import replace

import pytest

import numpy as np

from clrays.scene.costs import MAX_TEXTURE_GAMMA_SAMPLES, MAX_TEXTURE_SLICES, with_derived_sizes
from clrays.scene.fields import RENDER
from clrays.scene.model import DirectionalLight, Image, LightTexture, PointLight, Render, SpotLight
from tests.conftest import grid_plane, make_scene


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


@pytest.mark.parametrize("width, height", [(640, 360), (1280, 720), (1920, 1080), (128, 72)])
def test_bench_sizes_keep_the_measured_defaults(width, height):
    assert _sizes(width, height) == (1024, 1024, 1024)


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
    # A glTF cone's falloff is a slow ramp over 512² texels; a directional light's texels are lengths.
    assert _sizes(320, 180, lights=[_spot(_texture(512, smooth=True))]) == (1024, 1024, 1024)
    sun = DirectionalLight(np.array([0.0, -1.0, 0.0]), np.full(3, 2.0), texture=_texture(1024))
    assert _sizes(320, 180, lights=[sun]) == (1024, 1024, 1024)


def test_what_textures_ask_for_stays_within_a_budget():
    # 16 spot lights sharing a 4096² gobo in a 32×18 frame asked for 2048 × 1024 each: 2.4 GiB
    # of prefix sums. Within TEXTURE_SIZES_BUDGET the raise halves, the larger first, to
    # 256 slices × 512 γ texels (16 × 76 B × 131072 = 152 MiB); never below the image's.
    assert _sizes(32, 18, lights=[_spot(_texture(4096), 30.0)] * 16) == (256, 256, 512)
    # Two gobos at 320×180: 2 × 152 MiB is over, so the slices go back to the image's 1024.
    assert _sizes(320, 180, lights=[_spot(_texture(256))] * 2) == (1024, 1024, 1024)
