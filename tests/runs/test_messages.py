"""What clrays says to a newcomer: kernel builds announced whenever they run, messages that
name what the user wrote (and hint at what was meant), `import clrays` from the folder
above a checkout, and the help, sweep and bench output that read cut or misaligned."""
from __future__ import annotations

import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
from conftest import TEST_DEVICE, run_cli

import clrays
from clrays import device as device_module
from clrays import runtimes
from clrays.errors import SceneError
from clrays.runs.bench import BenchPoint, point_line
from clrays.scene.load import load_scene, parse_scene

REPO = Path(__file__).resolve().parents[2]
SCENE = ("version: 1\nimage: {width: 8, height: 8}\ncamera: {position: [0, 0, 5], look_at: [0, 0, 0]}\n"
         "lights: [{type: point, position: [0, 2, 0], intensity: 10}]\n")


def one_line(output: str) -> str:
    lines = output.strip().splitlines()
    assert len(lines) == 1, output
    return lines[0]


# --------------------------------------------------------------------------- kernel builds


def test_every_build_burst_that_builds_says_so_in_one_line(device, tmp_path, monkeypatch):
    # A new feature's or size's programs took 12-53 s to build with no line: only a run's
    # first build was announced. Now the first program of each burst (the builds until a
    # frame ends) that no run built says so; a program an earlier run built says nothing.
    monkeypatch.setattr(runtimes, "cache_root", lambda: tmp_path)
    lines: list[str] = []
    monkeypatch.setattr(device_module, "build_notice", lines.append)
    first = device_module.Device(TEST_DEVICE)
    first.program("minmax")
    first.program("minmax", {"NOTICE_TEST": 1})  # the same burst
    assert lines == [f"building OpenCL kernels for {first.name} (first run, cached after)"]
    first.end_frame(0)
    first.program("minmax", {"NOTICE_TEST": 1})  # built already in this process
    assert len(lines) == 1

    again = device_module.Device(TEST_DEVICE)  # a later run
    again.program("minmax")
    again.program("minmax", {"NOTICE_TEST": 1})
    assert len(lines) == 1, lines  # both built by the earlier run: cached, nothing said
    again.program("minmax", {"NOTICE_TEST": 2})
    again.program("minmax", {"NOTICE_TEST": 3})
    assert lines[1:] == [f"building OpenCL kernels for {again.name}: minmax with NOTICE_TEST=2 and any more this "
                         f"frame needs (new settings, cached after)"]
    again.end_frame(0)
    again.program("minmax", {"NOTICE_TEST": 4})  # a new burst: a new line
    assert len(lines) == 3 and "minmax with NOTICE_TEST=4 " in lines[2]


# --------------------------------------------------------------------------- what the user wrote


@pytest.mark.parametrize("name", ["a.exr", "a.npy"])
def test_render_exposure_names_only_what_render_writes(tmp_path, name):
    # It named GIF and WebP, which render cannot write.
    code, out = run_cli("render", "scenes/demo.yaml", "-o", tmp_path / name, "--exposure", "2")
    assert code == 1
    assert one_line(out) == (f"clrays: error: --exposure 2: applies only to PNG output; {tmp_path / name} keeps "
                             f"linear radiance (drop --exposure)")
    assert not list(tmp_path.iterdir())


def test_sequence_exposure_names_the_video_formats_it_changes(tmp_path):
    code, out = run_cli("sequence", "scenes/demo.yaml", "-o", tmp_path / "f_{}.npy", "--exposure", "2")
    assert code == 1
    assert "applies only to PNG, MP4, GIF and WebP output; " in one_line(out)


def test_aov_on_a_translucent_scene_names_aov(tmp_path):
    # It reported `--set render.aovs=[...]`, which the user never typed.
    code, out = run_cli("render", "scenes/glass_pane.yaml", "-o", tmp_path / "g.png", "--aov", "depth")
    assert code == 1
    assert one_line(out) == ("clrays: error: --aov depth: render.aovs: expected no render passes in a scene with "
                             "translucent objects (opacity below 1), got depth")


def test_camera_on_a_scene_without_gltf_names_camera(tmp_path):
    code, out = run_cli("render", "scenes/demo.yaml", "-o", tmp_path / "d.png", "--camera", "Cam")
    assert code == 1 and one_line(out).startswith("clrays: error: --camera Cam: gltf"), out


def test_the_python_api_names_its_overrides_not_set():
    with pytest.raises(SceneError, match=r"^override render\.aovs=\[depth\]: render\.aovs: expected no render "
                                         r"passes in a scene with translucent objects"):
        load_scene(REPO / "scenes/glass_pane.yaml", overrides=["render.aovs=[depth]"])
    with pytest.raises(SceneError, match=r"^override image\.spp=0: image\.spp: expected an integer"):
        parse_scene(SCENE, overrides=["image.spp=0"])


def test_set_on_the_command_line_still_says_set(tmp_path):
    code, out = run_cli("render", "scenes/demo.yaml", "-o", tmp_path / "d.png", "--set", "image.spp=0")
    assert code == 1 and one_line(out).startswith("clrays: error: --set image.spp=0: image.spp: expected"), out
    # and the API, run after the command line in the same process, is the API again
    with pytest.raises(SceneError, match=r"^override image\.spp=0: "):
        parse_scene(SCENE, overrides=["image.spp=0"])


def test_an_rgb_without_brackets_gets_the_list_form(tmp_path):
    code, out = run_cli("render", "scenes/demo.yaml", "-o", tmp_path / "d.png",
                        "--set", "lights.0.intensity=260,230,190")
    assert code == 1
    assert one_line(out) == ("clrays: error: --set lights.0.intensity=260,230,190: lights.0.intensity: expected a "
                             "list of 3 numbers (RGB) or a single number >= 0, got '260,230,190' (a list is "
                             "written in brackets: [260, 230, 190])")
    with pytest.raises(SceneError, match=r"<string>:7:16: lights\.0\.intensity: expected a list of 3 numbers "
                                         r"\(RGB\) .*got '260, 230, 190' \(a list is written in brackets: "
                                         r"\[260, 230, 190\]\)$"):
        parse_scene(SCENE.replace("lights: [{type: point, position: [0, 2, 0], intensity: 10}]",
                                  "lights:\n  - type: point\n    position: [0, 2, 0]\n    intensity: 260, 230, 190"))


def test_a_vector_without_brackets_gets_the_list_form():
    with pytest.raises(SceneError, match=r"lights\.0\.position: expected a list of 3 numbers \[x, y, z\], got "
                                         r"'1,2,3' \(a list is written in brackets: \[1, 2, 3\]\)$"):
        parse_scene(SCENE, overrides=["lights.0.position=1,2,3"])


def test_a_number_field_with_a_comma_gets_no_list_hint():
    with pytest.raises(SceneError, match=r"camera\.fov_deg: expected a number in \(0, 180\), got '1,5'$"):
        parse_scene(SCENE, overrides=["camera.fov_deg=1,5"])


def test_a_phase_named_alone_gets_its_mapping():
    with pytest.raises(SceneError, match=r"<string>:5:\d+: medium\.phase: expected a mapping, got 'hg' "
                                         r"\(write \{type: hg, g: \.\.\.\}\)$"):
        parse_scene(SCENE + "medium: {sigma_s: 0.1, phase: hg}\n")
    with pytest.raises(SceneError, match=r"medium\.phase: expected a mapping, got 'isotropic' "
                                         r"\(write \{type: isotropic\}\)$"):
        parse_scene(SCENE, overrides=["medium.phase=isotropic"])
    with pytest.raises(SceneError, match=r"lights\.0: expected a mapping, got 'point' "
                                         r"\(write \{type: point, position: \.\.\., intensity: \.\.\.\}\)$"):
        parse_scene(SCENE, overrides=["lights.0=point"])


# --------------------------------------------------------------------------- import from above a checkout


def test_import_clrays_from_the_folder_above_a_checkout(tmp_path):
    # Python made a namespace package of the checkout's top folder: `import clrays` passed
    # and `clrays.render` was a bare AttributeError.
    (tmp_path / "clrays").symlink_to(REPO, target_is_directory=True)
    shown = subprocess.run([sys.executable, "-c", "import clrays, clrays.cli; from clrays import load_scene; "
                            "print(clrays.__file__); print(clrays.render.__module__, clrays.cli.main.name)"],
                           capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert shown.returncode == 0, shown.stderr
    where, names = shown.stdout.splitlines()
    assert Path(where).resolve() == (REPO / "clrays" / "__init__.py").resolve()
    assert names == "clrays.session main"


def test_the_package_itself_is_the_inner_folder():
    assert Path(clrays.__file__).resolve() == (REPO / "clrays" / "__init__.py").resolve()


# --------------------------------------------------------------------------- help, sweep, bench


def test_the_top_level_help_cuts_no_description():
    code, out = run_cli("--help")
    assert code == 0
    from clrays.cli import main

    commands = out.split("Options:", 1)[1]
    assert "..." not in commands, out
    flat = " ".join(commands.split())
    for name, command in main.commands.items():
        first_sentence = " ".join(command.help.split("\n\n")[0].split()).split(". ")[0].rstrip(".")
        assert f"{name} {command.short_help or first_sentence}" in flat, (name, first_sentence)


def test_a_sweep_of_fixed_values_only_prints_no_empty_label(tmp_path, monkeypatch):
    # `point 0: : 59 ms`: a point of no swept key has an empty label.
    from clrays import cli
    from clrays.runs.point import SweepPoint
    from clrays.runs.sweep import SweepReport

    def fake_run_sweep(scene, overrides, out_dir, *, on_point, **_settings):
        on_point(SweepPoint(0, ()), {"wall_ms": "59.2"})
        on_point(SweepPoint(1, (("render.steps", "8"),)), {"wall_ms": "61", "warmup_ms": "10"})
        return SweepReport(Path(out_dir), [{"index": "0", "wall_ms": "59.20", "reused": ""}])

    monkeypatch.setattr(cli, "run_sweep", fake_run_sweep)
    code, out = run_cli("sweep", "scenes/demo.yaml", "--set", "image.width=16", "-o", tmp_path / "s", "--no-progress")
    assert code == 0, out
    assert "clrays: point 0: 59 ms" in out.splitlines()
    assert "clrays: point 1: render.steps=8: 61 ms (+ warm-up 10 ms)" in out.splitlines()


def _point(method: str, frame_ms: float, rmse: float) -> BenchPoint:
    return BenchPoint("demo", "64x36", method, "defaults", frame_ms, 0.01, rmse, 2 * rmse, rmse / 2, 12.0,
                      load_average=1.5, cpu_ms=2 * frame_ms)


def test_the_bench_table_aligns_every_method():
    lines = [point_line(_point(method, 12.5, 0.004)) for method in ("minmax", "raymarch", "volume_moments")]
    assert len({line.index(" ms ") for line in lines}) == 1, lines
    assert len({line.index("rmse") for line in lines}) == 1, lines
    assert lines[2].startswith("  volume_moments defaults ")


def test_the_bench_figure_is_in_percent_as_its_label_says():
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    from clrays.runs.bench import figure_of

    points = [_point("raymarch", 100, 0.04), _point("minmax", 20, 0.008)]
    figure = figure_of(points, targets=(0.01,))
    try:
        axis = next(axis for axis in figure.axes if axis.get_visible())
        assert axis.get_ylabel() == "relative RMSE vs exact (%)"
        heights = sorted(y for collection in axis.collections if collection.get_label() in ("raymarch", "minmax")
                         for _, y in collection.get_offsets())
        assert heights == pytest.approx([0.8, 4.0])
        assert [line.get_ydata()[0] for line in axis.lines if line.get_linestyle() == ":"] == pytest.approx([1.0])
    finally:
        plt.close(figure)


def test_the_readme_says_how_long_make_test_takes():
    text = (REPO / "README.md").read_text()
    assert re.search(r"`make test` takes (about )?\d+(–\d+)? minutes on \d cores", text)


def test_an_override_keeps_what_it_names_across_processes():
    import pickle

    from clrays.scene.yaml_tree import Override

    copy = pickle.loads(pickle.dumps(Override("render.aovs=[\"depth\"]", "--aov depth")))
    assert copy == "render.aovs=[\"depth\"]" and copy.given == "--aov depth"
