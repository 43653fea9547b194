"""Every label a frame times is one of the session's STAGE_ORDER, the figure's order that
results.csv's columns and the stats follow: a stage whose label is missing there would fall
to the end of a table, out of its place."""
from __future__ import annotations

from pathlib import Path

import pytest

from clrays.scene.load import load_scene
from clrays.session import STAGE_ORDER

SCENES = Path(__file__).resolve().parents[2] / "scenes"


@pytest.mark.parametrize("name, method, overrides", [
    ("demo", "minmax", ()), ("demo", "raymarch", ()), ("demo", "volume_moments", ()),
    ("gobo", "minmax", ()), ("glass_row", "minmax", ()), ("glass_row", "raymarch", ()),
    ("lattice", "minmax", ()), ("bunny", "minmax", ("render.surface_shadows=filtered",)),
])
def test_every_timed_label_has_its_place(renderer, name, method, overrides):
    scene = load_scene(SCENES / f"{name}.yaml", overrides=["image.width=32", "image.height=18", *overrides])
    result = renderer.render(scene, method, reuse=False)
    assert set(result.stage_ms) <= set(STAGE_ORDER), set(result.stage_ms) - set(STAGE_ORDER)
