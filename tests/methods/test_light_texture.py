"""Textured lights (docs/light-textures.md) in every method: a white texture changes
nothing, minmax follows exact on the example scenes, raymarch follows exact."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import clrays
from clrays.reference.metrics import depth_edges, depth_map, image_error
from clrays.scene.load import load_scene, parse_scene
from clrays.scene.model import LightTexture

ROOT = Path(__file__).resolve().parents[2]

SMALL = """
version: 1
image: {width: 48, height: 27}
camera: {position: [0, 2.5, 7], look_at: [0, 1, 0], far: 15}
lights: [LIGHT]
medium: {sigma_s: 0.1, sigma_a: 0.02, phase: {type: hg, g: 0.3}}
objects:
  - {type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 12}
  - {type: box, min: [-0.5, 1, -0.5], max: [0.5, 1.6, 0.5]}
render: {shadow_map: 512, slices: 512, gamma_samples: 512}
"""
LIGHTS = {
    "point": "{type: point, position: [0.3, 3.5, 0.2], intensity: 30}",
    "spot": "{type: spot, position: [0.3, 5, 0.2], direction: [0, -1, 0.1], cone_deg: 30, intensity: 60}",
    "directional": "{type: directional, direction: [-0.4, -1, -0.2], irradiance: 2}",
}


def _with_texture(scene, texels, **fields):
    light = dataclasses.replace(scene.lights[0], texture=LightTexture(np.asarray(texels, np.float32), "test"),
                                **fields)
    return dataclasses.replace(scene, lights=(light,))


def _error(scene, image, reference):
    return image_error(image, reference, depth_edges(depth_map(scene)))


@pytest.mark.parametrize("method", ["minmax", "raymarch", "exact"])
@pytest.mark.parametrize("kind", list(LIGHTS))
def test_a_white_texture_changes_nothing(kind, method):
    """A uniform white texture (of an odd size, so its texels fall anywhere) renders the
    untextured light's image within 0.1 %, surfaces and haze, in every method."""
    scene = parse_scene(SMALL.replace("LIGHT", LIGHTS[kind]), ROOT / "scenes" / "x.yaml")
    plain = clrays.render(scene, method=method, reuse=False)
    texels = np.ones((6 * 19, 19, 3)) if kind == "point" else np.ones((37, 53, 3))  # a point light's: a cube
    white = clrays.render(_with_texture(scene, texels, **({"texture_size": (3.7, 2.9)}
                                                           if kind == "directional" else {})),
                          method=method, reuse=False)
    lit = plain.mean(axis=2) > 0.01 * plain.mean()
    relative = np.abs(white - plain).max(axis=2)[lit] / plain.mean(axis=2)[lit]
    assert relative.max() < 1e-3, f"{kind} {method}: a white texture moves a pixel by {relative.max():.2e}"


@pytest.mark.parametrize("kind", list(LIGHTS))
def test_a_texture_scales_the_light_like_its_colour(kind):
    """A constant texture of colour c renders c times the untextured image (minmax: the
    control variate of the textured runs is exact for a constant)."""
    scene = parse_scene(SMALL.replace("LIGHT", LIGHTS[kind]), ROOT / "scenes" / "x.yaml")
    plain = clrays.render(scene, reuse=False)
    colour = np.array([0.25, 0.5, 2.0])
    tinted = clrays.render(_with_texture(scene, np.ones((48 if kind == "point" else 8, 8, 3)) * colour), reuse=False)
    np.testing.assert_allclose(tinted, plain * colour, rtol=1e-3, atol=1e-6 * plain.max())


def _minmax_against_exact(name, size, overrides=()):
    scene = load_scene(ROOT / "scenes" / name, [f"image.width={size[0]}", f"image.height={size[1]}",
                                                *overrides])
    exact = clrays.render(scene, method="exact")
    minmax = clrays.render(scene, method="minmax", reuse=False)
    return _error(scene, minmax, exact), scene, exact


def test_gobo_minmax_at_1024_slices_follows_exact():
    """scenes/gobo.yaml at 1024 slices and γ texels, 160×90: measured 0.215 % relative RMSE
    (0.232 % with each γ cell's texture its centre's). At 64×36 one pixel next to the lamp,
    whose ray sweeps a slice's whole row of the gobo, makes 58 % of the squared error, and
    its two slices, 1.7 texels apart, decide it: 1.015 % there with the cell's mean (1.04 %
    with 4 points a cell, the mean's limit; 0.950 % with its centre alone)."""
    error, _, _ = _minmax_against_exact("gobo.yaml", (160, 90), ["render.shadow_map=1024", "render.slices=1024",
                                                                 "render.gamma_samples=1024"])
    assert error.rmse < 0.0025, f"gobo: {error}"


def test_gobo_minmax_at_the_derived_sizes_is_within_half_a_percent_of_exact():
    """scenes/gobo.yaml at 64×36 with every size derived: the gobo's 256² texels over its 28°
    cone ask for 2048 slices and 1024 γ texels (clrays.scene.costs.texture_sizes), where the
    image alone derives 512 and 512 and the blend of two slices, 1.7 texels apart, smeared the
    pattern: measured 0.226 % relative RMSE (0.177 % with γ texels even in γ; 2.01 % with the
    image's 512 and 512 and even texels)."""
    error, scene, _ = _minmax_against_exact("gobo.yaml", (64, 36))
    assert scene.render.slices is None and scene.render.gamma_samples is None  # derived, not pinned
    assert error.rmse < 0.005, f"gobo at derived sizes: {error}"


@pytest.mark.parametrize("size", [(96, 64), (128, 72), (160, 90)])
def test_stained_glass_minmax_at_the_derived_sizes_follows_exact(size):
    """scenes/stained_glass.yaml with every size derived: the sun's 1 cm texels, seen up to
    10.5 units from the eye's line along the light over a fan of 3.0 rad, ask for 4096
    slices and 2048 γ texels, clamped to 4096 and 1024 (clrays.scene.costs.texture_sizes),
    and each γ cell's texture is its mean over 2 points (its cells are 1.9 texels long:
    γ reaches 19 through the window), and the mullions' shadows end on the mullions
    (cl/shaft_edges.h). Measured 0.390 / 0.221 / 0.285 % relative RMSE at 96×64 / 128×72 /
    160×90 (0.390 / 0.225 / 0.289 % with the sun's map over its bounding sphere); 0.452 % and 0.495 % at 128×72 and 160×90 with the runs' ends at the texels,
    0.569 % and 0.648 % at 2048 slices with each cell's centre alone, 1.10 % at 128×72 with
    the image's 1024 × 1024; at 96×64 0.76 % with a 512² shadow map."""
    error, scene, _ = _minmax_against_exact("stained_glass.yaml", size)
    assert scene.render.slices is None and scene.render.gamma_samples is None  # derived, not pinned
    assert error.rmse < 0.005, f"stained glass at derived sizes, {size}: {error}"


@pytest.mark.slow
def test_stained_glass_minmax_is_within_1_percent_of_exact():
    """scenes/stained_glass.yaml: lead lines two texels (2 cm) wide, tiled every 2.5 m, seen
    across a room. At 1024 slices the slices are about a texel apart at the room's far
    end and the blend of two slices misses the pattern between them: 1.10 % relative RMSE
    at 160×90; 2048 slices give 0.43 % (docs/light-textures.md; 1.17 and 0.56 % before the
    shafts' edges lay on the blockers and the sun's map fitted the bounds' outline)."""
    error, _, _ = _minmax_against_exact("stained_glass.yaml", (160, 90), [
        "render.shadow_map=1024", "render.slices=2048", "render.gamma_samples=1024"])
    assert error.rmse < 0.01, f"stained glass: {error}"


def test_a_cube_texture_in_minmax_and_raymarch_follows_exact(tmp_path):
    """A point light with a cube texture of a different checker in each face: the face
    seams, the per-face frames and the lookups agree between the device and exact
    (measured at 64×36: minmax 0.47 %, raymarch 0.58 % relative RMSE)."""
    rng = np.random.default_rng(3)
    y, x = np.mgrid[0:16, 0:16]
    checker = ((x // 4 + y // 4) % 2)[..., None]
    faces = np.concatenate([0.3 + rng.uniform(0, 1, 3) * checker for _ in range(6)])
    scene = _with_texture(parse_scene(SMALL.replace("LIGHT", LIGHTS["point"]).replace("512", "1024")
                                      .replace("width: 48, height: 27", "width: 64, height: 36"),
                                      ROOT / "scenes" / "x.yaml"), faces)
    exact = clrays.render(scene, method="exact")
    for method in ("minmax", "raymarch"):
        error = _error(scene, clrays.render(dataclasses.replace(scene, render=dataclasses.replace(
            scene.render, steps=2048)), method=method, reuse=False), exact)
        assert error.rmse < 0.01 and error.mean < 0.005, f"{method}: {error}"


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="a texture finer than the slice spacing: at 1024 slices (what the image "
                   "alone derives from 640×360 up) stained_glass.yaml is 1.10 % relative RMSE against exact at "
                   "160×90 (0.28 % untextured); the two-slice blend misses its 2 cm lead lines at the far wall, "
                   "which is why the derived sizes follow the texture (docs/light-textures.md)")
def test_stained_glass_at_1024_slices_misses_1_percent():
    error, _, _ = _minmax_against_exact("stained_glass.yaml", (160, 90), [
        "render.shadow_map=1024", "render.slices=1024", "render.gamma_samples=1024"])
    assert error.rmse < 0.01, f"stained glass at 1024 slices: {error}"


def test_raymarch_follows_exact_with_a_texture():
    """The per-sample lookup of raymarch against exact's cut-at-texel integral, on the
    gobo."""
    scene = load_scene(ROOT / "scenes" / "gobo.yaml", ["image.width=64", "image.height=36",
                                                       "render.shadow_map=1024", "render.steps=2048"])
    error = _error(scene, clrays.render(scene, method="raymarch"), clrays.render(scene, method="exact"))
    assert error.rmse < 0.01, f"raymarch: {error}"


def test_the_texture_stage_is_kept_while_its_inputs_stand_still(renderer):
    """A frame that changes only the surfaces' albedo keeps the light_texture stage
    (StageKeys.light_texture: the trees, the integrand, the eye, the rank), and its image is
    the one rendered from scratch, bit for bit."""
    scene = parse_scene(SMALL.replace("LIGHT", LIGHTS["spot"]), ROOT / "scenes" / "x.yaml")
    scene = _with_texture(scene, np.random.default_rng(5).uniform(0, 1, (9, 7, 3)))
    renderer.render(scene, "minmax")
    geometry = dataclasses.replace(scene.geometry, albedo=scene.geometry.albedo * 0.5)
    changed = dataclasses.replace(scene, geometry=geometry)
    kept = renderer.render(changed, "minmax")
    assert kept.stage_status["light_texture"] == "reused", kept.stage_status
    fresh = renderer.render(changed, "minmax", reuse=False)
    np.testing.assert_array_equal(kept.image, fresh.image)
