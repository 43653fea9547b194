"""What a hostile or careless user can do to a render and its output, and what clrays
answers: the same image whatever `camera.far` in a closed room, one-line errors for bad
options and unwritable outputs, no stale frames or temp files left behind."""
import warnings

import numpy as np
import pytest

from clrays import load_scene
from clrays.reference.radiometry import effective_far, lamp_radius

# A closed room: every camera ray hits a wall, so camera.far bounds nothing.
ROOM = """version: 1
image: {width: 32, height: 24}
camera: {position: [0, 1.5, 3.5], look_at: [0, 1.5, 0], fov_deg: 60, far: 40}
lights:
  - {type: point, position: [0.5, 3.2, 0.0], intensity: 20}
  - {type: spot, position: [-2, 3.5, -2], direction: [0.3, -1, 0.3], cone_deg: 30, intensity: 40}
medium: {sigma_s: 0.1, sigma_a: 0.02}
objects:
  - {type: box, min: [-4, 0, -4], max: [4, 4, 4], albedo: 0.5}
  - {type: box, min: [-0.5, 1.8, -0.5], max: [0.5, 2.0, 0.5], albedo: 0.7}
render: {steps: 256, shadow_map: 256}
"""


@pytest.fixture
def room(tmp_path):
    path = tmp_path / "room.yaml"
    path.write_text(ROOM)
    return path


def relative_rmse(image, reference) -> float:
    image, reference = image.astype(np.float64), reference.astype(np.float64)
    return float(np.sqrt(np.mean((image - reference) ** 2) / np.mean(reference ** 2)))


@pytest.mark.parametrize("method", ["minmax", "raymarch", "exact"])
def test_far_does_not_change_a_closed_room(renderer, room, method):
    # The lamp radius used to be 1e-6 × far: at far 1e7 a 10-unit ball without medium
    # swallowed the room (rel RMSE 0.86). It now follows the scene's size.
    near, distant = (load_scene(room, overrides=[f"camera.far={far}"]) for far in ("40", "1e7"))
    assert lamp_radius(near) == lamp_radius(distant)
    reference = renderer.render(near, method).image
    assert reference.mean() > 0.05
    assert relative_rmse(renderer.render(distant, method).image, reference) <= 1e-3


@pytest.mark.parametrize("method", ["minmax", "raymarch", "exact"])
def test_absurd_far_keeps_the_fog(renderer, method):
    # far reaches float32 clamped (radiometry.effective_far): no overflow warning, and the
    # fog of rays that hit nothing is there as with far 1e7.
    overrides = ["image.width=24", "image.height=14", "render.steps=128", "render.shadow_map=128"]
    sane = load_scene("scenes/demo.yaml", overrides=overrides + ["camera.far=1e7"])
    absurd = load_scene("scenes/demo.yaml", overrides=overrides + ["camera.far=1e300"])
    assert effective_far(absurd) == effective_far(sane) < 1e3
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        image = renderer.render(absurd, method).image
    assert np.isfinite(image).all()
    np.testing.assert_array_equal(image, renderer.render(sane, method).image)
    assert image[0].mean() > 0.02  # the top row sees only fog
