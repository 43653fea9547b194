"""`clrays sweep` and `clrays.runs.sweep`: the cartesian product, results.csv, the contact
sheet, errors against a reference, resume, reuse that changes nothing, bad input."""
from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from clrays.errors import ClraysError, SceneError
from clrays.scene.load import load_scene
from clrays.session import Renderer
from clrays.runs.references import Reference, parse_reference
from clrays.runs.sweep import (Axis, execution_order, parse_settings, run_sweep, split_values, sweep_points,
                               sweep_scenes)
from conftest import run_cli as run

SCENE = """\
version: 1
image: {width: 32, height: 24}
camera: {position: [0, 2, 8], look_at: [0, 1.5, 0], far: 30}
lights:
  - {type: point, position: [0.3, 5, -0.5], intensity: 80}
medium: {sigma_s: 0.06, sigma_a: 0.01}
objects:
  - {type: plane, center: [0, 0, 0], normal: [0, 1, 0], size: 12, segments: 2}
  - {type: box, min: [-2, 2.5, -3], max: [-1.6, 2.7, 3]}
  - {type: box, min: [0, 2.5, -3], max: [0.4, 2.7, 3]}
render: {shadow_map: 128, slices: 64, gamma_samples: 128, steps: 64}
"""


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_text(SCENE)
    return path




def rows_of(folder: Path) -> list[dict[str, str]]:
    with open(folder / "results.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_sweep_writes_images_results_and_contact_sheet(scene_file, tmp_path, device):
    out = tmp_path / "sweep"
    code, text = run("sweep", scene_file, "--set", "medium.sigma_s=0.02,0.05,0.1", "--set", "render.slices=32,64",
                     "--set", "image.width=40", "-o", out, "--reference", "raymarch:256", "--no-progress")
    assert code == 0, text
    rows = rows_of(out)
    assert [(r["medium.sigma_s"], r["render.slices"]) for r in rows] == [
        ("0.02", "32"), ("0.02", "64"), ("0.05", "32"), ("0.05", "64"), ("0.1", "32"), ("0.1", "64")]
    assert [r["image"] for r in rows] == [f"{i:03d}.png" for i in range(6)]
    for r in rows:
        assert np.asarray(Image.open(out / r["image"])).shape == (24, 40, 3)
        assert float(r["wall_ms"]) > 0 and float(r["traverse_ms"]) > 0 and r["method"] == "minmax"
        assert r["reference"] == "raymarch:256" and int(r["error_pixels"]) > 0
        assert 0 <= float(r["error_mean_pct"]) < 20 and float(r["error_mean_pct"]) <= float(r["error_p99_pct"])
        # device_ms: the stages timed by OpenCL events, not the integrand tables or the BVH built on the host.
        device_stages = [float(value) for column, value in r.items() if column.endswith("_ms") and value
                         and column not in ("wall_ms", "device_ms", "integrand_ms", "warmup_ms", "build_ms",
                                            "reference_ms", "edges_ms", "bvh_ms")]
        assert float(r["device_ms"]) == pytest.approx(sum(device_stages), abs=0.05)
    assert any(float(r["integrand_ms"] or 0) > 0 for r in rows)
    # Only the medium and the texture size change: the rasters are computed once.
    assert sum("raster.shadow" in r["reused"].split() for r in rows) == 5
    assert sum("rectify" in r["computed"].split() for r in rows) == 2
    sheet = Image.open(out / "contact_sheet.png")
    assert sheet.width >= 2 * 40 and sheet.height >= 3 * 24  # 3 rows (σs) of 2 columns (slices)
    assert "6 points rendered, 0 kept" in text
    # Without a bar, a line per point on stderr; the table on stdout.
    lines = text.splitlines()
    assert sorted(line.split(":")[1] for line in lines[:6]) == [f" point {i}" for i in range(6)]
    assert lines[6].startswith("medium.sigma_s")
    # Warm-up (kernel builds, first launches) and the host's reference and depth-edge map
    # are timed on their own, not in point 0's wall_ms. On a CPU device work-groups follow the
    # launch sizes, which follow render.slices (PoCL compiles a kernel for each new one): the
    # first point of 64 slices warms up too.
    warmed = [int(r["index"]) for r in rows if float(r["warmup_ms"]) > 0]
    assert warmed == ([0, 1] if device.is_cpu else [0])
    assert float(rows[0]["edges_ms"]) > 0 and not any(r["edges_ms"] for r in rows[1:])
    assert all(float(r["reference_ms"]) > 0 for r in rows[::2])  # the reference ignores slices


def test_resume_keeps_finished_points_and_redoes_changed_ones(scene_file, tmp_path):
    out = tmp_path / "sweep"
    assert run("sweep", scene_file, "--set", "medium.sigma_s=0.02,0.05", "-o", out)[0] == 0
    first = rows_of(out)
    code, text = run("sweep", scene_file, "--set", "medium.sigma_s=0.02,0.05,0.1", "-o", out)
    assert code == 0 and "1 point rendered, 2 kept from an earlier run (of 3)" in text
    assert rows_of(out)[:2] == first
    (out / "001.png").unlink()
    code, text = run("sweep", scene_file, "--set", "medium.sigma_s=0.02,0.05,0.1", "-o", out)
    assert "1 point rendered, 2 kept" in text and (out / "001.png").exists()
    # A changed scene (here a fixed override) renders everything again.
    code, text = run("sweep", scene_file, "--set", "medium.sigma_s=0.02,0.05,0.1", "--set", "image.height=20",
                     "-o", out)
    assert "3 points rendered, 0 kept" in text


def test_interrupted_sweep_keeps_its_rows(scene_file, tmp_path, device):
    class Stop(Exception):
        pass

    def stop_after_two(point, row):
        if point.index == 1:
            raise Stop

    out = tmp_path / "sweep"
    spec = {"medium.sigma_s": [0.02, 0.05, 0.1]}
    with pytest.raises(Stop):
        run_sweep(scene_file, spec, out, renderer=Renderer(device), on_point=stop_after_two)
    assert [r["index"] for r in rows_of(out)] == ["0", "1"]
    report = run_sweep(scene_file, spec, out, renderer=Renderer(device))
    assert report.kept == [0, 1] and report.rendered == [2]


def test_reuse_changes_no_image(scene_file, tmp_path, device):
    spec = ["medium.sigma_s=0.02,0.1", "lights.0.intensity=[50,50,50],[90,60,30]", "render.integrand=table,svd"]
    kept = run_sweep(scene_file, spec, tmp_path / "a", renderer=Renderer(device), image_format="npy")
    fresh = run_sweep(scene_file, spec, tmp_path / "b", renderer=Renderer(device, reuse=False), image_format="npy")
    assert len(kept.rows) == 8
    for a, b in zip(kept.rows, fresh.rows):
        np.testing.assert_array_equal(np.load(tmp_path / "a" / a["image"]), np.load(tmp_path / "b" / b["image"]))
        assert b["reused"] == ""
    assert sum("rectify" in r["reused"].split() for r in kept.rows) == 7  # power and medium: one texture


def test_exact_reference_is_rendered_once_per_scene(scene_file, tmp_path, device):
    report = run_sweep(scene_file, {"render.slices": [32, 64, 128]}, tmp_path / "s", reference="exact",
                       renderer=Renderer(device), contact_sheet=False)
    references = tmp_path / "s" / ".references"
    assert len(list(references.glob("exact-*.npy"))) == 1  # slices do not change the exact image
    assert len(list(references.glob("edges-*.npy"))) == 1
    errors = [float(r["error_mean_pct"]) for r in report.rows]
    assert all(0 <= e < 20 for e in errors)
    assert not (tmp_path / "s" / "contact_sheet.png").exists()


def test_python_iterator_of_scenes(scene_file):
    spec = {"medium.sigma_s": [0.02, 0.05], "lights.0.position": [[0, 5, 0], [1, 5, 0]]}
    points = list(sweep_scenes(scene_file, spec))
    assert [p.index for p, _ in points] == [0, 1, 2, 3]
    assert points[3][0].label == "medium.sigma_s=0.05 lights.0.position=[1, 5, 0]"
    assert points[3][1].medium.sigma_s[0] == 0.05 and points[3][1].lights[0].position[0] == 1
    assert [p.index for p, _ in sweep_scenes(scene_file, ["medium.sigma_s=0.1", "render.slices=32,64"])] == [0, 1]


def test_values_split_at_top_level_commas():
    assert split_values("0.02,0.05, 0.1") == ["0.02", "0.05", "0.1"]
    assert split_values("[1,2,3],[4,5,6]") == ["[1,2,3]", "[4,5,6]"]
    assert split_values("{type: hg, g: 0.5},{type: isotropic}") == ["{type: hg, g: 0.5}", "{type: isotropic}"]
    assert split_values("'a,b',c") == ["'a,b'", "c"]
    axes, fixed = parse_settings(["render.slices=256,1024", "medium.sigma_a=0.01"])
    assert axes == [Axis("render.slices", ("256", "1024"))] and fixed == ["medium.sigma_a=0.01"]


@pytest.mark.parametrize("axes, order", [
    # The camera raster and the trees follow the camera: it varies slowest, although given second.
    ([Axis("medium.sigma_s", ("0.02", "0.05")), Axis("camera.fov_deg", ("40", "50"))], [0, 2, 1, 3]),
    # A light's power is read by no stage before the integrand: the product order stands.
    ([Axis("camera.fov_deg", ("40", "50")), Axis("lights.0.intensity", ("50", "90"))], [0, 1, 2, 3]),
    # Its position moves its shadow map: that varies slowest.
    ([Axis("lights.0.intensity", ("50", "90")), Axis("lights.0.position", ("[0, 5, 0]", "[1, 5, 0]"))],
     [0, 2, 1, 3]),
])
def test_points_sharing_stages_run_together(scene_file, axes, order):
    points = sweep_points(axes)
    scenes = [load_scene(scene_file, point.overrides) for point in points]
    assert [p.index for p in execution_order(points, scenes)] == order


def test_contact_sheet_shows_the_error_in_the_unit_of_results_csv():
    from clrays.runs.sweep import _label_lines

    row = {"index": "3", "wall_ms": "12.5", "medium.sigma_s": "0.1", "error_mean_pct": "1.234", "error_p99_pct": "7.5"}
    assert _label_lines(row, [Axis("medium.sigma_s", ("0.02", "0.1"))]) == [
        "medium.sigma_s=0.1", "#3  12 ms", "error 1.23%, p99 7.5%"]


@pytest.mark.parametrize("args, message", [
    (["--set", "medium.sigma_s=0.02,-1"], r"--set medium\.sigma_s=-1: medium\.sigma_s: expected .* got -1"),
    (["--set", "render.slices=256,x"], r"--set render\.slices=x: render\.slices: expected an integer"),
    (["--set", "medium.sigma_s=0.02,"], r"medium\.sigma_s: expected comma-separated values, got an empty one"),
    (["--set", "nothing"], r"--set nothing: expected key\.path=value or key\.path=v1,v2"),
    (["--set", "render.stepz=1,2"], r"render\.stepz: unknown key \(did you mean 'steps'\?\)"),
    (["--reference", "raymarch"], r"--reference raymarch: expected exact or raymarch:N"),
    (["--reference", "raymarch:0"], r"expected exact or raymarch:N"),
    (["-o", "BLOCKER/sub"], r"cannot create the sweep folder"),
])
def test_bad_input_is_one_line(scene_file, tmp_path, args, message):
    (tmp_path / "blocker").write_text("a file")
    args = [a.replace("BLOCKER", str(tmp_path / "blocker")) for a in args]
    if "-o" not in args:
        args += ["-o", str(tmp_path / "out")]
    if "--set" not in args:
        args += ["--set", "medium.sigma_s=0.02,0.05"]
    code, out = run("sweep", scene_file, *args)
    assert code == 1 and len(out.strip().splitlines()) == 1 and re.search(message, out), out
    assert not list(tmp_path.glob("out/*.png"))


def test_errors_from_python():
    with pytest.raises(ClraysError, match="expected exact or raymarch:N"):
        parse_reference("exact:3")
    assert parse_reference("raymarch:512") == Reference("raymarch", 512) and parse_reference(None) is None
    assert parse_reference(" exact ").name == "exact" and parse_reference("raymarch:64").name == "raymarch:64"


def test_bad_value_fails_before_rendering(scene_file, tmp_path):
    with pytest.raises(SceneError, match=r"^override camera\.fov_deg=200"):
        run_sweep(scene_file, {"medium.sigma_s": [0.01, 0.02], "camera.fov_deg": [40, 200]}, tmp_path / "o")
    assert not list((tmp_path / "o").glob("*.png")) if (tmp_path / "o").exists() else True


def test_help_has_an_example():
    code, out = run("sweep", "--help")
    assert code == 0 and "clrays sweep scenes/demo.yaml --set medium.sigma_s=0.02,0.05,0.1" in out
