"""`clrays compare`: each shadow filter's image, heat map and row against PCF at the same radius."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from clrays.runs.compare import heat_map, leak_mask
from conftest import run_cli

REPO = Path(__file__).resolve().parents[2]
SMALL = ["--set", "image.width=64", "--set", "image.height=36", "--set", "render.shadow_map=128"]


def test_compare_writes_images_heat_maps_and_table(tmp_path):
    out = tmp_path / "cmp"
    code, output = run_cli("compare", REPO / "scenes" / "demo.yaml", "-o", out, *SMALL, "--repeats", "1",
                           "--filters", "pcf,vsm,msm_hamburger")
    assert code == 0, output
    for name in ("reference_pcf.png", "pcf.png", "vsm.png", "vsm_diff.png", "msm_hamburger_diff.png",
                 "compare.md", "compare.csv"):
        assert (out / name).is_file(), name
    rows = {row["filter"]: row for row in csv.DictReader((out / "compare.csv").open())}
    assert float(rows["pcf"]["rmse"]) == 0.0 and int(rows["pcf"]["leak_pixels"]) == 0  # the reference itself
    assert float(rows["vsm"]["rmse"]) > 0.0 and float(rows["vsm"]["filter_ms"]) > 0.0
    assert "| msm_hamburger |" in output


def test_unknown_filter_is_a_usage_error(tmp_path):
    code, output = run_cli("compare", REPO / "scenes" / "demo.yaml", "-o", tmp_path, "--filters", "vsm,pcss")
    assert code == 2 and "pcss" in output


def test_leaks_are_pixels_brighter_than_the_reference():
    reference = np.full((2, 2, 3), 1.0)
    image = reference.copy()
    image[0, 0] = 1.5  # brighter: a leak
    image[1, 1] = 0.5  # darker: not a leak
    assert leak_mask(image, reference).tolist() == [[True, False], [False, False]]
    heat = heat_map(image, reference)
    assert heat[0, 0, 0] == 255 and heat[1, 1, 2] == 255 and not heat[0, 1].any()
