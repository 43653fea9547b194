"""Sizes that follow the image (clrays.scene.costs): derived when unset, kept when set."""
from __future__ import annotations

from dataclasses import replace

import pytest

from clrays.scene.costs import with_derived_sizes
from clrays.scene.fields import RENDER
from clrays.scene.model import Image, Render
from tests.conftest import grid_plane, make_scene


def _sizes(width, height, **render):
    scene = make_scene(width=width, height=height)
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
