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


def test_the_lattice_at_default_sizes_matches_exact(renderer):
    """scenes/lattice.yaml, a window's lattice as a relief under a sun, at 96×64 with the sizes
    the image derives (docs/stability.md, "Fine occluders and closed rooms"). The walks cut
    the relief in each ray's own half-plane (stages/relief_cuts.py): measured 0.220 % relative
    RMSE against exact over the whole image, depth edges out (1.79 % with the relief in the
    volume's map, texel by texel)."""
    scene = load_scene(LATTICE, overrides=["image.width=96", "image.height=64"])
    exact = renderer.render(scene, "exact").image
    error = image_error(renderer.render(scene, "minmax").image, exact, depth_edges(depth_map(scene)))
    print(f"lattice 96×64, minmax at default sizes against exact: {error}")
    assert error.rmse < 0.005


@pytest.mark.parametrize("light", ["point", "spot"])
def test_the_lattice_under_a_lamp_matches_exact(renderer, tmp_path, light):
    """The lattice lit by a lamp outside the window instead of the sun: the relief's outline
    is taken as seen from the lamp's position, and its cuts in γ are angles at the lamp.
    Measured against exact at 96×64, whole image, depth edges out: point 0.127 %, spot 0.056 %
    (relative RMSE)."""
    text = LATTICE.read_text()
    lamp = {"point": "  - {type: point, position: [0.6, 3.6, -7.5], intensity: [60, 55, 45]}\n",
            "spot": "  - {type: spot, position: [0.6, 3.6, -7.5], direction: [-0.15, -0.25, 1.0], cone_deg: 40,\n"
                    "     intensity: [60, 55, 45]}\n"}[light]
    start = text.index("  - type: directional")
    text = text[:start] + lamp + text[text.index("medium:"):]
    path = tmp_path / "lattice_lamp.yaml"
    path.write_text(text.replace("textures/lattice.png", str(LATTICE.parent / "textures" / "lattice.png")))
    scene = load_scene(path, overrides=["image.width=96", "image.height=64"])
    exact = renderer.render(scene, "exact").image
    error = image_error(renderer.render(scene, "minmax").image, exact, depth_edges(depth_map(scene)))
    print(f"lattice under a {light} light, 96×64, minmax against exact: {error}")
    assert error.rmse < 0.005
