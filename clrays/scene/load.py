"""Load and validate a YAML scene file (format version 1) into a `clrays.scene.model.Scene`.

    scene = load_scene("scenes/demo.yaml", overrides=["render.steps=1024"])

The YAML is composed (not constructed) so every value keeps the line and column it came
from; the tree is wrapped in `_Node`s, `--set` overrides are spliced into it, and then a
small layer of typed readers (`_number`, `_integer`, `_vec3`, `_rgb`, `_direction`,
`_choice`, `_mapping`, ...) turns it into the frozen dataclasses. Any problem raises
`SceneError` with one line, like a compiler:

    scenes/x.yaml:14:9: lights.0.cone_deg: expected a number in (0, 90], got 120
    --set render.steps=abc: render.steps: expected an integer in [1, 65536], got 'abc'

The full format is documented in docs/scene-format.md.
"""
from __future__ import annotations

import dataclasses
import difflib
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, NoReturn, Sequence

import numpy as np
import yaml

from . import geometry as primitives
from .animation import EASINGS, Animation, Key, ObjectRig, Track
from ..errors import SceneError
from .model import (Camera, DirectionalLight, Geometry, Image, Light, Medium, Phase,
                    PointLight, Render, Scene, SpotLight)
from .transforms import (affine, matrix_to_quat, quat_to_matrix, rotation_axis_angle, rotation_euler,
                         transform_points)

FORMAT_VERSION = 1

# Limits (inclusive unless noted); docs/scene-format.md lists the same numbers.
MAX_IMAGE_SIDE = 16384
MAX_IMAGE_PIXELS = 1 << 26
MAX_SPP = 4096
MAX_STEPS = 65536
SHADOW_MAP_RANGE = (16, 8192)
SLICES_RANGE = (16, 16384)  # also gamma_samples
SVD_RANK_RANGE = (1, 16)
MAX_PCF = 16
SPHERE_SEGMENTS_RANGE = (4, 1024)
PLANE_SEGMENTS_RANGE = (1, 1024)
QUATERNION_TOLERANCE = 1e-6
MAX_FRAME = 100_000  # animation frame numbers: [0, MAX_FRAME]
MAX_FPS = 1000.0
DEFAULT_FPS = 24.0
PARALLEL_TOLERANCE = 1e-6  # |sin| of the angle between camera up and the view direction

DEFAULT_SPHERE_SEGMENTS = 48
DEFAULT_PLANE_SEGMENTS = 8
DEFAULT_ALBEDO = 0.8


# --------------------------------------------------------------------------- YAML tree


class _Loader(yaml.SafeLoader):
    """SafeLoader that also reads YAML 1.2 floats without a dot (1e3, -2E-4) as floats."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?[0-9][0-9_]*[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


@dataclass(eq=False)
class _Node:
    """One value of the scene tree and where it was written.

    value is a dict[str, _Node] (mapping), a list[_Node] (sequence) or a plain scalar
    (int, float, str, bool, None, ...). where is "file:line:col" or "--set key=value";
    path is the dotted key path ("lights.0.cone_deg", "" for the top level).
    """

    value: Any
    where: str
    path: str
    key_where: dict[str, str] = field(default_factory=dict)  # mapping: where each key is

    @property
    def label(self) -> str:
        return self.path or "(top level)"

    def child_path(self, key: str | int) -> str:
        return _join(self.path, key)

    def fail(self, expected: str, got: str | None = None) -> NoReturn:
        raise SceneError(f"{self.where}: {self.label}: expected {expected}, "
                         f"got {_show(self) if got is None else got}")


def _show(node: _Node | Any, limit: int = 60) -> str:
    """A short, YAML-like rendering of a value for messages; strings are quoted."""

    def show(v: Any) -> str:
        if isinstance(v, _Node):
            v = v.value
        if isinstance(v, dict):
            return "{" + ", ".join(f"{k}: {show(x)}" for k, x in v.items()) + "}"
        if isinstance(v, list):
            return "[" + ", ".join(show(x) for x in v) + "]"
        if isinstance(v, bool):
            return "true" if v else "false"
        if v is None:
            return "null"
        if isinstance(v, float):
            if math.isnan(v):
                return ".nan"
            if math.isinf(v):
                return ".inf" if v > 0 else "-.inf"
            return repr(v)
        if isinstance(v, str):
            return repr(v)
        return str(v)

    text = show(node)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _mark_where(filename: str) -> Callable[[yaml.Mark], str]:
    return lambda mark: f"{filename}:{mark.line + 1}:{mark.column + 1}"


class _Converter:
    """Wraps a composed YAML tree in `_Node`s: scalars constructed by the safe loader,
    mapping keys checked (strings, no duplicates), `<<: *anchor` merge keys resolved."""

    def __init__(self, loader: yaml.SafeLoader, where: Callable[[yaml.Mark], str]):
        self.loader = loader
        self.where = where
        self.merged: set[int] = set()  # mappings already flattened (an alias repeats them)

    def convert(self, node: yaml.Node, path: str, active: frozenset[int] = frozenset()) -> _Node:
        here = self.where(node.start_mark)
        if id(node) in active:  # an alias inside its own anchor
            raise SceneError(f"{here}: {path or '(top level)'}: expected a finite tree, got a recursive alias")
        active = active | {id(node)}
        if isinstance(node, yaml.SequenceNode):
            return _Node([self.convert(n, _join(path, i), active) for i, n in enumerate(node.value)],
                         here, path)
        if isinstance(node, yaml.MappingNode):
            self.flatten(node, path)
            items, key_where = {}, {}
            for key_node, value_node in node.value:  # later keys win over merged ones
                key = self.key(key_node, path)
                items[key] = self.convert(value_node, _join(path, key), active)
                key_where[key] = self.where(key_node.start_mark)
            return _Node(items, here, path, key_where)
        return _Node(self.construct(node, path), here, path)

    def construct(self, node: yaml.Node, path: str) -> Any:
        try:
            return self.loader.construct_object(node)
        except yaml.MarkedYAMLError as exc:  # an unknown tag, a malformed !!binary, ...
            raise _yaml_error(exc, self.where, path=path) from None

    def key(self, node: yaml.Node, path: str) -> str:
        key = self.construct(node, path) if isinstance(node, yaml.ScalarNode) else None
        if not isinstance(key, str):
            raise SceneError(f"{self.where(node.start_mark)}: {path or '(top level)'}: "
                             f"expected a string key, got {_show(key) if key is not None else 'a ' + node.id}")
        return key

    def flatten(self, node: yaml.MappingNode, path: str) -> None:
        """Reject keys written twice, then splice in merged (`<<`) keys, once per node."""
        if id(node) in self.merged:
            return
        first: dict[str, yaml.Mark] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.key(key_node, path)
            if key in first:
                raise SceneError(f"{self.where(key_node.start_mark)}: {_join(path, key)}: expected each "
                                 f"key once, got a duplicate (first at line {first[key].line + 1})")
            first[key] = key_node.start_mark
        try:
            self.loader.flatten_mapping(node)
        except yaml.MarkedYAMLError as exc:
            raise _yaml_error(exc, self.where, path=path) from None
        self.merged.add(id(node))


def _join(path: str, key: str | int) -> str:
    return f"{path}.{key}" if path else str(key)


def _yaml_error(exc: yaml.YAMLError, where: Callable[[yaml.Mark], str], fallback: str = "",
                path: str = "") -> SceneError:
    """A yaml exception as one line at its problem mark (or `fallback` when it has none)."""
    problem = " ".join(str(getattr(exc, "problem", None) or exc).split())
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    prefix = where(mark) if mark is not None else fallback
    return SceneError(f"{prefix}: {path + ': ' if path else ''}malformed YAML: {problem}")


def _compose(text: str, path: str, where: Callable[[yaml.Mark], str], fallback: str) -> _Node | None:
    """Compose one YAML document into a `_Node` tree (None for an empty document)."""
    loader = _Loader(text)
    try:
        try:
            root = loader.get_single_node()
        except yaml.YAMLError as exc:
            raise _yaml_error(exc, where, fallback, path) from None
        return None if root is None else _Converter(loader, where).convert(root, path)
    finally:
        loader.dispose()


# --------------------------------------------------------------------------- overrides


def _apply_override(root: _Node, text: str) -> None:
    """Splice one `key.path=value` override into the tree (creating missing mappings)."""
    where = f"--set {text}"
    key, sep, value_text = text.partition("=")
    key = key.strip()
    parts = key.split(".")
    if not sep or not key or any(not p.strip() for p in parts):
        raise SceneError(f"{where}: expected key.path=value, got {text!r}")
    parts = [p.strip() for p in parts]
    value = _compose(value_text, key, lambda _mark: where, where)
    if value is None:  # `key=` sets null, which the schema then rejects or accepts
        value = _Node(None, where, key)

    node = root
    for depth, part in enumerate(parts):
        last = depth == len(parts) - 1
        path = ".".join(parts[: depth + 1])
        if isinstance(node.value, dict):
            if last:
                node.value[part] = value
                node.key_where[part] = where
            else:
                if part not in node.value:
                    node.value[part] = _Node({}, where, path)
                    node.key_where[part] = where
                node = node.value[part]
        elif isinstance(node.value, list):
            n = len(node.value)
            if not part.isdigit() or int(part) > n or (int(part) == n and not last):
                what = f"a list index in [0, {n - 1}]" if n else "no index (the list is empty)"
                if last:
                    what += f" or {n} to append" if n else "; set it whole or use 0 to append"
                raise SceneError(f"{where}: {path}: expected {what}, got {part!r}")
            index = int(part)
            if last:
                node.value[index:index + 1] = [value]
            else:
                node = node.value[index]
        else:
            raise SceneError(f"{where}: {path}: expected a mapping or a list to set "
                             f"{'.'.join(parts[depth:])} in, got {_show(node)}")


# --------------------------------------------------------------------------- readers


def _mapping(node: _Node, required: Sequence[str] = (), optional: Sequence[str] = ()) -> dict[str, _Node]:
    """node as a mapping with only the given keys, all required ones present."""
    if not isinstance(node.value, dict):
        node.fail("a mapping")
    allowed = list(required) + [k for k in optional if k not in required]
    for key in node.value:
        if key not in allowed:
            close = difflib.get_close_matches(key, allowed, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise SceneError(f"{node.key_where.get(key, node.where)}: {node.child_path(key)}: "
                             f"unknown key{hint}; expected one of: {', '.join(allowed)}")
    for key in required:
        if key not in node.value:
            raise SceneError(f"{node.where}: {node.label}: missing required key {key!r}")
    return node.value


def _range_text(kind: str, lo, hi, lo_open: bool = False, hi_open: bool = False) -> str:
    if lo is not None and hi is not None:
        return f"{kind} in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{kind} {'>' if lo_open else '>='} {lo:g}"
    if hi is not None:
        return f"{kind} {'<' if hi_open else '<='} {hi:g}"
    return kind


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _number(node: _Node | None, lo: float | None = None, hi: float | None = None, *,
            lo_open: bool = False, hi_open: bool = False, default: float | None = None) -> float:
    """A finite number (int or float, never bool) in the given range."""
    if node is None:
        assert default is not None
        return float(default)
    v = node.value
    what = _range_text("a number", lo, hi, lo_open, hi_open)
    if not _is_number(v):
        node.fail(what)
    finite = math.isfinite(v) if isinstance(v, float) else abs(v) <= 1e308  # huge ints overflow
    if not finite:
        node.fail(what.replace("a number", "a finite number", 1))
    if ((lo is not None and (v <= lo if lo_open else v < lo))
            or (hi is not None and (v >= hi if hi_open else v > hi))):
        node.fail(what)
    return float(v)


def _integer(node: _Node | None, lo: int | None = None, hi: int | None = None, *,
             default: int | None = None) -> int:
    """An integer (not a bool, not a float) in [lo, hi]."""
    if node is None:
        assert default is not None
        return int(default)
    v = node.value
    if (not isinstance(v, int) or isinstance(v, bool) or (lo is not None and v < lo)
            or (hi is not None and v > hi)):
        node.fail(_range_text("an integer", lo, hi))
    return int(v)


def _boolean(node: _Node | None, default: bool) -> bool:
    if node is None:
        return default
    if not isinstance(node.value, bool):
        node.fail("true or false")
    return node.value


def _choice(node: _Node | None, options: Sequence[str], default: str | None = None) -> str:
    if node is None:
        assert default is not None
        return default
    if node.value not in options or not isinstance(node.value, str):
        node.fail("one of " + ", ".join(repr(o) for o in options))
    return node.value


def _typed(node: _Node, kinds: dict[str, tuple[tuple[str, ...], tuple[str, ...]]],
           common: tuple[str, ...] = ()) -> tuple[str, dict[str, _Node]]:
    """A mapping whose `type` names one of `kinds` (type -> (required keys, optional keys));
    returns (type, mapping) with the keys checked against that type (plus `common`)."""
    if not isinstance(node.value, dict) or "type" not in node.value:
        everything = [k for req, opt in kinds.values() for k in req + opt] + list(common)
        _mapping(node, required=("type",), optional=everything)
    kind = _choice(node.value["type"], tuple(kinds))
    required, optional = kinds[kind]
    return kind, _mapping(node, required=("type",) + required, optional=optional + common)


def _list(node: _Node, what: str, min_len: int = 0) -> list[_Node]:
    if not isinstance(node.value, list) or len(node.value) < min_len:
        node.fail(what)
    return node.value


def _numbers(node: _Node, n: int, what: str, lo: float | None = None, hi: float | None = None,
             **kw) -> np.ndarray:
    """A list of exactly n numbers; each element is checked (and reported) on its own."""
    if not isinstance(node.value, list) or len(node.value) != n:
        node.fail(what)
    return np.array([_number(x, lo, hi, **kw) for x in node.value], dtype=np.float64)


def _vec3(node: _Node) -> np.ndarray:
    return _numbers(node, 3, "a list of 3 numbers [x, y, z]")


def _direction(node: _Node) -> np.ndarray:
    """A non-zero 3-vector, normalised."""
    v = _vec3(node)
    norm = float(np.linalg.norm(v))
    if norm == 0.0 or not math.isfinite(norm):
        node.fail("a non-zero direction [x, y, z]")
    return v / norm


#: Largest light power accepted: beyond it float32 radiance on the device overflows.
MAX_POWER = 1e30


def _power(node: _Node | None) -> np.ndarray:
    """A light's intensity (W/sr) or irradiance: RGB ≥ 0, at most MAX_POWER."""
    power = _rgb(node)
    if power.max() > MAX_POWER:
        node.fail(f"a power of at most {MAX_POWER:g} (beyond it float32 radiance overflows)")
    return power


def _rgb(node: _Node | None, lo: float = 0.0, hi: float | None = None, *,
         default: float | None = None) -> np.ndarray:
    """A colour: a number (broadcast to RGB) or a list of 3 numbers, each in [lo, hi]."""
    if node is None:
        assert default is not None
        return np.full(3, float(default))
    if isinstance(node.value, list):
        what = f"a list of 3 numbers (RGB) or a single {_range_text('number', lo, hi)}"
        return _numbers(node, 3, what, lo, hi)
    return np.full(3, _number(node, lo, hi))


def _scale(node: _Node | None) -> np.ndarray:
    """A positive number or a list of 3 positive numbers."""
    if node is None:
        return np.ones(3)
    if isinstance(node.value, list):
        return _numbers(node, 3, "a number > 0 or a list of 3 numbers > 0", 0.0, lo_open=True)
    return np.full(3, _number(node, 0.0, lo_open=True))


# --------------------------------------------------------------------------- sections


def _image(node: _Node) -> Image:
    m = _mapping(node, required=("width", "height"), optional=("spp",))
    width = _integer(m["width"], 1, MAX_IMAGE_SIDE)
    height = _integer(m["height"], 1, MAX_IMAGE_SIDE)
    if width * height > MAX_IMAGE_PIXELS:
        node.fail(f"width * height <= {MAX_IMAGE_PIXELS} pixels",
                  f"{width} x {height} = {width * height}")
    return Image(width=width, height=height, spp=_integer(m.get("spp"), 1, MAX_SPP, default=1))


def _camera(node: _Node) -> Camera:
    m = _mapping(node, required=("position", "look_at"), optional=("up", "fov_deg", "far"))
    position = _vec3(m["position"])
    look_at = _vec3(m["look_at"])
    if np.array_equal(position, look_at):
        m["look_at"].fail("a point different from camera.position")
    up = _direction(m["up"]) if "up" in m else np.array([0.0, 1.0, 0.0])
    forward = (look_at - position) / np.linalg.norm(look_at - position)
    if np.linalg.norm(np.cross(forward, up)) < PARALLEL_TOLERANCE:
        up_node = m.get("up") or _Node([0, 1, 0], node.where, node.child_path("up"))
        up_node.fail("a direction not parallel to look_at - position",
                     None if "up" in m else "[0, 1, 0] (default)")
    defaults = _defaults(Camera)
    return Camera(position=position, look_at=look_at, up=up,
                  fov_deg=_number(m.get("fov_deg"), 0.0, 180.0, lo_open=True, hi_open=True,
                                  default=defaults["fov_deg"]),
                  far=_number(m.get("far"), 0.0, lo_open=True, default=defaults["far"]))


_LIGHTS = {  # type -> (required keys, optional keys)
    "point": (("position", "intensity"), ()),
    "spot": (("position", "direction", "cone_deg", "intensity"), ()),
    "directional": (("direction", "irradiance"), ()),
}


def _light(node: _Node) -> Light:
    kind, m = _typed(node, _LIGHTS)
    if kind == "point":
        return PointLight(position=_vec3(m["position"]), intensity=_power(m["intensity"]))
    if kind == "spot":
        return SpotLight(position=_vec3(m["position"]), direction=_direction(m["direction"]),
                         cone_deg=_number(m["cone_deg"], 0.0, 90.0, lo_open=True),
                         intensity=_power(m["intensity"]))
    return DirectionalLight(direction=_direction(m["direction"]), irradiance=_power(m["irradiance"]))


def _phase(node: _Node) -> Phase:
    kind, m = _typed(node, {"isotropic": ((), ()), "hg": (("g",), ())})
    if kind == "isotropic":
        return Phase()
    return Phase(type="hg", g=_number(m["g"], -1.0, 1.0, lo_open=True, hi_open=True))


def _medium(node: _Node | None) -> Medium:
    if node is None:
        return Medium(sigma_s=np.zeros(3), sigma_a=np.zeros(3))
    m = _mapping(node, optional=("sigma_s", "sigma_a", "phase"))
    return Medium(sigma_s=_rgb(m.get("sigma_s"), default=0.0),
                  sigma_a=_rgb(m.get("sigma_a"), default=0.0),
                  phase=_phase(m["phase"]) if "phase" in m else Phase())


def _render(node: _Node | None) -> Render:
    d = _defaults(Render)
    if node is None:
        return Render()
    m = _mapping(node, optional=tuple(d))
    return Render(
        method=_choice(m.get("method"), ("raymarch", "exact", "minmax"), d["method"]),
        steps=_integer(m.get("steps"), 1, MAX_STEPS, default=d["steps"]),
        jitter=_boolean(m.get("jitter"), d["jitter"]),
        shadow_map=_integer(m.get("shadow_map"), *SHADOW_MAP_RANGE, default=d["shadow_map"]),
        pcf=_integer(m.get("pcf"), 0, MAX_PCF, default=d["pcf"]),
        slices=_integer(m.get("slices"), *SLICES_RANGE, default=d["slices"]),
        gamma_samples=_integer(m.get("gamma_samples"), *SLICES_RANGE, default=d["gamma_samples"]),
        integrand=_choice(m.get("integrand"), ("svd", "table", "analytic"), d["integrand"]),
        svd_rank=_integer(m.get("svd_rank"), *SVD_RANK_RANGE, default=d["svd_rank"]),
        traversal=_choice(m.get("traversal"), ("tree", "scan"), d["traversal"]),
    )


def _defaults(cls) -> dict[str, Any]:
    return {f.name: f.default for f in dataclasses.fields(cls)
            if f.default is not dataclasses.MISSING}


# --------------------------------------------------------------------------- objects


def _rotation(node: _Node) -> np.ndarray:
    """3x3 from exactly one of {axis, angle_deg}, {euler_deg, order}, {quaternion}."""
    forms = {"axis-angle": ("axis", "angle_deg"), "euler": ("euler_deg", "order"),
             "quaternion": ("quaternion",)}
    m = _mapping(node, optional=[k for keys in forms.values() for k in keys])
    used = [name for name, keys in forms.items() if any(k in m for k in keys)]
    if len(used) != 1:
        node.fail("exactly one of {axis, angle_deg}, {euler_deg, order} or {quaternion}")
    if used == ["axis-angle"]:
        m = _mapping(node, required=("axis", "angle_deg"))
        return rotation_axis_angle(_direction(m["axis"]), math.radians(_number(m["angle_deg"])))
    if used == ["euler"]:
        m = _mapping(node, required=("euler_deg",), optional=("order",))
        angles = _numbers(m["euler_deg"], 3, "a list of 3 angles in degrees")
        order = "xyz"
        if "order" in m:
            order = m["order"].value
            if (not isinstance(order, str) or len(order) != 3 or set(order) - set("xyz")
                    or order[0] == order[1] or order[1] == order[2]):
                m["order"].fail("3 letters over 'xyz' with no adjacent repeats, like 'xyz' or 'zxz'")
        return rotation_euler(np.radians(angles), order)
    return quat_to_matrix(_unit_quaternion(m["quaternion"]))


def _unit_quaternion(node: _Node) -> np.ndarray:
    q = _numbers(node, 4, "a unit quaternion [w, x, y, z]")
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUATERNION_TOLERANCE:
        node.fail(f"a unit quaternion [w, x, y, z] (|q| = 1 within {QUATERNION_TOLERANCE:g})",
                  f"{_show(node)} with |q| = {norm:.9g}")
    return q


def _transform_parts(node: _Node | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(translate (3,), rotation 3x3, scale (3,)); the identity for no transform."""
    if node is None:
        return np.zeros(3), np.eye(3), np.ones(3)
    m = _mapping(node, optional=("translate", "rotate", "scale"))
    translate = _vec3(m["translate"]) if "translate" in m else np.zeros(3)
    rotate = _rotation(m["rotate"]) if "rotate" in m else np.eye(3)
    return translate, rotate, _scale(m.get("scale"))


def _triangles(m: dict[str, _Node]) -> np.ndarray:
    vertices = np.array([_vec3(v) for v in _list(m["vertices"], "a list of at least 3 vertices [x, y, z]", 3)])
    n = len(vertices)
    faces = []
    for face in _list(m["faces"], "a list of at least 1 face [i, j, k]", 1):
        if not isinstance(face.value, list) or len(face.value) != 3:
            face.fail("a face: a list of 3 vertex indices [i, j, k]")
        faces.append([_integer(i, 0, n - 1) for i in face.value])
    return primitives.indexed_triangles(vertices, np.array(faces))


def _box(m: dict[str, _Node]) -> np.ndarray:
    lo, hi = _vec3(m["min"]), _vec3(m["max"])
    if not (lo < hi).all():
        m["max"].fail(f"a point above min {_show(m['min'])} on every axis")
    return primitives.box_triangles(lo, hi)


def _sphere(m: dict[str, _Node]) -> np.ndarray:
    return primitives.sphere_triangles(
        _vec3(m["center"]), _number(m["radius"], 0.0, lo_open=True),
        _integer(m.get("segments"), *SPHERE_SEGMENTS_RANGE, default=DEFAULT_SPHERE_SEGMENTS))


def _plane(m: dict[str, _Node]) -> np.ndarray:
    return primitives.plane_triangles(
        _vec3(m["center"]), _direction(m["normal"]), _number(m["size"], 0.0, lo_open=True),
        _integer(m.get("segments"), *PLANE_SEGMENTS_RANGE, default=DEFAULT_PLANE_SEGMENTS))


def _mesh(m: dict[str, _Node], base_dir: Path) -> np.ndarray:
    node = m["file"]
    if not isinstance(node.value, str) or not node.value.strip():
        node.fail("a mesh file path (.obj, .ply or .stl)")
    path = Path(node.value)
    path = path if path.is_absolute() else base_dir / path
    try:
        return primitives.load_mesh_triangles(path)
    except (ValueError, OSError) as exc:
        node.fail("a readable mesh file (.obj, .ply or .stl) with triangles",
                  f"{_show(node)} ({exc}: {path})")


# type -> (required keys, optional keys, builder(mapping, base_dir))
_OBJECTS: dict[str, tuple[tuple[str, ...], tuple[str, ...], Callable[[dict, Path], np.ndarray]]] = {
    "triangles": (("vertices", "faces"), (), lambda m, _: _triangles(m)),
    "plane": (("center", "normal", "size"), ("segments",), lambda m, _: _plane(m)),
    "box": (("min", "max"), (), lambda m, _: _box(m)),
    "sphere": (("center", "radius"), ("segments",), lambda m, _: _sphere(m)),
    "mesh": (("file",), (), _mesh),
}
_OBJECT_COMMON = ("albedo", "transform")


def _object(node: _Node, base_dir: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple]:
    """(triangles (T, 3, 3) world space, albedo (3,), triangles before the transform,
    transform parts (translate, rotation, scale)) of one object."""
    kind, m = _typed(node, {k: (req, opt) for k, (req, opt, _) in _OBJECTS.items()}, _OBJECT_COMMON)
    build = _OBJECTS[kind][2]
    albedo = _rgb(m.get("albedo"), 0.0, 1.0, default=DEFAULT_ALBEDO)
    parts = _transform_parts(m.get("transform"))
    local = tris = build(m, base_dir)
    if "transform" in m:
        tris = transform_points(affine(*parts), tris)
    return tris, albedo, local, parts


def _geometry(node: _Node | None, base_dir: Path, rigs: list | None = None) -> Geometry:
    """All objects flattened; `rigs`, when given, receives each object's ObjectRig."""
    tris, albedo, ids = [np.zeros((0, 3, 3))], [np.zeros((0, 3))], [np.zeros(0, np.int32)]
    start = 0
    for i, obj in enumerate(_list(node, "a list of objects") if node is not None else []):
        t, a, local, (translate, rotate, scale) = _object(obj, base_dir)
        if rigs is not None:
            rigs.append(ObjectRig(local, slice(start, start + len(t)), translate, matrix_to_quat(rotate), scale))
        start += len(t)
        tris.append(t)
        albedo.append(np.broadcast_to(a, (len(t), 3)))
        ids.append(np.full(len(t), i, dtype=np.int32))
    return Geometry(triangles=np.ascontiguousarray(np.concatenate(tris), dtype=np.float64),
                    albedo=np.ascontiguousarray(np.concatenate(albedo), dtype=np.float64),
                    object_id=np.concatenate(ids).astype(np.int32))


# --------------------------------------------------------------------------- animation

# Animated properties: name -> (reader, interpolation). Lights by type, like _LIGHTS.
_Reader = tuple[Callable[[_Node], Any], str]
_CAMERA_TRACKS: dict[str, _Reader] = {
    "position": (_vec3, "linear"),
    "look_at": (_vec3, "linear"),
    "up": (_direction, "direction"),
    "orientation": (_unit_quaternion, "rotation"),
    "fov_deg": (lambda n: _number(n, 0.0, 180.0, lo_open=True, hi_open=True), "linear"),
}
_LIGHT_TRACKS: dict[str, dict[str, _Reader]] = {
    "point": {"position": (_vec3, "linear"), "intensity": (_power, "linear")},
    "spot": {"position": (_vec3, "linear"), "direction": (_direction, "direction"),
             "cone_deg": (lambda n: _number(n, 0.0, 90.0, lo_open=True), "linear"), "intensity": (_power, "linear")},
    "directional": {"direction": (_direction, "direction"), "irradiance": (_power, "linear")},
}
_OBJECT_TRACKS: dict[str, _Reader] = {
    "translate": (_vec3, "linear"),
    "rotate": (lambda n: matrix_to_quat(_rotation(n)), "rotation"),
    "scale": (_scale, "linear"),
}
_MEDIUM_TRACKS: dict[str, _Reader] = {
    "sigma_s": (_rgb, "linear"),
    "sigma_a": (_rgb, "linear"),
    "g": (lambda n: _number(n, -1.0, 1.0, lo_open=True, hi_open=True), "linear"),
}


def _keys(node: _Node, tracks: dict[str, _Reader], easing: str) -> tuple[dict[str, Track], dict[str, list[_Node]]]:
    """A list of keys {frame, [easing], property: value, ...} → one Track per property
    (and the value nodes of each, for later messages)."""
    keys: dict[str, list[Key]] = {}
    nodes: dict[str, list[_Node]] = {}
    previous = None
    for item in _list(node, "a list of at least 1 key {frame: ..., <property>: ...}", 1):
        m = _mapping(item, required=("frame",), optional=("easing",) + tuple(tracks))
        frame = _number(m["frame"])
        if previous is not None and frame <= previous:
            m["frame"].fail(f"a frame after {previous:g} (keys in increasing frame order)")
        previous = frame
        key_easing = _choice(m.get("easing"), tuple(EASINGS), easing)
        names = [name for name in m if name in tracks]
        if not names:
            item.fail(f"a key that sets at least one of {', '.join(tracks)}")
        for name in names:
            reader, kind = tracks[name]
            value = reader(m[name])
            if kind == "direction" and keys.get(name) and float(value @ keys[name][-1].value) <= -1.0 + 1e-12:
                m[name].fail("a direction not opposite to the previous key's (the way between them is undefined)")
            keys.setdefault(name, []).append(Key(frame, value, key_easing))
            nodes.setdefault(name, []).append(m[name])
    return {name: Track(tracks[name][1], tuple(k)) for name, k in keys.items()}, nodes


def _indexed_tracks(node: _Node, what: str, count: int, tracks_of: Callable[[int], dict[str, _Reader]],
                    easing: str) -> dict[int, tuple[dict[str, Track], dict[str, list[_Node]]]]:
    """A list of {<what>: index, keys: [...]} (a light or an object per entry)."""
    found: dict[int, tuple[dict[str, Track], dict[str, list[_Node]]]] = {}
    for entry in _list(node, f"a list of {{{what}: index, keys: [...]}}"):
        m = _mapping(entry, required=(what, "keys"))
        index = _integer(m[what], 0, count - 1) if count else m[what].fail(f"no {what} index (there are none)")
        if index in found:
            m[what].fail(f"each {what} animated once (merge its keys into one entry)", f"{index} again")
        found[index] = _keys(m["keys"], tracks_of(index), easing)
    return found


def _animation(node: _Node, scene: Scene, rigs: list[ObjectRig]) -> Animation:
    m = _mapping(node, required=("frames",), optional=("fps", "easing", "camera", "lights", "objects", "medium"))
    fps = _number(m.get("fps"), 0.0, MAX_FPS, lo_open=True, default=DEFAULT_FPS)
    frames = m["frames"]
    if not isinstance(frames.value, list) or len(frames.value) != 2:
        frames.fail("[first, last]: the first and last frame, inclusive")
    first, last = (_integer(n, 0, MAX_FRAME) for n in frames.value)
    if last < first:
        frames.value[1].fail(f"a last frame >= the first, {first}")
    easing = _choice(m.get("easing"), tuple(EASINGS), "linear")

    camera, camera_nodes = _keys(m["camera"], _CAMERA_TRACKS, easing) if "camera" in m else ({}, {})
    if "orientation" in camera:
        for name in ("look_at", "up"):
            if name in camera:
                camera_nodes[name][0].fail("no look_at or up keys beside orientation keys (the orientation "
                                           "points the camera)", f"{name} keys")
    lights = _indexed_tracks(m["lights"], "light", len(scene.lights),
                             lambda i: _LIGHT_TRACKS[scene.lights[i].type], easing) if "lights" in m else {}
    objects = _indexed_tracks(m["objects"], "object", len(rigs), lambda i: _OBJECT_TRACKS,
                              easing) if "objects" in m else {}
    medium, medium_nodes = _keys(m["medium"], _MEDIUM_TRACKS, easing) if "medium" in m else ({}, {})
    if "g" in medium and scene.medium.phase.type != "hg":
        medium_nodes["g"][0].fail("a medium with phase {type: hg, g: ...} (only then is there a g to animate)",
                                  f"{_show(medium_nodes['g'][0])} with phase {scene.medium.phase.type!r}")
    animation = Animation(
        fps=fps, first=first, last=last, camera=camera, medium=medium,
        lights={i: tracks for i, (tracks, _) in lights.items()},
        objects={i: (rigs[i], tracks) for i, (tracks, _) in objects.items()},
    )
    if camera.keys() & {"position", "look_at", "up"} and "orientation" not in camera:
        _check_camera_path(m["camera"], animation, scene)
    return animation


def _check_camera_path(node: _Node, animation: Animation, scene: Scene) -> None:
    """Every frame's camera must be valid, like a static one (look_at off the position,
    up off the view direction)."""
    for frame in animation.frames:
        camera = animation._camera(scene, frame)
        view = camera.look_at - camera.position
        if not np.any(view):
            node.fail("look_at away from position at every frame", f"look_at = position at frame {frame}")
        if np.linalg.norm(np.cross(view / np.linalg.norm(view), camera.up)) < PARALLEL_TOLERANCE:
            node.fail("up not parallel to look_at - position at every frame", f"parallel at frame {frame}")


# --------------------------------------------------------------------------- entry points

_TOP_REQUIRED = ("version", "image", "camera", "lights")
_TOP_OPTIONAL = ("medium", "background", "objects", "render", "animation")


def parse_scene(text: str, source: Path | str | None = None, overrides: Sequence[str] = ()) -> Scene:
    """Parse scene YAML text. `source` names the file in messages and its folder is where
    relative mesh paths start (the working directory when None)."""
    return _parse(text, str(source) if source is not None else "<string>", source, overrides)


def _parse(text: str, filename: str, source: Path | str | None, overrides: Sequence[str]) -> Scene:
    root = _compose(text, "", _mark_where(filename), filename)
    if root is None:
        raise SceneError(f"{filename}:1:1: (top level): expected a mapping, got an empty document")
    if not isinstance(root.value, dict):
        root.fail("a mapping")
    if isinstance(overrides, str):
        overrides = [overrides]
    for override in overrides:
        _apply_override(root, override)

    top = root.value
    if "version" not in top:
        raise SceneError(f"{root.where}: (top level): missing required key 'version' "
                         f"(this loader reads version: {FORMAT_VERSION})")
    version = top["version"]
    if not isinstance(version.value, int) or isinstance(version.value, bool) or version.value != FORMAT_VERSION:
        version.fail(f"version {FORMAT_VERSION}")
    m = _mapping(root, required=_TOP_REQUIRED, optional=_TOP_OPTIONAL)

    base_dir = Path(source).parent if source is not None else Path.cwd()
    rigs: list[ObjectRig] = []
    scene = Scene(  # sections are read (and fail) in the order the format lists them
        image=_image(m["image"]),
        camera=_camera(m["camera"]),
        lights=tuple(_light(n) for n in _list(m["lights"], "a list of at least 1 light", 1)),
        medium=_medium(m.get("medium")),
        background=_rgb(m.get("background"), default=0.0),
        geometry=_geometry(m.get("objects"), base_dir, rigs if "animation" in m else None),
        render=_render(m.get("render")),
        source=Path(source) if source is not None else None,
    )
    if "animation" in m:
        scene = dataclasses.replace(scene, animation=_animation(m["animation"], scene, rigs))
    return scene


def load_scene(path: Path | str, overrides: Sequence[str] = ()) -> Scene:
    """Read, override (`key.path=value` strings, as from `--set`) and validate a scene file."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError(f"{path}: cannot read scene file: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except OSError as exc:
        raise SceneError(f"{path}: cannot read scene file: {exc.strerror or exc}") from None
    return _parse(text, str(path), path, overrides)
