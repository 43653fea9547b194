"""Translucent objects seen by the camera (the transparency stage; docs/design.md, translucent
surfaces: the camera side): a pane
blends over the wall behind it, depth peeling composites its layers in order, the gathered list
(the default) meets exact, MBOIT comes close to it, and an opaque-only scene runs none of it."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import clrays.session
from clrays.reference.exact import exact_pixels, render_exact
from clrays.reference.metrics import depth_edges, depth_map, image_error
from clrays.reference.translucency import film_pixels
from clrays.scene.load import load_scene, parse_scene
from clrays.session import Renderer
from clrays.stages.transparency import translucent_films

ROOT = Path(__file__).resolve().parents[2]

# A wall, a pane in front of it lit from the camera's side; the light comes in at an angle, so
# that the pane's own shadow falls on the wall beside the pixels where the camera sees it.
PANE = """version: 1
image: {width: 48, height: 36}
camera: {position: [0, 1, 6], look_at: [0, 1, 0], fov_deg: 40}
lights: [{type: directional, direction: [-1.2, -1, -1], irradiance: 2}]
objects:
  - {type: box, min: [-4, -1, -1.2], max: [4, 4, -1], albedo: 0.7}
  - {type: plane, center: [0, 1, 3], normal: [0, 0, 1], size: 1.5, albedo: [0.9, 0.6, 0.3], opacity: [0.2, 0.9, 0.5]}
"""
OPACITY = np.array([0.2, 0.9, 0.5])


@pytest.mark.parametrize("kind", ["depth_peeling", "mboit"])
@pytest.mark.parametrize("method", ["minmax", "raymarch"])
def test_a_pane_blends_over_the_wall(renderer, method, kind):
    """Fog off: opacity · (the pane, were it opaque) + (1 − opacity) · (the wall, with no pane)."""
    blend = renderer.render(parse_scene(PANE, overrides=[f"render.transparency={kind}"]), method).image
    pane = renderer.render(parse_scene(PANE, overrides=["objects.1.opacity=1"]), method).image
    wall = renderer.render(parse_scene(PANE, overrides=["objects.1.opacity=1", "objects.1.size=1e-4"]), method).image
    # Where the camera sees the pane: lit with the wall black (not where the pane's shadow falls).
    seen = renderer.render(parse_scene(PANE, overrides=["objects.1.opacity=1", "objects.0.albedo=0"]),
                           method).image.max(axis=2) > 1e-3
    inside = seen & np.roll(seen, 1, 0) & np.roll(seen, -1, 0) & np.roll(seen, 1, 1) & np.roll(seen, -1, 1)
    assert inside.sum() > 100
    expected = OPACITY * pane + (1 - OPACITY) * wall
    error = np.abs(blend - expected)[inside].max() / expected[inside].max()
    assert error < 0.005  # the bound; measured 3e-8 (peeling) and 6e-8 (moments), float32 rounding


def test_an_opaque_scene_skips_the_stage(renderer):
    scene = parse_scene(PANE, overrides=["objects.1.opacity=1"])
    result = renderer.render(scene, "minmax", reuse=False)
    assert result.stage_status["transparency"] == "skipped" and "transparency" not in result.stage_ms


def _films_run_per_film(*args, **kwargs):
    """translucent_films with MBOIT's fog run up to each film, as peeling's, not in its one
    weighted walk: the path the tests compare that walk with."""
    return translucent_films(*args, **kwargs, weighted_walk=False)


def small_row(*overrides):
    return load_scene(ROOT / "scenes" / "glass_row.yaml",
                      overrides=["image.width=64", "image.height=36", *overrides])


class CompositeSpy:
    """Keeps the layers and the composite's output of the frames rendered while it is installed."""

    def __init__(self, monkeypatch):
        self.frames = []
        original = clrays.session.composite

        def spy(device, buffers, rastered, layers, timer, *light_layers):
            out = original(device, buffers, rastered, layers, timer, *light_layers)
            samples = layers.samples
            read = lambda buffer, shape, dtype: device.read(buffer, shape, dtype)  # noqa: E731
            self.frames.append({
                "depth": read(layers.depth, (layers.slots, samples), np.uint32).view(np.float32).astype(np.float64),
                "tri": read(layers.tri, (layers.slots, samples), np.int32),
                "scatter": read(layers.scatter, (layers.slots, samples, 4), np.float32)[..., :3].astype(np.float64),
                "transmittance": read(out[0], (samples, 4), np.float32)[:, :3],
                "in_front": read(out[1], (samples, 4), np.float32)[:, :3],
                "opacity": buffers.inputs.scene.geometry.opacity_or_ones()})
            return out

        monkeypatch.setattr(clrays.session, "composite", spy)


@pytest.mark.parametrize("method", ["minmax", "raymarch"])
def test_peeling_every_layer_is_the_sorted_composite(renderer, monkeypatch, method):
    """Black panes (albedo 0: S_k = 0) in fog, so each layer adds α_k·T(z_k⁻)·L(0, z_k): the
    layers MBOIT gathers in no order, sorted and composited in float64, against 8-layer peeling
    (more layers than the scene has). MBOIT's fog runs up to each film here, as peeling's, not
    in its one walk, so that its films carry their L(0, z_k)."""
    spy = CompositeSpy(monkeypatch)
    monkeypatch.setattr(clrays.session, "translucent_films", _films_run_per_film)
    black = [f"objects.{i}.albedo=0" for i in range(2, 7)]
    renderer.render(small_row(*black, "render.transparency={type: mboit}"), method, reuse=False)
    renderer.render(small_row(*black, "render.transparency={type: depth_peeling, layers: 8}"), method, reuse=False)
    gathered, peeled = spy.frames
    assert gathered["depth"].shape[0] == 5 and peeled["depth"].shape[0] == 5  # five panes, all met
    opacity = gathered["opacity"]
    through = np.ones((gathered["depth"].shape[1], 3))
    light = np.zeros_like(through)
    order = np.argsort(np.where(gathered["tri"] >= 0, gathered["depth"], np.inf), axis=0)
    for k in range(order.shape[0]):
        slot = order[k]
        column = np.arange(order.shape[1])
        tri = gathered["tri"][slot, column]
        alpha = np.where((tri >= 0)[:, None], opacity[np.maximum(tri, 0)], 0.0)
        light += alpha * through * gathered["scatter"][slot, column]
        through *= 1 - alpha
    assert (gathered["tri"] >= 0).sum(axis=0).max() == 5 and light.max() > 0
    np.testing.assert_allclose(peeled["transmittance"], through, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(peeled["in_front"], light, rtol=1e-4, atol=1e-5 * light.max())


def test_peeling_drops_the_layers_behind_the_last(renderer):
    images = {k: renderer.render(small_row(f"render.transparency={{type: depth_peeling, layers: {k}}}")).image
              for k in (1, 4, 5, 8)}
    np.testing.assert_array_equal(images[5], images[8])  # five panes: the sixth pass finds nothing
    assert image_error(images[4], images[8]).rmse > 1e-5
    assert image_error(images[1], images[8]).rmse > 0.02


def test_moments_come_close_to_eight_layer_peeling(renderer):
    """MBOIT (4 moments, log warp, the defaults) against 8-layer peeling on the five-pane row:
    bench/RESULTS.md's history has the figures at full size; measured here at 64×36: 1.07 % (the fog
    walked once per sample, transparency_walk.cl; 1.07 % too with the fog run up to each film)."""
    peeled = renderer.render(small_row("render.transparency={type: depth_peeling, layers: 8}")).image
    moments = renderer.render(small_row("render.transparency=mboit")).image
    assert image_error(moments, peeled).rmse < 0.02


_EXACT: dict = {}


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["depth_peeling", "mboit"])
@pytest.mark.parametrize("method", ["raymarch", "minmax"])
def test_glass_pane_with_its_film_agrees_with_exact(renderer, method, kind):
    """scenes/glass_pane.yaml at 160×90, the pane seen by the camera included, depth edges out:
    within 1 % relative RMSE of exact (measured: raymarch 0.18 %, minmax 0.34 %), and the
    pixels that see the pane within 0.1 % (measured 1.2e-5: its lit face outshines the fog)."""
    overrides = ["image.width=160", "image.height=90", "render.steps=1024", f"render.transparency={kind}"]
    scene = load_scene(ROOT / "scenes" / "glass_pane.yaml", overrides=overrides)
    if "glass_pane" not in _EXACT:
        _EXACT["glass_pane"] = render_exact(scene)
    reference = _EXACT["glass_pane"]
    edges, films = depth_edges(depth_map(scene)), film_pixels(scene)
    assert (films & ~edges).sum() > 40
    image = renderer.render(scene, method).image
    assert image_error(image, reference, edges).rmse < 0.01
    assert image_error(image, reference, edges | ~films).rmse < 0.001


@pytest.mark.parametrize("method", ["minmax", "raymarch"])
def test_moments_one_walk_is_the_per_film_composite(renderer, monkeypatch, method):
    """MBOIT's fog walked once per sample, weighted by T(s) − T(D) (transparency_walk.cl), against
    the in-scatter runs up to each film composited with MBOIT's weights (the path peeling takes,
    kept reachable): black panes (S_k = 0), so the films' light in front is all fog. The two
    evaluate the same estimate of T, at the films or along the ray between them."""
    spy = CompositeSpy(monkeypatch)
    black = [f"objects.{i}.albedo=0" for i in range(2, 7)]
    scene = small_row(*black, "render.transparency={type: mboit}")
    walked = renderer.render(scene, method, reuse=False)
    monkeypatch.setattr(clrays.session, "translucent_films", _films_run_per_film)
    per_film = renderer.render(scene, method, reuse=False)
    walk, runs = spy.frames
    films = (runs["tri"] >= 0).any(axis=0)
    assert films.sum() > 300 and not runs["scatter"].any(axis=(0, 2))[~films].any()
    assert not walk["scatter"].any()  # no run per film: the walk alone
    np.testing.assert_array_equal(walk["transmittance"], runs["transmittance"])
    fog = runs["in_front"][films]
    error = np.sqrt(np.mean((walk["in_front"][films] - fog) ** 2)) / fog.mean()
    assert error < 0.008, error  # measured 0.43 % (minmax, 4 pieces), 0.42 % (raymarch)
    assert image_error(walked.image, per_film.image).rmse < 0.001  # measured 0.016 %


def test_moments_fog_march_takes_the_scene_step_spacing(renderer, monkeypatch):
    """raymarch's weighted fog march is the raymarch kernel with the scene's `step_spacing`:
    with black panes the films' light in front is that march alone, so at a few steps the two
    spacings must give different fog (the march had once ignored the key and always taken
    equiangular steps)."""
    spy = CompositeSpy(monkeypatch)
    black = [f"objects.{i}.albedo=0" for i in range(2, 7)]
    for spacing in ("equiangular", "uniform"):
        renderer.render(small_row(*black, "render.transparency={type: mboit}", "render.steps=4",
                                  f"render.step_spacing={spacing}"), "raymarch", reuse=False)
    equiangular, uniform = spy.frames
    films = equiangular["in_front"][..., :3].any(axis=-1)
    assert films.sum() > 300
    difference = np.abs(equiangular["in_front"][films] - uniform["in_front"][films]).mean()
    assert difference > 0.01 * equiangular["in_front"][films].mean(), difference  # measured 2.9 % of the mean


_ROW_EXACT: dict = {}


def _row_against_exact(renderer, size, *overrides, method="minmax"):
    """The relative RMSE (depth edges out) of glass_row at `size` against exact."""
    width, height = size
    scene = load_scene(ROOT / "scenes" / "glass_row.yaml",
                       overrides=[f"image.width={width}", f"image.height={height}", *overrides])
    key = (size, tuple(o for o in overrides if not o.startswith("render.")))
    if key not in _ROW_EXACT:
        _ROW_EXACT[key] = render_exact(scene)
    return image_error(renderer.render(scene, method).image, _ROW_EXACT[key], depth_edges(depth_map(scene))).rmse


@pytest.mark.parametrize("method", ["minmax", "raymarch"])
def test_the_default_transparency_is_exact_on_the_row(renderer, method):
    """The default, `gathered`, weights each film by the exact product of the (1 − α) in front of
    it, read from the sample's gathered list, and walks the fog once with its pieces at the films:
    on the five-pane row at 64×36 it meets exact as 8-layer peeling does (measured: minmax
    0.0072 %, raymarch 0.0067 %), where MBOIT's 4-moment estimate was 1.1 %."""
    error = _row_against_exact(renderer, (64, 36), method=method)
    assert error < 0.002


def test_mboit_stays_its_estimate(renderer):
    """`mboit` is still the 4-moment estimate (measured 1.25 % at 64×36), not the exact list."""
    error = _row_against_exact(renderer, (64, 36), "render.transparency=mboit")
    assert error > 0.005


def test_a_films_coloured_shadow_edge_is_where_exact_puts_it(renderer):
    """Surfaces alone (no fog) at 160×90: a film in the shadow of a nearer pane's edge takes the
    light through a shadow ray, not the layers' lookup, whose edge is a texel wide (a row of
    five pixels 5.6 % dark before; the image measured 4e-5 %, 0.82 % through the map)."""
    error = _row_against_exact(renderer, (160, 90), "medium.sigma_s=0", "medium.sigma_a=0")
    through_map = _row_against_exact(renderer, (160, 90), "medium.sigma_s=0", "medium.sigma_a=0",
                                     "render.surface_shadows=map")
    assert error < 0.0005 < through_map


def test_films_of_many_triangles_take_the_layers_lookup(renderer, monkeypatch):
    """Past FILM_SHADOW_RAY_TRIANGLES translucent triangles (a mesh of millions would not
    finish, every film's ray testing each), the films' light comes through the layers' lookup:
    with the limit below glass_row's ten, the error is the lookup's (measured 0.29 %; the
    other surfaces' shadows exact), not the rays' (4e-5 %, bounded at 0.05 % above)."""
    from clrays.stages import transparency

    monkeypatch.setattr(transparency, "FILM_SHADOW_RAY_TRIANGLES", 9)
    fresh = Renderer(renderer.device, reuse=False)  # (the session keeps the frame the rays made)
    assert _row_against_exact(fresh, (160, 90), "medium.sigma_s=0", "medium.sigma_a=0") > 0.0005


def test_a_shadow_edge_beyond_the_lookups_texels_is_seen(renderer):
    """A floor pixel of the row at 640×360 whose point sees the light just below a pane's edge:
    the lookup, a texel up the normal, had 3 × 3 texels all in the pane's shadow, so the layers
    answered and the pixel took the pane's colour (80 % dark in red). The 5 × 5 test sends it a
    shadow ray (measured: within 1e-7 of exact)."""
    scene = load_scene(ROOT / "scenes" / "glass_row.yaml",
                       overrides=["image.width=640", "image.height=360", "medium.sigma_s=0", "medium.sigma_a=0"])
    expected = exact_pixels(scene, np.array([257]), np.array([356]))[0]
    pixel = renderer.render(scene, "minmax").image[257, 356]
    np.testing.assert_allclose(pixel, expected, rtol=1e-3)


@pytest.mark.parametrize("method", ["minmax", "raymarch"])
def test_the_gathered_walk_is_the_per_film_composite(renderer, monkeypatch, method):
    """`gathered`'s fog walked once, its pieces ending at the films (five films, WALK_PIECES + 1),
    against the in-scatter runs up to each film: black panes, so the films' light in front is all
    fog. T is exact and constant over each piece, so minmax's walk is the per-film composite
    (measured 9e-8 relative); raymarch weights each step at its point, a step that straddles a
    film takes one side's T (measured 0.045 %)."""
    spy = CompositeSpy(monkeypatch)
    black = [f"objects.{i}.albedo=0" for i in range(2, 7)]
    scene = small_row(*black, "render.transparency={type: gathered}")
    renderer.render(scene, method, reuse=False)
    monkeypatch.setattr(clrays.session, "translucent_films", _films_run_per_film)
    renderer.render(scene, method, reuse=False)
    walk, runs = spy.frames
    films = (runs["tri"] >= 0).any(axis=0)
    assert films.sum() > 300 and not walk["scatter"].any()
    fog = runs["in_front"][films]
    error = np.sqrt(np.mean((walk["in_front"][films] - fog) ** 2)) / fog.mean()
    assert error < (1e-5 if method == "minmax" else 0.002)


def test_more_films_than_pieces_walk_close_to_the_per_film_composite(renderer, monkeypatch):
    """Seven black panes, more than WALK_PIECES + 1: `gathered`'s walk takes even pieces in the
    warp, each weighted by the exact T at its middle, against the in-scatter runs up to each film
    (measured 0.052 %, minmax)."""
    extra = "".join(f"  - {{type: plane, center: [{x}, 1.5, {z}], normal: [0, 0, 1], size: 2.2, segments: 1, "
                    f"opacity: 0.3}}\n" for x, z in ((0.2, 0.4), (0.6, -1.2)))
    text = (ROOT / "scenes" / "glass_row.yaml").read_text().replace("render:", extra + "render:")
    black = [f"objects.{i}.albedo=0" for i in range(2, 9)]
    scene = parse_scene(text, overrides=["image.width=64", "image.height=36", *black])
    spy = CompositeSpy(monkeypatch)
    renderer.render(scene, "minmax", reuse=False)
    monkeypatch.setattr(clrays.session, "translucent_films", _films_run_per_film)
    renderer.render(scene, "minmax", reuse=False)
    walk, runs = spy.frames
    assert (runs["tri"] >= 0).sum(axis=0).max() == 7
    films = (runs["tri"] >= 0).any(axis=0)
    fog = runs["in_front"][films]
    error = np.sqrt(np.mean((walk["in_front"][films] - fog) ** 2)) / fog.mean()
    assert error < 0.002
