"""Progress of long runs: raymarch in parts with a bar or lines (the same image as in one
launch), and a line per frame or point when stderr is not a terminal."""
from __future__ import annotations

import re

import numpy as np
import pytest

import clrays.stages.raymarch as raymarch_stage
from clrays.scene.load import load_scene
from clrays.session import Renderer
from conftest import run_cli as run
from test_sequence import write_scene

DEMO = ["image.width=48", "image.height=27", "render.steps=64"]


@pytest.fixture
def long_marches(monkeypatch):
    """Every march counts as long: in parts, with lines from the start."""
    monkeypatch.setattr(raymarch_stage, "PROGRESS_MIN_S", 0.0)
    monkeypatch.setattr(raymarch_stage, "PROGRESS_LINES_AFTER_S", 0.0)


def test_raymarch_in_parts_gives_the_image_of_one_launch_and_says_how_far_it_is(device, long_marches):
    scene = load_scene("scenes/demo.yaml", DEMO)
    renderer = Renderer(device, reuse=False)
    whole = renderer.render(scene, "raymarch")
    lines = []
    parts = renderer.render(scene, "raymarch", progress=lines.append)
    np.testing.assert_array_equal(parts.image, whole.image)
    assert [int(re.match(r"raymarch: (\d+)% \(\d+ s, about \d+ s left\)$", line).group(1)) for line in lines] == \
        list(range(10, 101, 10))


def test_a_short_raymarch_says_nothing_and_marches_in_two_launches_at_most(device, monkeypatch):
    launches = []
    kernel = raymarch_stage.Device.kernel

    def counting(self, stage, name, defines=None):
        launcher = kernel(self, stage, name, defines)
        if stage != "raymarch":
            return launcher
        return lambda *args, **kwargs: launches.append(kwargs.get("global_offset", (0,))) or launcher(*args, **kwargs)

    monkeypatch.setattr(raymarch_stage.Device, "kernel", counting)
    lines = []
    Renderer(device, reuse=False).render(load_scene("scenes/demo.yaml", DEMO), "raymarch", progress=lines.append)
    assert lines == [] and 1 <= len(launches) <= 2  # the first part, and the rest at once


def test_render_with_raymarch_shows_progress_off_a_terminal(tmp_path, long_marches):
    # 1024 steps ran 17 s without a word; --progress promised a bar "for slow methods".
    code, out = run("render", "scenes/demo.yaml", "-o", tmp_path / "a.npy", "--method", "raymarch", "--no-progress",
                    *[a for o in DEMO for a in ("--set", o)])
    assert code == 0, out
    assert [line for line in out.splitlines() if line.startswith("clrays: raymarch: ")][-1].startswith(
        "clrays: raymarch: 100% ("), out


def test_render_with_raymarch_draws_a_bar_when_asked(tmp_path, long_marches):
    code, out = run("render", "scenes/demo.yaml", "-o", tmp_path / "a.npy", "--method", "raymarch", "--progress",
                    *[a for o in DEMO for a in ("--set", o)])
    assert code == 0 and re.search(r"raymarch: 100%\|", out), out


def test_a_sequence_off_a_terminal_prints_a_line_per_frame(tmp_path):
    scene = write_scene(tmp_path, 3)
    code, out = run("sequence", scene, "-o", tmp_path / "f_{}.npy", "--no-progress")
    assert code == 0, out
    assert re.findall(r"^clrays: frame (\d): \d+ ms \((\d) of 3\)$", out, re.M) == [("0", "1"), ("1", "2"), ("2", "3")]
    code, out = run("sequence", scene, "-o", tmp_path / "f_{}.npy", "--no-progress", "--frames", "1:2", "--overwrite")
    assert re.findall(r"^clrays: frame (\d): \d+ ms \((\d) of 2\)$", out, re.M) == [("1", "1"), ("2", "2")]


def test_a_sweep_off_a_terminal_prints_a_line_per_point(tmp_path):
    scene = write_scene(tmp_path, 2)
    code, out = run("sweep", scene, "--set", "render.slices=32,64", "-o", tmp_path / "sweep", "--no-progress")
    assert code == 0, out
    assert re.findall(r"^clrays: point (\d): render\.slices=(\d+): \d+ ms", out, re.M) == [("0", "32"), ("1", "64")]
