"""render.shadow_filter in the scene format: its keys and values, and how it combines with
render.surface_shadows and render.pcf; every bad one is a one-line error naming the key."""
from __future__ import annotations

from pathlib import Path

import pytest

from clrays.errors import SceneError
from clrays.scene.load import parse_scene
from clrays.scene.model import ShadowFilter
from conftest import run_cli

SCENE = ("version: 1\nimage: {width: 8, height: 8}\ncamera: {position: [0, 0, 5], look_at: [0, 0, 0]}\n"
         "lights: [{type: point, position: [0, 5, 0], intensity: 1}]\n")


def render_of(*overrides):
    return parse_scene(SCENE, overrides=list(overrides)).render


def test_a_filter_alone_asks_for_filtered_shadows():
    render = render_of("render.shadow_filter={type: vsm, radius: 3}")
    assert render.surface_shadows == "filtered" and render.shadow_filter == ShadowFilter("vsm", 3)
    assert render_of("render.shadow_filter=msm_hausdorff").shadow_filter.type == "msm_hausdorff"
    assert render_of("render.surface_shadows=filtered").shadow_filter == ShadowFilter()


def test_without_the_key_nothing_changes():
    render = render_of()
    assert render.surface_shadows == "exact" and render.shadow_filter is None


@pytest.mark.parametrize("overrides, message", [
    (["render.shadow_filter={type: pcss}"], r"render\.shadow_filter\.type: expected one of 'hard', 'pcf', 'vsm', "
                                            r"'msm_hamburger', 'msm_hausdorff', got 'pcss'"),
    (["render.shadow_filter=soft"], r"render\.shadow_filter: expected one of .*, got 'soft'"),
    (["render.shadow_filter={radius: 17}"], r"render\.shadow_filter\.radius: expected an integer in \[0, 16\], got 17"),
    (["render.shadow_filter={radius: -1}"], r"render\.shadow_filter\.radius: expected an integer in \[0, 16\]"),
    (["render.shadow_filter={moment_bias: 0.9}"], r"render\.shadow_filter\.moment_bias: expected a number in "
                                                  r"\[0, 0\.5\], got 0\.9"),
    (["render.shadow_filter={depth_bias: abc}"], r"render\.shadow_filter\.depth_bias: expected a number"),
    (["render.shadow_filter={kind: vsm}"], r"render\.shadow_filter\.kind: unknown key"),
    (["render.shadow_filter=[vsm]"], r"render\.shadow_filter: expected"),
    (["render.surface_shadows=exact", "render.shadow_filter=vsm"],
     r"render\.shadow_filter: expected no shadow_filter with render\.surface_shadows: exact"),
    (["render.surface_shadows=pcf", "render.pcf=2", "render.shadow_filter=vsm"],
     r"render\.shadow_filter: expected no shadow_filter with render\.surface_shadows: pcf"),
    (["render.pcf=2", "render.shadow_filter=vsm"], r"render\.pcf: expected 0 with render\.shadow_filter"),
    (["render.surface_shadows=filtered", "render.pcf=1"], r"render\.pcf: expected 0 with surface_shadows: filtered"),
])
def test_bad_keys_and_values_name_the_key(overrides, message):
    with pytest.raises(SceneError, match=message):
        parse_scene(SCENE, overrides=overrides)


def test_bad_filter_on_the_command_line_is_one_line(tmp_path: Path):
    scene = tmp_path / "s.yaml"
    scene.write_text(SCENE + "render: {surface_shadows: map, shadow_filter: {type: vsm}}\n")
    code, output = run_cli("render", scene, "-o", tmp_path / "x.png")
    assert code == 1
    lines = output.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in output, output
    assert f"{scene}:5:" in lines[0] and "render.shadow_filter" in lines[0] and "surface_shadows: map" in lines[0]
