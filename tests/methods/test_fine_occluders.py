"""Volume visibility with occluders finer than the map the image alone derives: scenes/grate.yaml,
1 cm slats every 4 cm under a point light (docs/stability.md, "Fine occluders and closed rooms")."""
from __future__ import annotations

from pathlib import Path

import pytest

from clrays.reference.metrics import depth_edges, depth_map, image_error
from clrays.scene.costs import with_derived_sizes
from clrays.scene.load import load_scene

GRATE = Path(__file__).resolve().parents[2] / "scenes" / "grate.yaml"


@pytest.mark.parametrize("method, bound", [("minmax", 0.5), ("raymarch", 0.5)])
def test_the_grate_at_default_sizes_matches_exact(renderer, method, bound):
    """The slats span 2.1 texels of the 1024² cube face that 96×64 derives from the image (a
    diagonal of 100 pixels or more gets the full map); the map grows to 4096² (8.6 texels).
    Relative RMSE against exact, depth edges out, measured on PoCL: minmax 0.202 % (0.404 %
    when 96×64 derived 512², grown to 2048²; 5.67 % with the 512² map alone), raymarch
    0.361 % (0.494 %; 5.65 %)."""
    scene = load_scene(GRATE, overrides=["image.width=96", "image.height=64"])
    exact = renderer.render(scene, "exact").image
    error = image_error(renderer.render(scene, method).image, exact, depth_edges(depth_map(scene)))
    print(f"grate 96×64, {method} at default sizes against exact: {error}")
    assert error.rmse < bound / 100
    assert with_derived_sizes(scene).render.shadow_map == 4096


LATTICE = Path(__file__).resolve().parents[2] / "scenes" / "lattice.yaml"


@pytest.mark.xfail(strict=True, raises=AssertionError, reason="the lattice's bars and their slanted sides cut "
                   "the sunlight into slivers under a map texel wide, which no texel centre sees, and rays along "
                   "the shafts cross 20-50 of them: measured minmax 1.79 % relative RMSE against exact at 96×64 "
                   "(0.5 % asked); `clrays tune --target-error 0.5` reaches 0.49 % at 320×180 with 4× the sizes")
def test_the_lattice_at_default_sizes_matches_exact(renderer):
    """scenes/lattice.yaml, a window's lattice as a relief under a sun, at 96×64 with the sizes
    the image derives (docs/stability.md, "Fine occluders and closed rooms")."""
    scene = load_scene(LATTICE, overrides=["image.width=96", "image.height=64"])
    exact = renderer.render(scene, "exact").image
    error = image_error(renderer.render(scene, "minmax").image, exact, depth_edges(depth_map(scene)))
    print(f"lattice 96×64, minmax at default sizes against exact: {error}")
    assert error.rmse < 0.005
