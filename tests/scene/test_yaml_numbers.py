"""One number grammar for scene files and `--set`: YAML 1.2's core schema (YAML 1.2.2
§10.3.2, "Tag Resolution"), not PyYAML's YAML 1.1 one, which refused `1.5e2` and
`6.02e23` ("expected a number") and read `1_000`, `0b1`, `010` (octal) and `1:30` (base
60) as numbers."""
from __future__ import annotations

import math

import pytest
import yaml

from clrays.errors import SceneError
from clrays.scene.load import parse_scene
from clrays.scene.yaml_tree import compose, core_float, core_int

SCENE = ("version: 1\nimage: {width: 8, height: 8}\ncamera: {position: [0, 0, 5], look_at: [0, 0, 0]}\n"
         "lights: [{type: point, position: [0, 2, 0], intensity: 10}]\n")


def value(text: str):
    """A scalar as the scene loader reads it."""
    return compose(text, "x", lambda _mark: "here", "here").value


# The spec's example 10.9 ("Core Tag Resolution") and the rows of its table.
SPEC_EXAMPLES = [
    ("0", 0), ("0o7", 7), ("0x3A", 58), ("-19", -19),
    ("0.", 0.0), ("-0.0", -0.0), (".5", 0.5), ("+12e03", 12000.0), ("-2E+05", -200000.0),
    (".inf", math.inf), ("-.Inf", -math.inf), ("+.INF", math.inf),
]
# The forms this issue met, and more of the table's grammar.
MORE_NUMBERS = [
    ("1.5e2", 150.0), ("6.02e23", 6.02e23), ("1e11", 1e11), ("1.5e-2", 0.015), ("1E3", 1000.0),
    ("+.5", 0.5), ("-.5", -0.5), ("1.", 1.0), ("1.e5", 1e5), (".5e3", 500.0), ("+7", 7), ("007", 7),
    ("010", 10), ("0o17", 15), ("0xff", 255), ("0xFF", 255), ("2.50", 2.5),
]


@pytest.mark.parametrize("text, expected", SPEC_EXAMPLES + MORE_NUMBERS)
def test_core_schema_numbers_are_numbers(text, expected):
    read = value(text)
    assert read == expected and type(read) is type(expected), (text, read)
    if expected == 0:
        assert math.copysign(1, read) == math.copysign(1, expected)  # -0.0 keeps its sign


@pytest.mark.parametrize("text", [".nan", ".NaN", ".NAN"])
def test_core_schema_nan(text):
    assert math.isnan(value(text))


@pytest.mark.parametrize("text", [
    "1_000", "0b1", "0b101", "1:20", "1:30.5", "-0x1F", "+0o7", "0o8", "0xg", "1e", "1e+", ".", "+", "1.5.2",
    ".Nan", "-.nan", "inf", "nan", "1,5", "0x", "0o", "1d3",
])
def test_other_forms_are_text(text):
    # YAML 1.1 forms (underscores, binary, base 60, signed hex) and near-misses stay strings.
    assert value(text) == text


def test_the_spec_examples_in_one_document():
    read = compose("ints: [0, 0o7, 0x3A, -19]\nfloats: [0., -0.0, .5, +12e03, -2E+05]\n"
                   "also: [.inf, -.Inf, +.INF, .NAN]\n", "", lambda _mark: "here", "here").value
    assert [n.value for n in read["ints"].value] == [0, 7, 58, -19]
    assert [n.value for n in read["floats"].value] == [0.0, -0.0, 0.5, 12000.0, -200000.0]
    also = [n.value for n in read["also"].value]
    assert also[:3] == [math.inf, -math.inf, math.inf] and math.isnan(also[3])


def test_explicit_tags_read_the_same_grammar():
    assert value("!!float 3") == 3.0 and type(value("!!float 3")) is float
    assert value("!!int 0o7") == 7 and value("!!float 1.5e2") == 150.0
    with pytest.raises(SceneError, match=r"here: x: expected a value that int can read, got '1_000' "
                                         r"\(not a YAML 1\.2 integer\)$"):
        value("!!int 1_000")
    with pytest.raises(SceneError, match=r"expected a value that float can read, got '0b1' \(not a YAML 1\.2 float\)"):
        value("!!float 0b1")


def test_the_grammar_functions():
    assert core_int("-19") == -19 and core_int("0x3A") == 58 and core_int("0o7") == 7
    assert core_float("-.Inf") == -math.inf and core_float("6.02e23") == 6.02e23
    for text in ("1_000", " 1", "0b1"):
        with pytest.raises(ValueError):
            core_int(text)
    with pytest.raises(ValueError):
        core_float("1_0.5")  # Python's float() reads underscores; YAML 1.2 does not


def test_pyyamls_own_loader_is_left_as_it_is():
    compose("a: 1.5e2", "", lambda _mark: "here", "here")
    assert yaml.safe_load("a: 1_000\nb: 1.5e2") == {"a": 1000, "b": "1.5e2"}  # YAML 1.1, unchanged


@pytest.mark.parametrize("text, expected", [("1.5e2", 150.0), ("6.02e23", 6.02e23), ("+.5", 0.5), ("0o17", 15.0)])
def test_scene_files_and_set_read_numbers_alike(text, expected):
    from_file = parse_scene(SCENE + f"background: {text}\n")
    from_set = parse_scene(SCENE, overrides=[f"background={text}"])
    assert from_file.background.tolist() == from_set.background.tolist() == [expected] * 3


def test_a_file_number_in_the_new_forms():
    scene = parse_scene(SCENE.replace("intensity: 10", "intensity: 1.5e2")
                        .replace("look_at: [0, 0, 0]}", "look_at: [0, 0, 0], far: 6.02e23}"))
    assert scene.lights[0].intensity.tolist() == [150.0] * 3 and scene.camera.far == 6.02e23


@pytest.mark.parametrize("where", ["file", "set"])
@pytest.mark.parametrize("text", [".nan", "-.inf", ".Inf"])
def test_non_finite_numbers_are_still_refused_by_the_fields(where, text):
    with pytest.raises(SceneError, match=r"background: expected a finite number >= 0, got (\.nan|-?\.inf)$"):
        if where == "file":
            parse_scene(SCENE + f"background: {text}\n")
        else:
            parse_scene(SCENE, overrides=[f"background={text}"])


@pytest.mark.parametrize("text", ["1_000", "0b1", "1:30"])
def test_a_yaml_1_1_number_is_refused_with_a_hint(text):
    with pytest.raises(SceneError, match=rf"image\.spp: expected an integer in \[1, 4096\], got '{text}' \(a number "
                                         r"in YAML 1\.1 only: clrays reads YAML 1\.2's, without `_`, `0b` or base 60\)$"):
        parse_scene(SCENE, overrides=[f"image.spp={text}"])
    with pytest.raises(SceneError, match=rf"<string>:2:\d+: image\.spp: expected an integer .*got '{text}' \(a number "
                                         r"in YAML 1\.1 only"):
        parse_scene(SCENE.replace("height: 8}", f"height: 8, spp: {text}}}"))


def test_010_is_ten():
    assert parse_scene(SCENE, overrides=["image.spp=010"]).image.spp == 10
