"""Lights below the error budget (clrays/light_skip.py): the bound holds a light's own image
from above, a negligible light is left out of a frame of lights in turn within the budget
and `--stats` says so, a guess that fails the check after the frame renders the light after
all, and what no bound covers is never left out."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from clrays import light_skip
from clrays.light_skip import SKIP_BUDGET, candidates, contribution_bound, mean_luminance
from clrays.scene.load import load_scene
from clrays.scene.model import DirectionalLight, PointLight
from clrays.session import Renderer
from conftest import run_cli

#: The demo's room at 64×36: its light over the roof, and a dim one behind the camera.
SCENE = """version: 1
image: {width: 64, height: 36, spp: 1}
camera: {position: [0, 2.0, 9.5], look_at: [0, 2.4, 0], up: [0, 1, 0], fov_deg: 55, far: 40}
lights:
  - {type: point, position: [0.3, 7.5, -1.0], intensity: [260, 230, 190]}
  - {type: point, position: [0, 3, 30], intensity: [0.01, 0.01, 0.01]}
medium: {sigma_s: 0.08, sigma_a: 0.01, phase: {type: hg, g: 0.5}}
background: 0
objects:
  - {type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 30, albedo: 0.5}
  - {type: sphere, center: [1.6, 1.0, 0.5], radius: 1.0, albedo: [0.8, 0.5, 0.3]}
  - {type: box, min: [-3.0, 0, -1.5], max: [-1.8, 2.4, -0.3], albedo: 0.7}
  - {type: box, min: [-1.0, 4.6, -4.5], max: [-0.55, 4.8, 2.5], albedo: 0.6}
"""


@pytest.fixture(scope="module")
def scene_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("skip") / "dim.yaml"
    path.write_text(SCENE)
    return path


@pytest.fixture(scope="module")
def scene(scene_path):
    return load_scene(scene_path)


def _luminance(image: np.ndarray) -> np.ndarray:
    return np.asarray(image, np.float64) @ light_skip.LUMINANCE


def test_the_bound_holds_the_lights_own_image_from_above(device, scene):
    for index, light in enumerate(scene.lights):
        alone = replace(scene, lights=(light,))
        image = Renderer(device).render(alone).image
        bound = contribution_bound(scene, index)
        assert 0 < _luminance(image).max() <= bound, (index, _luminance(image).max(), bound)


def test_a_negligible_light_is_skipped_within_the_budget(device, scene):
    skipped = Renderer(device).render(scene)
    whole = Renderer(device, skip_lights=False).render(scene)
    assert skipped.skipped_lights is not None and skipped.skipped_lights.indices == (1,)
    assert whole.skipped_lights is None
    difference = np.abs(_luminance(skipped.image) - _luminance(whole.image))
    assert difference.max() <= SKIP_BUDGET * mean_luminance(whole.image)
    assert skipped.skipped_lights.bound <= skipped.skipped_lights.allowed
    # the dim light does add light: the skipped image is not the whole one
    assert not np.array_equal(skipped.image, whole.image)


def test_stats_list_the_skipped_light(scene_path, tmp_path):
    code, output = run_cli("render", scene_path, "-o", tmp_path / "dim.npy", "--stats")
    assert code == 0, output
    assert "1 of 2 lights below the error budget, skipped" in output


def test_a_guess_over_the_budget_renders_the_light_after_all(device, scene, monkeypatch):
    # every light but the brightest a candidate: the check after the frame finds the
    # skipped light's bound far over the budget and renders the frame again with it
    bright = replace(scene, lights=(scene.lights[0], replace(scene.lights[0], position=np.array([-0.3, 7.5, -1.0]))))
    monkeypatch.setattr(light_skip, "CHOOSE_FRACTION", 1e9)
    assert candidates(bright)[0] == (0,) or candidates(bright)[0] == (1,)
    guessed = Renderer(device).render(bright)
    monkeypatch.undo()
    whole = Renderer(device, skip_lights=False).render(bright)
    assert guessed.skipped_lights is None
    np.testing.assert_array_equal(guessed.image, whole.image)  # the frame again, every light in its turn


def test_what_no_bound_covers_is_never_skipped(scene):
    sun = DirectionalLight(direction=np.array([0.0, -1.0, 0.0]), irradiance=np.full(3, 1e-9))
    assert contribution_bound(replace(scene, lights=(scene.lights[0], sun)), 1) == math.inf
    assert candidates(replace(scene, lights=(sun, sun))) == ((), 0.0)
    # a light in the view: the lamp's ball bounds its in-scattering, finite but large
    seen = PointLight(position=np.array([0.0, 2.4, 0.0]), intensity=np.full(3, 0.01))
    assert 1e3 * contribution_bound(scene, 1) < contribution_bound(replace(scene, lights=(scene.lights[0], seen)), 1)
    dark = PointLight(position=np.array([0.0, 3.0, 30.0]), intensity=np.zeros(3))
    assert contribution_bound(replace(scene, lights=(scene.lights[0], dark)), 1) == 0.0
    assert candidates(scene, enabled=False) == ((), 0.0)
    assert candidates(replace(scene, lights=scene.lights[1:])) == ((), 0.0)  # one light is never left out
