"""Render passes (clrays/passes.py) on every method: the image is surface × transmittance +
in_scatter (the background's attenuated colour being surface × transmittance where no
surface is seen), and the lights' in_scatter_light<i> add up to in_scatter, each within
1e-4 of the image's peak; in_scatter with black surfaces is the volume `exact` renders; a
frame without passes is the same image, with no pass buffer allocated."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from clrays.reference.metrics import image_error
from clrays.scene.load import parse_scene
from clrays.session import Renderer

SCENE = """
version: 1
image: {width: 48, height: 32, spp: SPP}
camera: {position: [0, 2.5, 7], look_at: [0, 1.2, 0], far: 12}
background: [0.05, 0.1, 0.2]
lights:
  - {type: point, position: [1.5, 4, 0.5], intensity: [40, 35, 30]}
  - {type: spot, position: [-2, 4.5, 1], direction: [0.3, -1, -0.1], cone_deg: 25, intensity: 50}
  - {type: directional, direction: [0.4, -1, -0.3], irradiance: 0.8}
medium: {sigma_s: [0.08, 0.1, 0.12], sigma_a: 0.02, phase: {type: hg, g: 0.3}}
objects:
  - {type: plane, center: [0, 0, -2], normal: [0, 1, 0], size: 6, albedo: 0.5}
  - {type: sphere, center: [0.8, 1.0, 0.5], radius: 0.8, albedo: [0.8, 0.5, 0.3]}
  - {type: box, min: [-2.0, 2.6, -2.5], max: [-1.2, 2.8, 1.5], albedo: 0.6}
"""
ALL = ["in_scatter", "transmittance", "surface", "depth", "in_scatter_light0", "in_scatter_light1",
       "in_scatter_light2"]
#: Every method, and the epipolar methods' other paths (pixel sampling, a linear walk).
CASES = [("minmax", ()), ("minmax", ("render.sampling=pixel",)), ("minmax", ("render.traversal=scan",)),
         ("volume_moments", ()), ("raymarch", ("render.steps=64",)), ("exact", ())]


def _scene(spp=1, aovs=ALL, extra=()):
    scene = parse_scene(SCENE.replace("SPP", str(spp)), "passes.yaml")
    render = dataclasses.replace(scene.render, aovs=tuple(aovs))
    for item in extra:  # `key=value` on the render settings
        key, value = item.removeprefix("render.").split("=")
        render = dataclasses.replace(render, **{key: int(value) if value.isdigit() else value})
    return dataclasses.replace(scene, render=render)


@pytest.fixture(scope="module")
def renderer():
    return Renderer(reuse=False)


@pytest.mark.parametrize("spp", [1, 4])
@pytest.mark.parametrize("method,extra", CASES, ids=[" ".join((m, *e)) for m, e in CASES])
def test_identities(renderer, method, extra, spp):
    result = renderer.render(_scene(spp, extra=extra), method)
    image, passes = result.image, result.passes
    assert sorted(passes) == sorted(ALL)
    peak = float(image.max())
    assert peak > 0
    beauty = passes["surface"] * passes["transmittance"] + passes["in_scatter"]
    lights = sum(passes[f"in_scatter_light{i}"] for i in range(3))
    print(f"passes {method} {' '.join(extra)} spp {spp}: |S·T + I − image| {np.abs(beauty - image).max() / peak:.1e}, "
          f"|Σ lights − I| {np.abs(lights - passes['in_scatter']).max() / peak:.1e} of the peak")
    assert np.abs(beauty - image).max() <= 1e-4 * peak
    assert np.abs(lights - passes["in_scatter"]).max() <= 1e-4 * peak
    # Each light's part is its own: none is zero, and none is the whole.
    for i in range(3):
        part = passes[f"in_scatter_light{i}"]
        assert part.max() > 1e-3 * peak and np.abs(part - passes["in_scatter"]).max() > 1e-3 * peak
    # The background: no depth, the background colour, the transmittance to the far end.
    depth = passes["depth"]
    assert depth.shape == image.shape[:2]
    empty = np.isinf(depth)
    assert 0 < empty.sum() < empty.size and np.all(depth[~empty] > 0) and np.all(depth[~empty] <= 12)
    sigma_t = np.array([0.10, 0.12, 0.14])
    if spp == 1:
        np.testing.assert_allclose(passes["surface"][empty], np.broadcast_to([0.05, 0.1, 0.2], (empty.sum(), 3)),
                                   rtol=1e-5)
        np.testing.assert_allclose(passes["transmittance"][empty],
                                   np.broadcast_to(np.exp(-sigma_t * 12), (empty.sum(), 3)), rtol=1e-5)
        np.testing.assert_allclose(passes["transmittance"][~empty],
                                   np.exp(-sigma_t * depth[~empty][:, None]), rtol=1e-5)


@pytest.mark.parametrize("method,extra", CASES[:-1], ids=[" ".join((m, *e)) for m, e in CASES[:-1]])
def test_in_scatter_is_the_exact_volume(renderer, method, extra):
    """With black surfaces and background, exact's image is the volume's light alone."""
    scene = _scene(extra=extra)
    black = dataclasses.replace(scene, background=np.zeros(3), geometry=dataclasses.replace(
        scene.geometry, albedo=np.zeros_like(scene.geometry.albedo)))
    reference = renderer.render(dataclasses.replace(black, render=dataclasses.replace(black.render, aovs=())),
                                "exact").image
    in_scatter = renderer.render(scene, method).passes["in_scatter"]  # the surfaces' colour does not reach it
    print(f"in_scatter {method} {' '.join(extra)} against exact, black surfaces: {image_error(in_scatter, reference)}")
    assert image_error(in_scatter, reference).rmse < 0.005


@pytest.mark.parametrize("method", ["minmax", "volume_moments", "raymarch"])
def test_no_pass_no_buffer(method):
    """Without passes the image is the same bits, and the frame allocates the pass buffers' bytes less."""
    plain, asked = _scene(aovs=()), _scene()
    if method == "raymarch":
        plain, asked = (dataclasses.replace(s, render=dataclasses.replace(s.render, steps=64)) for s in (plain, asked))
    without = Renderer(reuse=False).render(plain, method)
    with_passes = Renderer(reuse=False).render(asked, method)
    assert without.passes is None
    np.testing.assert_array_equal(without.image, with_passes.image)
    pixels = 48 * 32
    extra = 48 * pixels + (3 * 16 * pixels if method == "raymarch" else 0)  # shade's terms; raymarch: each light alone
    assert with_passes.device_bytes - without.device_bytes == extra


@pytest.mark.parametrize("method", ["minmax", "volume_moments", "raymarch", "exact"])
def test_identities_with_the_eye_in_a_lamp(renderer, method):
    """The eye at the point light: the epipolar methods take its in-scattering on the host (stages/lamp.py)."""
    scene = parse_scene(SCENE.replace("SPP", "1").replace("position: [1.5, 4, 0.5]", "position: [0, 2.5, 7]"),
                        "passes.yaml")
    result = renderer.render(dataclasses.replace(scene, render=dataclasses.replace(scene.render, aovs=tuple(ALL))),
                             method)
    passes, peak = result.passes, float(result.image.max())
    assert passes["in_scatter_light0"].max() > 0.5 * peak  # the lamp's light is most of the image
    assert np.abs(passes["surface"] * passes["transmittance"] + passes["in_scatter"] - result.image).max() <= 1e-4 * peak
    assert np.abs(sum(passes[f"in_scatter_light{i}"] for i in range(3)) - passes["in_scatter"]).max() <= 1e-4 * peak
