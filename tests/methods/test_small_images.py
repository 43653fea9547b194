"""Small images at their derived sizes against `exact`: from a diagonal of 100 pixels up
(96×64) the image derives the full 1024² shadow map, and with it 1024 slices and γ texels
(clrays.scene.costs.FULL_SHADOW_MAP_DIAGONAL), which keeps the scenes whose error the map
sets within 0.5 % relative RMSE; the 512² map that 4 texels per pixel of the diagonal gave
96×64 missed it (bench/RESULTS.md history, "The full map from a diagonal of 100 pixels")."""
from __future__ import annotations

from pathlib import Path

import pytest

from clrays.reference.metrics import depth_edges, depth_map, image_error
from clrays.scene.costs import with_derived_sizes
from clrays.scene.load import load_scene

SCENES = Path(__file__).resolve().parents[2] / "scenes"


#: (scene, frame or None for the base frame): relative RMSE measured on PoCL, whole 96×64
#: image, depth edges out, at the derived sizes; in brackets with the runs' ends at the
#: texels and the sun's map over its bounding sphere, then also with the 512² map derived before.
@pytest.mark.parametrize("name, frame", [
    ("sun", None),    # 0.248 % (0.328 %; 0.649 % with 512²)
    ("room", None),   # 0.044 % (0.275 %; 0.857 %)
    ("orbit", 10),    # 0.167 % (0.442 %; 1.578 %)
])
def test_a_96x64_image_is_within_half_a_percent_of_exact(renderer, name, frame):
    scene = load_scene(SCENES / f"{name}.yaml", overrides=["image.width=96", "image.height=64"])
    if frame is not None:
        scene = scene.animation.scene_at(scene, frame)
    render = with_derived_sizes(scene).render
    assert (render.shadow_map, render.slices, render.gamma_samples) == (1024, 1024, 1024)
    exact = renderer.render(scene, "exact").image
    error = image_error(renderer.render(scene, "minmax").image, exact, depth_edges(depth_map(scene)))
    print(f"{name} 96×64, minmax at derived sizes against exact: {error}")
    assert error.rmse < 0.005, f"{error}"
