"""The field table of the scene format: it agrees with the model, the loader follows it,
and the key tables of docs/scene-format.md are the ones tools/scene_format_doc.py writes."""
from __future__ import annotations

import dataclasses
import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

from clrays.errors import SceneError
from clrays.scene import fields
from clrays.scene.fields import LIGHTS, OBJECTS, PHASES, RENDER, SECTIONS
from clrays.scene.load import parse_scene
from clrays.scene.model import INTEGRAND_MODES, METHODS, PHASE_TYPES, TRAVERSALS, Render

REPO = Path(__file__).resolve().parents[2]
TOOL = REPO / "tools" / "scene_format_doc.py"
DOC = REPO / "docs" / "scene-format.md"


def tool():
    spec = importlib.util.spec_from_file_location("scene_format_doc", TOOL)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_docs_tables_are_current():
    result = subprocess.run([sys.executable, str(TOOL), "--check"], capture_output=True, text=True, cwd=REPO)
    assert result.returncode == 0, result.stderr


def test_check_fails_on_a_stale_or_unknown_table(tmp_path):
    text = DOC.read_text(encoding="utf-8")
    stale = tmp_path / "stale.md"
    row = "| `steps` | integer | no | `256` | [1, 65536] |"
    assert row in text
    stale.write_text(text.replace(row, row.replace("256", "128")))
    assert tool().main(["--check", "--doc", str(stale)]) == 1
    with pytest.raises(ValueError, match=r"fields:rendr -->: no such section"):
        tool().generate(text.replace("<!-- fields:render -->", "<!-- fields:rendr -->"))
    with pytest.raises(ValueError, match=r"sections without a table in the document: render$"):
        tool().generate(text.replace("<!-- fields:render -->", "").replace("<!-- /fields -->\n\n```yaml\nrender:", ""))


def test_render_fields_are_the_model_fields_with_its_defaults():
    model = {f.name: f.default for f in dataclasses.fields(Render)}
    assert {field.key: field.default for field in RENDER.fields} == model


def test_choices_come_from_the_model():
    assert RENDER["method"].choices == METHODS
    assert RENDER["integrand"].choices == INTEGRAND_MODES
    assert RENDER["traversal"].choices == TRAVERSALS
    assert tuple(PHASES) == PHASE_TYPES


def test_every_section_is_named_by_its_path():
    assert set(SECTIONS) >= {f"lights.{kind}" for kind in LIGHTS} | {f"objects.{kind}" for kind in OBJECTS}
    for section in SECTIONS.values():
        keys = [field.key for field in section.fields]
        assert len(keys) == len(set(keys)), section.name


@pytest.mark.parametrize("path, value, message", [
    ("render.steps", RENDER["steps"].high + 1, r"expected an integer in \[1, 65536\]"),
    ("image.spp", fields.IMAGE["spp"].high + 1, r"expected an integer in \[1, 4096\]"),
    ("camera.fov_deg", fields.CAMERA["fov_deg"].high, r"expected a number in \(0, 180\)"),
])
def test_the_loader_reads_its_limits_from_the_table(path, value, message):
    text = ("version: 1\nimage: {width: 8, height: 8}\ncamera: {position: [0, 0, 5], look_at: [0, 0, 0]}\n"
            "lights: [{type: point, position: [0, 5, 0], intensity: 1}]\n")
    parse_scene(text, overrides=[f"{path}={value - 1}"])
    with pytest.raises(SceneError, match=message):
        parse_scene(text, overrides=[f"{path}={value}"])


def test_relief_example_names_the_file_the_tool_writes():
    """The relief example of docs/scene-format.md names the depth image that
    tools/lattice_depth.py writes, as scenes/lattice.yaml (beside it) reads it."""
    import re

    text = DOC.read_text()
    section = text[text.index("### relief"):text.index("### transform")]
    example = re.search(r"```yaml\n(.*?)```", section, re.DOTALL).group(1)
    depth_map = re.search(r"depth_map: (\S+)", example).group(1)
    spec = importlib.util.spec_from_file_location("lattice_depth", REPO / "tools" / "lattice_depth.py")
    lattice_depth = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(lattice_depth)
    assert REPO / "scenes" / depth_map == lattice_depth.DEFAULT_OUTPUT
    assert f"depth_map: {depth_map}" in (REPO / "scenes" / "lattice.yaml").read_text()
