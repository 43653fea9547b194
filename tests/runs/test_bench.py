"""The benchmark's bookkeeping, and a smoke run of `clrays bench` end to end."""
import csv
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from clrays.runs.bench import (BenchPoint, cheapest_at, error_pixels, markdown_summary, pareto_front,
                               raymarch_ladder, summary, target_tag)
from clrays.cli import main

DEMO = Path(__file__).resolve().parents[2] / "scenes" / "demo.yaml"


def _point(method, ms, rmse, setting=""):
    return BenchPoint("s", "64x36", method, setting or f"{ms}", ms, 0.0, rmse, rmse, rmse, 1.0, cpu_ms=ms)


def test_pareto_front_keeps_only_undominated_points():
    points = [_point("a", 10, 0.5), _point("a", 20, 0.2), _point("a", 30, 0.3), _point("a", 40, 0.1)]
    assert [p.frame_ms for p in pareto_front(points)] == [10, 20, 40]


def test_speedup_compares_the_cheapest_points_that_reach_each_error():
    points = [_point("raymarch", 100, 0.04), _point("raymarch", 400, 0.009), _point("raymarch", 50, 0.2),
              _point("minmax", 20, 0.008), _point("minmax", 10, 0.03), _point("minmax", 40, 0.004)]
    assert cheapest_at(points, "minmax", 0.01).frame_ms == 20
    (row,) = summary(points)
    assert row["speedup@1%"] == pytest.approx(400 / 20)
    assert row["speedup@5%"] == pytest.approx(100 / 10)
    assert row["speedup@0.5%"] is None and row["raymarch_setting@0.5%"] == "not reached"
    assert cheapest_at(points, "raymarch", 0.001) is None
    assert row["speedup_above@0.5%"] == pytest.approx(400 / 40)  # raymarch needs more than its 400 ms point
    assert row["speedup_above@1%"] is None
    assert "| 0.5% | 40 (40) | not reached (costliest: 400: 0.90% in 400 ms) | > 10.0× |" in markdown_summary(points)


def test_targets_are_labelled_as_percentages():
    assert [target_tag(t) for t in (0.05, 0.01, 0.005, 0.001)] == ["5%", "1%", "0.5%", "0.1%"]


def test_speedup_is_read_at_the_targets_asked_for():
    # minmax's 0.08 % reaches 0.1 %, where raymarch needs its 900 ms point
    points = [_point("raymarch", 100, 0.004), _point("raymarch", 900, 0.0009), _point("minmax", 20, 0.0008)]
    (row,) = summary(points, targets=(0.005, 0.001))
    assert row["speedup@0.5%"] == pytest.approx(100 / 20) and row["speedup@0.1%"] == pytest.approx(900 / 20)
    assert "speedup@5%" not in row
    table = markdown_summary(points, targets=(0.005, 0.001))
    assert "| 0.1% | 20 (20) | 900 (900) | 45.0× |" in table and "| 5% |" not in table


def _ladder(error_at, ms_per_step=1.0):
    """raymarch_ladder on a fake measure: error_at(steps, shadow_map) → rmse, a frame time
    of ms_per_step per step; the (steps, map) pairs it asked for, in order."""
    asked = []

    def measure_at(steps, shadow_map):
        asked.append((steps, shadow_map))
        return _point("raymarch", steps * ms_per_step, error_at(steps, shadow_map), f"{steps} {shadow_map}")

    points = raymarch_ladder(measure_at, 1024, targets=(0.01, 0.005))
    assert len(points) == len(asked) == len(set(asked))
    return asked


def test_raymarch_ladder_doubles_until_the_lowest_target_then_refines_each_crossing():
    asked = _ladder(lambda steps, shadow_map: 1.0 / steps)  # 1 % at 100 steps, 0.5 % at 200
    assert asked[:6] == [(8, 1024), (16, 1024), (32, 1024), (64, 1024), (128, 1024), (256, 1024)]
    # 1 %: between 64 and 128 → 88 (fails); 0.5 %: between 128 and 256 → 184 (fails)
    assert asked[6:] == [(88, 1024), (184, 1024)]


def test_raymarch_ladder_goes_to_twice_the_map_where_the_map_stops_it():
    # The error stops falling at 0.6 % with a 1024 map, at 0.1 % with a 2048 map.
    asked = _ladder(lambda steps, shadow_map: max(1.0 / steps, 0.006 if shadow_map == 1024 else 0.001))
    at_1024 = [steps for steps, size in asked if size == 1024]
    at_2048 = [steps for steps, size in asked if size == 2048]
    assert max(at_1024) == 512  # 256 → 512 cut the error by less than 1.25×: the floor, not 2048 steps
    assert at_2048 == [128, 256, 184]  # from the first rung within 2× of 0.5 % (0.78 %), then 0.39 %: reached


def test_raymarch_ladder_stops_at_the_most_steps_or_after_a_long_frame():
    # Far from the target, the map is not what stops it: no larger map.
    assert _ladder(lambda steps, shadow_map: 0.5) == [(steps, 1024) for steps in (8, 16, 32, 64, 128, 256, 512, 1024,
                                                                                   2048)]
    # 1024 steps take 30.7 s of CPU time, past RAYMARCH_MOST_FRAME_CPU_MS: the last rung.
    assert _ladder(lambda steps, shadow_map: 0.5, ms_per_step=30) == [(steps, 1024) for steps in (8, 16, 32, 64, 128,
                                                                                                   256, 512, 1024)]


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
                                       "--pixels", "300", "--targets", "5,0.1", "--output", str(out), "--cache",
                                       str(tmp_path / "cache")])
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader(open(out / "bench.csv")))
    assert {r["method"] for r in rows} == {"raymarch", "minmax", "volume_moments"}
    assert all(float(r["frame_ms"]) > 0 and 0 <= float(r["rel_rmse"]) < 10 for r in rows)
    assert (out / "bench.png").stat().st_size > 1000
    summary_text = (out / "summary.md").read_text()
    assert "speedup" in summary_text and "| 0.1% |" in summary_text and "| 0.5% |" not in summary_text
    assert json.loads((out / "machine.json").read_text())["targets"] == [0.05, 0.001]
    assert any((tmp_path / "cache").iterdir())  # exact was cached


def test_the_figure_names_the_methods_that_ran_and_only_those():
    # bench.png listed "moments" with no points (the method runs as volume_moments) and left
    # minmax unlabelled: the legend now comes from the points.
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    from clrays.runs.bench import figure_of

    points = [_point("raymarch", 100, 0.04), _point("raymarch", 400, 0.009), _point("minmax", 20, 0.008),
              _point("volume_moments", 15, 0.02), _point("a_new_method", 30, 0.01)]
    other = [replace(p, scene="t") for p in points if p.method in ("minmax", "raymarch")]
    figure = figure_of(points + other)
    try:
        first, second = (axis for axis in figure.axes if axis.get_visible())
        for axis, methods in ((first, ["raymarch", "minmax", "volume_moments", "a_new_method"]),
                              (second, ["raymarch", "minmax"])):
            labels = [text.get_text() for text in axis.get_legend().get_texts()]
            assert labels == methods + ["Pareto front (all)"]
            for collection in axis.collections:  # every labelled series has its points
                assert len(collection.get_offsets()) > 0, collection.get_label()
        colours = {c.get_label(): tuple(c.get_facecolor()[0]) for c in first.collections
                   if c.get_label() != "Pareto front (all)"}
        assert len(set(colours.values())) == len(colours)  # one colour per method
    finally:
        plt.close(figure)


def test_bench_takes_output_and_its_former_name_out(tmp_path):
    for flag in ("-o", "--output", "--out"):
        result = CliRunner().invoke(main, ["bench", str(tmp_path / "missing.yaml"), flag, str(tmp_path / "o")])
        assert result.exit_code == 1 and "no such scene file" in result.output, (flag, result.output)
    result = CliRunner().invoke(main, ["bench", str(DEMO), "-o", str(tmp_path / "a"), "--out", str(tmp_path / "b")])
    assert result.exit_code == 2 and "give -o/--output or --out (its former name), not both" in result.output
    assert "--out " not in CliRunner().invoke(main, ["bench", "--help"]).output  # hidden: --output is the name


def test_volume_only_skips_the_surface_shadows_it_cannot_show(device):
    from clrays.runs.bench import volume_only
    from clrays.scene.load import load_scene
    from clrays.session import Renderer

    volume = volume_only(load_scene(DEMO, ["image.width=32", "image.height=18"]))
    with_exact = replace(volume, render=replace(volume.render, surface_shadows="exact"))
    renderer = Renderer(device, reuse=False)
    for method in ("minmax", "raymarch"):
        fast, exact = renderer.render(volume, method), renderer.render(with_exact, method)
        np.testing.assert_array_equal(fast.image, exact.image)
        assert "visibility" in exact.stage_ms and "visibility" not in fast.stage_ms


def test_bench_rejects_a_bad_resolution():
    result = CliRunner().invoke(main, ["bench", str(DEMO), "-r", "640by360"])
    assert result.exit_code == 2 and "WIDTHxHEIGHT" in result.output


@pytest.mark.parametrize("targets", ["1,abc", "0", "100", ""])
def test_bench_rejects_bad_targets(targets):
    result = CliRunner().invoke(main, ["bench", str(DEMO), "--targets", targets])
    assert result.exit_code == 2 and "--targets" in result.output and "percentages" in result.output


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


def test_an_error_with_no_pixel_left_to_compare_is_nan_not_a_crash():
    # A 16×9 sun.yaml leaves no pixel once its depth edges and dark pixels are out: the
    # error is NaN over 0 pixels, which the bench scripts print as such, not a traceback.
    from clrays.reference.metrics import image_error

    image = np.ones((3, 4, 3), np.float32)
    error = image_error(image, image, exclude=np.ones((3, 4), bool))
    assert error.pixels == 0 and np.isnan([error.mean, error.p99, error.rmse]).all()
    kept = image_error(image * 1.1, image)
    assert kept.pixels == 12 and kept.rmse == pytest.approx(0.1, rel=1e-5)


def test_bench_of_a_thumbnail_with_nothing_to_compare_says_so_in_one_line(tmp_path):
    sun = DEMO.parent / "sun.yaml"
    result = CliRunner().invoke(main, ["bench", str(sun), "-r", "16x9", "--volume-only", "--repeats", "1",
                                       "--no-progress", "--cache", str(tmp_path / "cache"), "--out",
                                       str(tmp_path / "out")])
    assert result.exit_code == 1, result.output
    message = result.output.strip().splitlines()[-1]
    assert message.startswith("clrays: error:") and "no pixel is left to compare" in message
    assert "Traceback" not in result.output
    assert not list((tmp_path / "out").glob("*")), "nothing written"
