"""The time `exact` announces before it runs (clrays.reference.exact.estimate_seconds)
against the time it takes. The estimate was a flat 300 µs per ray and light, 1.4–2.6×
too high (69 s announced, 26.5 s taken for sun at 640×360), 2.1–5.4× on a quiet machine;
it now follows the triangle count and the light type, and was measured at 0.97–1.31× the
time taken on a quiet machine (exact.SECONDS_PER_RAY_LIGHT_DOUBLING)."""
from __future__ import annotations

import math
import time
from pathlib import Path

import pytest

from clrays.reference.exact import DIRECTIONAL_RAY_COST, estimate_seconds, render_exact
from clrays.scene.load import load_scene

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def test_estimate_follows_rays_lights_and_triangles():
    scene = load_scene(SCENES / "sun.yaml", ["image.width=64", "image.height=36"])
    twice = load_scene(SCENES / "sun.yaml", ["image.width=128", "image.height=36"])
    assert estimate_seconds(twice) == pytest.approx(2 * estimate_seconds(scene))
    point = load_scene(SCENES / "behind.yaml", ["image.width=64", "image.height=36"])
    assert scene.lights[0].type == "directional" and point.lights[0].type == "point"
    # the same rays: fewer triangles, a light that costs more a ray
    assert estimate_seconds(point) / estimate_seconds(scene) == pytest.approx(
        math.log2(point.geometry.count) / math.log2(scene.geometry.count) / DIRECTIONAL_RAY_COST)


@pytest.mark.parametrize("name", ["sun", "behind"])
def test_estimate_is_near_the_time_taken(name):
    """Measured on the 2-core machine at 128×72, quiet: the estimate 1.25× (sun) and 1.31×
    (behind) the time taken, 0.52 and 0.54 s; the band leaves room for a machine busy with
    other work (up to twice as slow), and excludes the old estimate's 2.6× and more."""
    scene = load_scene(SCENES / f"{name}.yaml", ["image.width=128", "image.height=72"])
    start = time.perf_counter()
    render_exact(scene)
    taken = time.perf_counter() - start
    ratio = estimate_seconds(scene) / taken
    print(f"{name}: estimate {estimate_seconds(scene):.2f} s, taken {taken:.2f} s, ratio {ratio:.2f}")
    assert 0.4 < ratio < 2.0
