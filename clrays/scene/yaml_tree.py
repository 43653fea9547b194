"""YAML with positions: a composed document as a tree of `Node`s that remember where
each value was written, `--set key.path=value` overrides spliced into it, and typed
readers that turn nodes into numbers, vectors and choices or fail in one line:

    scenes/x.yaml:14:9: lights.0.cone_deg: expected a number in (0, 90], got 120
    --set render.steps=abc: render.steps: expected an integer in [1, 65536], got 'abc'

Nothing here knows the scene format; `clrays.scene.load` does.
"""
from __future__ import annotations

import difflib
import math
import re
from dataclasses import dataclass, field
from typing import Any, Callable, NoReturn, Sequence

import numpy as np
import yaml

from ..errors import SceneError


class _Loader(yaml.SafeLoader):
    """SafeLoader that also reads YAML 1.2 floats without a dot (1e3, -2E-4) as floats."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?[0-9][0-9_]*[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


@dataclass(eq=False)
class Node:
    """One value of the tree and where it was written.

    value is a dict[str, Node] (mapping), a list[Node] (sequence) or a plain scalar
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
        return join(self.path, key)

    def fail(self, expected: str, got: str | None = None) -> NoReturn:
        raise SceneError(f"{self.where}: {self.label}: expected {expected}, "
                         f"got {show(self) if got is None else got}")


def show(node: Node | Any, limit: int = 60) -> str:
    """A short, YAML-like rendering of a value for messages; strings are quoted."""

    def render(v: Any) -> str:
        if isinstance(v, Node):
            v = v.value
        if isinstance(v, dict):
            return "{" + ", ".join(f"{k}: {render(x)}" for k, x in v.items()) + "}"
        if isinstance(v, list):
            return "[" + ", ".join(render(x) for x in v) + "]"
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

    text = render(node)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def join(path: str, key: str | int) -> str:
    return f"{path}.{key}" if path else str(key)


def mark_where(filename: str) -> Callable[[yaml.Mark], str]:
    return lambda mark: f"{filename}:{mark.line + 1}:{mark.column + 1}"


class _Converter:
    """Wraps a composed YAML tree in `Node`s: scalars constructed by the safe loader,
    mapping keys checked (strings, no duplicates), `<<: *anchor` merge keys resolved."""

    def __init__(self, loader: yaml.SafeLoader, where: Callable[[yaml.Mark], str]):
        self.loader = loader
        self.where = where
        self.merged: set[int] = set()  # mappings already flattened (an alias repeats them)

    def convert(self, node: yaml.Node, path: str, active: frozenset[int] = frozenset()) -> Node:
        here = self.where(node.start_mark)
        if id(node) in active:  # an alias inside its own anchor
            raise SceneError(f"{here}: {path or '(top level)'}: expected a finite tree, got a recursive alias")
        active = active | {id(node)}
        if isinstance(node, yaml.SequenceNode):
            return Node([self.convert(n, join(path, i), active) for i, n in enumerate(node.value)], here, path)
        if isinstance(node, yaml.MappingNode):
            self.flatten(node, path)
            items, key_where = {}, {}
            for key_node, value_node in node.value:  # later keys win over merged ones
                key = self.key(key_node, path)
                items[key] = self.convert(value_node, join(path, key), active)
                key_where[key] = self.where(key_node.start_mark)
            return Node(items, here, path, key_where)
        return Node(self.construct(node, path), here, path)

    def construct(self, node: yaml.Node, path: str) -> Any:
        try:
            return self.loader.construct_object(node)
        except yaml.MarkedYAMLError as exc:  # an unknown tag, a malformed !!binary, ...
            raise _yaml_error(exc, self.where, path=path) from None

    def key(self, node: yaml.Node, path: str) -> str:
        key = self.construct(node, path) if isinstance(node, yaml.ScalarNode) else None
        if not isinstance(key, str):
            raise SceneError(f"{self.where(node.start_mark)}: {path or '(top level)'}: "
                             f"expected a string key, got {show(key) if key is not None else 'a ' + node.id}")
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
                raise SceneError(f"{self.where(key_node.start_mark)}: {join(path, key)}: expected each "
                                 f"key once, got a duplicate (first at line {first[key].line + 1})")
            first[key] = key_node.start_mark
        try:
            self.loader.flatten_mapping(node)
        except yaml.MarkedYAMLError as exc:
            raise _yaml_error(exc, self.where, path=path) from None
        self.merged.add(id(node))


def _yaml_error(exc: yaml.YAMLError, where: Callable[[yaml.Mark], str], fallback: str = "",
                path: str = "") -> SceneError:
    """A yaml exception as one line at its problem mark (or `fallback` when it has none)."""
    problem = " ".join(str(getattr(exc, "problem", None) or exc).split())
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    prefix = where(mark) if mark is not None else fallback
    return SceneError(f"{prefix}: {path + ': ' if path else ''}malformed YAML: {problem}")


def compose(text: str, path: str, where: Callable[[yaml.Mark], str], fallback: str) -> Node | None:
    """Compose one YAML document into a `Node` tree (None for an empty document)."""
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


def apply_override(root: Node, text: str) -> None:
    """Splice one `key.path=value` override into the tree (creating missing mappings)."""
    where = f"--set {text}"
    key, sep, value_text = text.partition("=")
    key = key.strip()
    parts = key.split(".")
    if not sep or not key or any(not p.strip() for p in parts):
        raise SceneError(f"{where}: expected key.path=value, got {text!r}")
    parts = [p.strip() for p in parts]
    value = compose(value_text, key, lambda _mark: where, where)
    if value is None:  # `key=` sets null, which the schema then rejects or accepts
        value = Node(None, where, key)

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
                    node.value[part] = Node({}, where, path)
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
                             f"{'.'.join(parts[depth:])} in, got {show(node)}")


# --------------------------------------------------------------------------- readers


def mapping(node: Node, required: Sequence[str] = (), optional: Sequence[str] = ()) -> dict[str, Node]:
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


def typed(node: Node, kinds: dict[str, tuple[tuple[str, ...], tuple[str, ...]]],
          common: tuple[str, ...] = ()) -> tuple[str, dict[str, Node]]:
    """A mapping whose `type` names one of `kinds` (type -> (required keys, optional keys));
    returns (type, mapping) with the keys checked against that type (plus `common`)."""
    if not isinstance(node.value, dict) or "type" not in node.value:
        everything = [k for req, opt in kinds.values() for k in req + opt] + list(common)
        mapping(node, required=("type",), optional=everything)
    kind = choice(node.value["type"], tuple(kinds))
    required, optional = kinds[kind]
    return kind, mapping(node, required=("type",) + required, optional=optional + common)


def sequence(node: Node, what: str, min_len: int = 0) -> list[Node]:
    if not isinstance(node.value, list) or len(node.value) < min_len:
        node.fail(what)
    return node.value


def range_text(kind: str, lo, hi, lo_open: bool = False, hi_open: bool = False) -> str:
    if lo is not None and hi is not None:
        return f"{kind} in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{kind} {'>' if lo_open else '>='} {lo:g}"
    if hi is not None:
        return f"{kind} {'<' if hi_open else '<='} {hi:g}"
    return kind


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def number(node: Node | None, lo: float | None = None, hi: float | None = None, *,
           lo_open: bool = False, hi_open: bool = False, default: float | None = None) -> float:
    """A finite number (int or float, never bool) in the given range."""
    if node is None:
        assert default is not None
        return float(default)
    v = node.value
    what = range_text("a number", lo, hi, lo_open, hi_open)
    if not _is_number(v):
        node.fail(what)
    finite = math.isfinite(v) if isinstance(v, float) else abs(v) <= 1e308  # huge ints overflow
    if not finite:
        node.fail(what.replace("a number", "a finite number", 1))
    if ((lo is not None and (v <= lo if lo_open else v < lo))
            or (hi is not None and (v >= hi if hi_open else v > hi))):
        node.fail(what)
    return float(v)


def integer(node: Node | None, lo: int | None = None, hi: int | None = None, *,
            default: int | None = None) -> int:
    """An integer (not a bool, not a float) in [lo, hi]."""
    if node is None:
        assert default is not None
        return int(default)
    v = node.value
    if (not isinstance(v, int) or isinstance(v, bool) or (lo is not None and v < lo)
            or (hi is not None and v > hi)):
        node.fail(range_text("an integer", lo, hi))
    return int(v)


def boolean(node: Node | None, default: bool) -> bool:
    if node is None:
        return default
    if not isinstance(node.value, bool):
        node.fail("true or false")
    return node.value


def choice(node: Node | None, options: Sequence[str], default: str | None = None) -> str:
    if node is None:
        assert default is not None
        return default
    if node.value not in options or not isinstance(node.value, str):
        node.fail("one of " + ", ".join(repr(o) for o in options))
    return node.value


def numbers(node: Node, n: int, what: str, lo: float | None = None, hi: float | None = None,
            **kw) -> np.ndarray:
    """A list of exactly n numbers; each element is checked (and reported) on its own."""
    if not isinstance(node.value, list) or len(node.value) != n:
        node.fail(what)
    return np.array([number(x, lo, hi, **kw) for x in node.value], dtype=np.float64)


def vec3(node: Node) -> np.ndarray:
    return numbers(node, 3, "a list of 3 numbers [x, y, z]")


def direction(node: Node) -> np.ndarray:
    """A non-zero 3-vector, normalised."""
    v = vec3(node)
    norm = float(np.linalg.norm(v))
    if norm == 0.0 or not math.isfinite(norm):
        node.fail("a non-zero direction [x, y, z]")
    return v / norm


def rgb(node: Node | None, lo: float = 0.0, hi: float | None = None, *,
        default: float | None = None) -> np.ndarray:
    """A colour: a number (broadcast to RGB) or a list of 3 numbers, each in [lo, hi]."""
    if node is None:
        assert default is not None
        return np.full(3, float(default))
    if isinstance(node.value, list):
        what = f"a list of 3 numbers (RGB) or a single {range_text('number', lo, hi)}"
        return numbers(node, 3, what, lo, hi)
    return np.full(3, number(node, lo, hi))
