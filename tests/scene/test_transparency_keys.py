"""render.transparency in the scene format: its keys, defaults and values; every bad one is a
one-line error naming the key."""
from __future__ import annotations

import pytest

from clrays.errors import SceneError
from clrays.scene.load import parse_scene
from clrays.scene.model import Transparency
from conftest import run_cli

SCENE = ("version: 1\nimage: {width: 8, height: 8}\ncamera: {position: [0, 0, 5], look_at: [0, 0, 0]}\n"
         "lights: [{type: point, position: [0, 5, 0], intensity: 1}]\n")


def transparency_of(*overrides):
    return parse_scene(SCENE, overrides=list(overrides)).render.transparency


def test_keys_and_defaults():
    assert transparency_of() is None  # left out: Transparency()'s defaults
    assert Transparency() == Transparency("gathered", 8, "log", 5e-3)
    assert transparency_of("render.transparency=mboit") == Transparency(type="mboit")
    assert transparency_of("render.transparency=gathered") == Transparency(type="gathered")
    assert transparency_of("render.transparency={type: depth_peeling, layers: 3}").layers == 3
    assert transparency_of("render.transparency={type: mboit, warp: none, moment_bias: 0}") == \
        Transparency("mboit", 8, "none", 0.0)


def test_the_former_name_moments_reads_as_mboit():
    assert transparency_of("render.transparency=moments") == Transparency(type="mboit")
    assert transparency_of("render.transparency={type: moments, warp: none}") == Transparency("mboit", warp="none")


BAD = [
    ("render.transparency={type: peel}", r"render\.transparency\.type: expected one of 'depth_peeling', 'gathered', "
                                         r"'mboit', got 'peel'"),
    ("render.transparency=sorted", r"render\.transparency: expected one of 'depth_peeling', 'gathered', 'mboit', "
                                   r"got 'sorted'"),
    ("render.transparency={layers: 0}", r"render\.transparency\.layers: expected an integer in \[1, 64\], got 0"),
    ("render.transparency={layers: 2.5}", r"render\.transparency\.layers: expected an integer in \[1, 64\], got 2\.5"),
    ("render.transparency={warp: linear}", r"render\.transparency\.warp: expected one of 'none', 'log', got 'linear'"),
    ("render.transparency={moment_bias: -1}", r"render\.transparency\.moment_bias: expected a .*number in \[0, 0\.5\], "
                                              r"got -1"),
    ("render.transparency={moment_bias: .nan}", r"render\.transparency\.moment_bias: expected a finite number"),
    ("render.transparency={bias: 1}", r"render\.transparency\.bias: unknown key; expected one of: type, layers, warp, "
                                      r"moment_bias"),
    ("render.transparency=3", r"render\.transparency: expected a mapping, got 3"),
]


@pytest.mark.parametrize("override, message", BAD)
def test_bad_values_are_one_line_errors(override, message):
    with pytest.raises(SceneError, match=message):
        parse_scene(SCENE, overrides=[override])


def test_the_command_line_reports_one_line(tmp_path):
    scene = tmp_path / "s.yaml"
    scene.write_text(SCENE + "render: {transparency: {type: mboit, warp: cubic}}\n")
    code, out = run_cli("render", str(scene), "-o", str(tmp_path / "x.png"))
    assert code == 1 and "Traceback" not in out
    assert out.strip().splitlines()[-1].endswith("render.transparency.warp: expected one of 'none', 'log', got 'cubic'")


def test_a_key_of_one_type_names_it_when_the_type_is_left_out():
    assert transparency_of("render.transparency={layers: 4}") == Transparency("depth_peeling", 4)
    assert transparency_of("render.transparency={warp: none}").type == "mboit"


@pytest.mark.parametrize("override, message", [
    ("render.transparency={type: mboit, layers: 4}",
     r"render\.transparency\.layers: only depth_peeling reads it, got type mboit"),
    ("render.transparency={type: gathered, warp: log}",
     r"render\.transparency\.warp: only mboit reads it, got type gathered"),
    ("render.transparency={type: depth_peeling, moment_bias: 0.01}",
     r"render\.transparency\.moment_bias: only mboit reads it, got type depth_peeling"),
    ("render.transparency={layers: 4, warp: log}",
     r"render\.transparency: layers is read by depth_peeling, warp and moment_bias by mboit: add type"),
])
def test_keys_of_the_other_type_are_one_line_errors(override, message):
    with pytest.raises(SceneError, match=message):
        parse_scene(SCENE, overrides=[override])


def test_the_former_method_name_moments_reads_as_volume_moments():
    assert parse_scene(SCENE, overrides=["render.method=moments"]).render.method == "volume_moments"
    assert parse_scene(SCENE, overrides=["render.method=volume_moments"]).render.method == "volume_moments"
