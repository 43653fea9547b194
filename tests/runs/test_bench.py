"""The benchmark's bookkeeping, and a smoke run of `clrays bench` end to end."""
import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from clrays.runs.bench import BenchPoint, cheapest_at, error_pixels, pareto_front, summary
from clrays.cli import main

DEMO = Path(__file__).resolve().parents[2] / "scenes" / "demo.yaml"


def _point(method, ms, rmse, setting=""):
    return BenchPoint("s", "64x36", method, setting or f"{ms}", ms, 0.0, rmse, rmse, rmse, 1.0)


def test_pareto_front_keeps_only_undominated_points():
    points = [_point("a", 10, 0.5), _point("a", 20, 0.2), _point("a", 30, 0.3), _point("a", 40, 0.1)]
    assert [p.frame_ms for p in pareto_front(points)] == [10, 20, 40]


def test_speedup_compares_the_cheapest_points_that_reach_each_error():
    points = [_point("raymarch", 100, 0.04), _point("raymarch", 400, 0.009), _point("raymarch", 50, 0.2),
              _point("minmax", 20, 0.008), _point("minmax", 10, 0.03)]
    assert cheapest_at(points, "minmax", 0.01).frame_ms == 20
    (row,) = summary(points)
    assert row["speedup@1%"] == pytest.approx(400 / 20)
    assert row["speedup@5%"] == pytest.approx(100 / 10)
    assert cheapest_at(points, "raymarch", 0.001) is None


def test_error_pixels_are_fixed_and_distinct():
    ys, xs = error_pixels(64, 36, 100)
    again = error_pixels(64, 36, 100)
    assert (ys == again[0]).all() and (xs == again[1]).all()
    assert len(set(zip(ys.tolist(), xs.tolist()))) == 100
    assert len(error_pixels(8, 4, 1000)[0]) == 32


def test_bench_command_writes_csv_plot_and_summary(tmp_path):
    pytest.importorskip("matplotlib")  # the `bench` extra, which `make test` installs
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["bench", str(DEMO), "-r", "48x27", "--quick", "--repeats", "1",
                                       "--pixels", "300", "--out", str(out), "--cache", str(tmp_path / "cache")])
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader(open(out / "bench.csv")))
    assert {r["method"] for r in rows} == {"raymarch", "minmax", "moments"}
    assert all(float(r["frame_ms"]) > 0 and 0 <= float(r["rel_rmse"]) < 10 for r in rows)
    assert (out / "bench.png").stat().st_size > 1000
    assert "speedup" in (out / "summary.md").read_text()
    assert any((tmp_path / "cache").iterdir())  # exact was cached


def test_bench_rejects_a_bad_resolution():
    result = CliRunner().invoke(main, ["bench", str(DEMO), "-r", "640by360"])
    assert result.exit_code == 2 and "WIDTHxHEIGHT" in result.output


def test_reference_cache_keeps_exact_on_pixels_on_disk(tmp_path, monkeypatch, device):
    from clrays.scene.load import load_scene
    from clrays.session import Renderer
    from clrays.runs.references import EXACT, ReferenceCache

    scene = load_scene(DEMO, ["image.width=16", "image.height=9"])
    pixels = error_pixels(16, 9, 20)
    cache = ReferenceCache(tmp_path, Renderer(device))
    on_pixels = cache.radiance(scene, EXACT, pixels)
    whole = cache.radiance(scene, EXACT)
    assert on_pixels.shape == (20, 3) and whole.shape == (9, 16, 3)
    np.testing.assert_allclose(on_pixels, whole[pixels], rtol=1e-6)  # float64 on the pixels, float32 frame
    assert cache.edges(scene, pixels).shape == (20,) and cache.edges(scene).shape == (9, 16)

    def recomputed(*args, **kwargs):
        raise AssertionError("the cached reference was computed again")

    monkeypatch.setattr("clrays.reference.exact.exact_pixels", recomputed)
    fresh = ReferenceCache(tmp_path, Renderer(device))
    coarser = replace(scene, render=replace(scene.render, slices=64))  # exact reads no render setting
    np.testing.assert_array_equal(fresh.radiance(coarser, EXACT, pixels), on_pixels)
    assert fresh.error(scene, EXACT, whole, pixels).rmse < 1e-6
