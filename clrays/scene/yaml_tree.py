"""YAML with positions: a composed document as a tree of `Node`s that remember where
each value was written, `--set key.path=value` overrides spliced into it, and typed
readers that turn nodes into numbers, vectors and choices or fail in one line:

    scenes/x.yaml:14:9: lights.0.cone_deg: expected a number in (0, 90], got 120
    --set render.steps=abc: render.steps: expected an integer in [1, 65536], got 'abc'

Nothing here knows the scene format; `clrays.scene.load` does.
"""
from __future__ import annotations

import difflib
import gc
import math
import re
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, NoReturn, Sequence

import numpy as np
import yaml
import yaml.cyaml

from ..errors import SceneError
from .limits import MAX_ALIAS_NODES, MAX_NESTING, MAX_NUMBER_DIGITS


_INT_TAG, _FLOAT_TAG = "tag:yaml.org,2002:int", "tag:yaml.org,2002:float"
_MERGE_TAG = "tag:yaml.org,2002:merge"

if yaml.__with_libyaml__:
    class _Loader(yaml.cyaml.CParser, yaml.constructor.SafeConstructor, yaml.resolver.Resolver):
        """The safe loader on libyaml's parser and composer (the parser alone is about 20
        times faster than PyYAML's, with the same line and column), reading numbers as YAML
        1.2's core schema does (`_CORE_INT`, `_CORE_FLOAT`)."""

        def __init__(self, text: str):
            yaml.cyaml.CParser.__init__(self, text)
            yaml.constructor.SafeConstructor.__init__(self)
            yaml.resolver.Resolver.__init__(self)
else:  # pragma: no cover - PyYAML built without libyaml
    class _Loader(yaml.SafeLoader):
        """The safe loader, reading numbers as YAML 1.2's core schema does."""


# The one number grammar of scene files and `--set`: YAML 1.2's core schema (YAML 1.2.2 §10.3.2).
# PyYAML resolves YAML 1.1's, whose floats need a dot and a signed exponent (`1.5e2` and `1e3`
# were text), and which reads `1_000`, `0b1`, `010` (octal 8) and the base-60 `1:30` (90) as
# numbers. Here those are text (then refused where a number belongs), `010` is ten and `0o10`
# eight. Other tags (bool, null, ...) resolve as PyYAML does.
_CORE_INT = re.compile(r"[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+")
_CORE_FLOAT = re.compile(r"[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?"
                         r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN)")


def core_int(text: str) -> int:
    """A YAML 1.2 core-schema integer: decimal with a sign or none, `0o` octal or `0x` hex."""
    if not _CORE_INT.fullmatch(text):
        raise ValueError("not a YAML 1.2 integer")
    base = {"0o": 8, "0x": 16}.get(text[:2], 10)
    return int(text if base == 10 else text[2:], base)


def core_float(text: str) -> float:
    """A YAML 1.2 core-schema float (`.5`, `1.`, `1.5e2`, `6.02e+23`, `-.inf`, `.nan`; every
    integer too, as `!!float 3`)."""
    if not _CORE_FLOAT.fullmatch(text):
        raise ValueError("not a YAML 1.2 float")
    special = text.lower().replace(".", "", 1) if text.lower().lstrip("+-") in (".inf", ".nan") else text
    return float(special)


_Loader.yaml_implicit_resolvers = {  # a copy without YAML 1.1's number resolvers (PyYAML's own stay as they are)
    first: [(tag, regexp) for tag, regexp in resolvers if tag not in (_INT_TAG, _FLOAT_TAG)]
    for first, resolvers in yaml.resolver.Resolver.yaml_implicit_resolvers.items()}
# int before float: every integer also matches the float pattern.
_Loader.add_implicit_resolver(_INT_TAG, re.compile(rf"(?:{_CORE_INT.pattern})\Z"), list("-+0123456789"))
_Loader.add_implicit_resolver(_FLOAT_TAG, re.compile(rf"(?:{_CORE_FLOAT.pattern})\Z"), list("-+.0123456789"))
_Loader.add_constructor(_INT_TAG, lambda loader, node: core_int(loader.construct_scalar(node)))
_Loader.add_constructor(_FLOAT_TAG, lambda loader, node: core_float(loader.construct_scalar(node)))


@dataclass(eq=False)
class Node:
    """One value of the tree and where it was written.

    value is a dict[str, Node] (mapping), a list[Node] (sequence) or a plain scalar
    (int, float, str, bool, None, ...). where is "file:line:col" or "--set key=value"
    (`apply_override`);
    path is the dotted key path ("lights.0.cone_deg", "" for the top level).
    """

    value: Any
    where: str | Place
    path: str
    key_where: dict[str, str | Place] = field(default_factory=dict)  # mapping: where each key is

    @property
    def label(self) -> str:
        return self.path or "(top level)"

    def child_path(self, key: str | int) -> str:
        return join(self.path, key)

    def fail(self, expected: str, got: str | None = None) -> NoReturn:
        got = show(self) + _hint(self.value, expected) if got is None else got
        raise SceneError(f"{self.where}: {self.label}: expected {expected}, got {got}")


_COMMA_NUMBERS = re.compile(r"\s*[-+.0-9eE]+(?:\s*,\s*[-+.0-9eE]+)+\s*")


def _hint(value: Any, expected: str) -> str:
    """What a text written where a list or a number belongs was meant as, as the tail of a
    message: `260,230,190` is a list without its brackets; `1_000` a number only in YAML 1.1."""
    if not isinstance(value, str):
        return ""
    if "list" in expected and _COMMA_NUMBERS.fullmatch(value):
        return f" (a list is written in brackets: [{', '.join(part.strip() for part in value.split(','))}])"
    # PyYAML's own resolver reads YAML 1.1: a number there is one this loader left as text
    if ("number" in expected or "integer" in expected) and \
            yaml.resolver.Resolver().resolve(yaml.ScalarNode, value, (True, False)) in (_INT_TAG, _FLOAT_TAG):
        return " (a number in YAML 1.1 only: clrays reads YAML 1.2's, without `_`, `0b` or base 60)"
    return ""


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


class Place:
    """Where a value was written, shown as "file:line:col"; kept as the parser's mark and
    written out only when a message shows it (most values never are)."""

    __slots__ = ("filename", "mark")

    def __init__(self, filename: str, mark: yaml.Mark):
        self.filename, self.mark = filename, mark

    def __str__(self) -> str:
        return f"{self.filename}:{self.mark.line + 1}:{self.mark.column + 1}"

    def __format__(self, spec: str) -> str:  # f-strings format, not str()
        return format(str(self), spec)


def mark_where(filename: str) -> Callable[[yaml.Mark], Place]:
    return lambda mark: Place(filename, mark)


class _Converter:
    """Wraps a composed YAML tree in `Node`s: scalars constructed by the safe loader,
    mapping keys checked (strings, no duplicates), `<<: *anchor` merge keys resolved.

    An alias makes a fresh copy of what it names, so the copies are counted against
    `MAX_ALIAS_NODES`, and the depth of the tree they build against `MAX_NESTING`."""

    def __init__(self, loader: yaml.SafeLoader, where: Callable[[yaml.Mark], str | Place]):
        self.loader = loader
        self.where = where
        self.seen: set[int] = set()  # YAML nodes converted once; another visit is an alias's copy
        self.copies = 0
        self.active: set[int] = set()  # YAML nodes on the way down to the current one

    def convert(self, node: yaml.Node, path: str, depth: int = 0) -> Node:
        if id(node) in self.seen:
            self.copies += 1
            if self.copies > MAX_ALIAS_NODES:
                raise SceneError(f"{self.where(node.start_mark)}: {path or '(top level)'}: expected aliases that "
                                 f"copy at most {MAX_ALIAS_NODES} values in all, got more (an alias bomb?)")
        else:
            self.seen.add(id(node))
        if isinstance(node, yaml.ScalarNode):
            return Node(self.construct(node, path), self.where(node.start_mark), path)
        if id(node) in self.active:  # an alias inside its own anchor
            raise SceneError(f"{self.where(node.start_mark)}: {path or '(top level)'}: "
                             f"expected a finite tree, got a recursive alias")
        if depth >= MAX_NESTING:  # aliases of aliases nest deeper than the text does
            raise SceneError(f"{self.where(node.start_mark)}: {path or '(top level)'}: expected at most "
                             f"{MAX_NESTING} levels of nesting, got more through aliases")
        self.active.add(id(node))
        try:
            if isinstance(node, yaml.SequenceNode):
                return Node([self.convert(n, join(path, i), depth + 1) for i, n in enumerate(node.value)],
                            self.where(node.start_mark), path)
            return self.mapping(node, path, depth)
        finally:
            self.active.discard(id(node))

    def mapping(self, node: yaml.MappingNode, path: str, depth: int) -> Node:
        """A mapping: merged (`<<`) keys first, in YAML's order of precedence (explicit keys
        win, then the first of a merged list), then the mapping's own keys, each once."""
        items: dict[str, Node] = {}
        key_where: dict[str, str | Place] = {}
        own = []
        for key_node, value_node in node.value:
            if key_node.tag == _MERGE_TAG:
                for merged in self.merged(value_node, path, depth):
                    items.update(merged.value)
                    key_where.update(merged.key_where)
            else:
                own.append((self.key(key_node, path), key_node, value_node))
        first: dict[str, yaml.Mark] = {}
        for key, key_node, value_node in own:
            if key in first:
                raise SceneError(f"{self.where(key_node.start_mark)}: {join(path, key)}: expected each "
                                 f"key once, got a duplicate (first at line {first[key].line + 1})")
            first[key] = key_node.start_mark
            items[key] = self.convert(value_node, join(path, key), depth + 1)
            key_where[key] = self.where(key_node.start_mark)
        return Node(items, self.where(node.start_mark), path, key_where)

    def merged(self, node: yaml.Node, path: str, depth: int) -> list[Node]:
        """The mappings a `<<` key merges, lowest precedence first."""
        parts = node.value if isinstance(node, yaml.SequenceNode) else [node]
        converted = []
        for part in reversed(parts):  # in `<<: [*a, *b]`, a's keys win over b's
            if not isinstance(part, yaml.MappingNode):
                raise SceneError(f"{self.where(part.start_mark)}: {path or '(top level)'}: expected a mapping "
                                 f"or a list of mappings to merge with <<, got a {part.id}")
            converted.append(self.convert(part, path, depth))
        return converted

    def construct(self, node: yaml.ScalarNode, path: str) -> Any:
        if node.tag in (_INT_TAG, _FLOAT_TAG):
            self.check_number(node, path)
        try:
            return self.loader.construct_object(node)
        except yaml.MarkedYAMLError as exc:  # an unknown tag, a malformed !!binary, ...
            raise _yaml_error(exc, self.where, path=path) from None
        except (ValueError, TypeError, OverflowError) as exc:  # `!!int abc`, `!!float x`
            raise SceneError(f"{self.where(node.start_mark)}: {path or '(top level)'}: expected a value "
                             f"that {node.tag.rsplit(':', 1)[-1]} can read, got {node.value[:40]!r} ({exc})") from None

    def check_number(self, node: yaml.ScalarNode, path: str) -> None:
        """Refuse before converting: a base-60 number written with an explicit tag (`!!int 1:30`)
        and numbers too long to read safely."""
        text = node.value
        if ":" in text:
            raise SceneError(f"{self.where(node.start_mark)}: {path or '(top level)'}: expected a number, "
                             f"got {text[:40]!r} (YAML 1.1 base-60 numbers are not read)")
        digits = len(text) if len(text) <= MAX_NUMBER_DIGITS else sum(c.isalnum() for c in text)
        if digits > MAX_NUMBER_DIGITS:
            raise SceneError(f"{self.where(node.start_mark)}: {path or '(top level)'}: expected a number of at "
                             f"most {MAX_NUMBER_DIGITS} digits, got one of {digits}")

    def key(self, node: yaml.Node, path: str) -> str:
        key = self.construct(node, path) if isinstance(node, yaml.ScalarNode) else None
        if not isinstance(key, str):
            raise SceneError(f"{self.where(node.start_mark)}: {path or '(top level)'}: "
                             f"expected a string key, got {show(key) if key is not None else 'a ' + node.id}")
        return key


def _yaml_error(exc: yaml.YAMLError, where: Callable[[yaml.Mark], str | Place], fallback: str = "",
                path: str = "", text: str = "") -> SceneError:
    """A yaml exception as one line at its problem mark (or `fallback` when it has none),
    naming what libyaml's messages leave out: the tab, the alias."""
    problem = " ".join(str(getattr(exc, "problem", None) or exc).split())
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    at = text[mark.index:mark.index + 100] if mark is not None else ""
    alias = re.match(r"\*([^\s,\[\]{}]+)", at)
    if problem == "found undefined alias" and alias:
        problem += f" {alias.group(1)!r}"
    elif problem.startswith("found character") and at.startswith("\t"):
        problem += " (a tab: indent with spaces)"
    prefix = where(mark) if mark is not None else fallback
    return SceneError(f"{prefix}: {path + ': ' if path else ''}malformed YAML: {problem}")


def _check_nesting(text: str) -> None:
    """Walk the parser's events (flat, no recursion) and stop at the first mapping or list
    nested deeper than `MAX_NESTING`."""
    events = _Loader(text)
    depth, last = 0, None
    try:
        while not events.check_event(yaml.StreamEndEvent):
            event = events.get_event()
            last = event.end_mark
            if isinstance(event, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
                depth += 1
                if depth > MAX_NESTING:
                    raise _TooDeep(event.start_mark)
            elif isinstance(event, (yaml.SequenceEndEvent, yaml.MappingEndEvent)):
                depth -= 1
    except yaml.YAMLError as exc:
        too_deep = _first_too_deep_bracket(text, last, depth) if "nesting depth" in str(exc) else None
        if too_deep is None:
            raise
        raise _TooDeep(too_deep) from None
    finally:
        events.dispose()


class _TooDeep(Exception):
    def __init__(self, mark: yaml.Mark):
        self.mark = mark


def _first_too_deep_bracket(text: str, start: yaml.Mark | None, depth: int) -> yaml.Mark | None:
    """Where flow brackets ([ and {, outside quotes and comments) from `start` (None: the
    text's start), `depth` levels in already, first nest deeper than MAX_NESTING, or None.
    PyYAML from 6.0.3 refuses a flow nesting of 1000 in its scanner, which reads far ahead of
    the parser, so such a scene never gets its events to `_check_nesting`; this finds the
    place that check would have named."""
    index, line, column = (start.index, start.line, start.column) if start is not None else (0, 0, 0)
    quote = ""
    while index < len(text):
        c = text[index]
        if quote:
            if c == "\\" and quote == '"':
                index, column = index + 1, column + 1
            elif c == quote:
                quote = ""
        elif c in "'\"":
            quote = c
        elif c == "#" and (index == 0 or text[index - 1] in " \t\n"):
            while index + 1 < len(text) and text[index + 1] != "\n":
                index += 1
        elif c in "[{":
            depth += 1
            if depth > MAX_NESTING:
                return yaml.Mark("<scene>", index, line, column, None, None)
        elif c in "]}":
            depth = max(depth - 1, 0)
        if c == "\n":
            line, column = line + 1, 0
        else:
            column += 1
        index += 1
    return None


def compose(text: str, path: str, where: Callable[[yaml.Mark], str | Place], fallback: str) -> Node | None:
    """Compose one YAML document into a `Node` tree (None for an empty document)."""
    loader = _Loader(text)
    collecting = gc.isenabled()
    gc.disable()  # the tree holds no cycles; collecting while it grows doubles the time
    try:
        try:
            _check_nesting(text)
            root = loader.get_single_node()
        except yaml.YAMLError as exc:
            raise _yaml_error(exc, where, fallback, path, text) from None
        except _TooDeep as exc:
            raise SceneError(f"{where(exc.mark)}: {path or '(top level)'}: expected at most {MAX_NESTING} "
                             f"levels of nesting, got more") from None
        return None if root is None else _Converter(loader, where).convert(root, path)
    finally:
        loader.dispose()
        if collecting:
            gc.enable()


# --------------------------------------------------------------------------- overrides


#: What messages call a plain `key.path=value` override: the Python API's `overrides=` by
#: default; the command line sets "--set".
override_origin = "override"


class Override(str):
    """A `key.path=value` override that names what the user wrote to give it (`given`, such
    as `--aov depth`), for messages to show instead of the override they never typed."""

    def __new__(cls, text: str, given: str):
        override = super().__new__(cls, text)
        override.given = given
        return override

    def __reduce__(self):  # pickled (to a worker process) with what it names
        return Override, (str(self), self.given)


def apply_override(root: Node, text: str) -> None:
    """Splice one `key.path=value` override into the tree, creating missing mappings, and a
    missing list where the next key is an index. An index equal to a list's length appends."""
    given = text.given if isinstance(text, Override) else f"{override_origin} {text}"
    where = given if len(given) <= 90 else given[:87] + "..."  # a message shows a value, not all of it
    key, sep, value_text = text.partition("=")
    key = key.strip()
    parts = key.split(".")
    if not sep or not key or any(not p.strip() for p in parts):
        raise SceneError(f"{where}: expected key.path=value, got {show(text)}")
    if len(parts) > MAX_NESTING:
        raise SceneError(f"{where}: expected a key path of at most {MAX_NESTING} keys, got {len(parts)}")
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
                if part not in node.value:  # a list where the next key is an index: `lights.0={...}` starts one
                    node.value[part] = Node([] if parts[depth + 1].isdecimal() else {}, where, path)
                    node.key_where[part] = where
                node = node.value[part]
        elif isinstance(node.value, list):
            n = len(node.value)
            if not part.isdecimal() or int(part) > n or (int(part) == n and not last):
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
    if isinstance(node.value, str) and node.value in kinds:  # `phase: hg` for `phase: {type: hg, g: 0.5}`
        written = ", ".join([f"type: {node.value}"] + [f"{key}: ..." for key in kinds[node.value][0]])
        node.fail("a mapping", f"{show(node)} (write {{{written}}})")
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


def choice(node: Node | None, options: Sequence[str], default: str | None = None,
           renamed: Mapping[str, str] | None = None) -> str:
    """One of `options`; a name in `renamed` (an option's former name) reads as the option."""
    if node is None:
        assert default is not None
        return default
    if isinstance(node.value, str) and renamed and node.value in renamed:
        return renamed[node.value]
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
    what = f"a list of 3 numbers (RGB) or a single {range_text('number', lo, hi)}"
    if isinstance(node.value, list):
        return numbers(node, 3, what, lo, hi)
    if isinstance(node.value, str) and _COMMA_NUMBERS.fullmatch(node.value):  # `260,230,190`: brackets left out
        node.fail(what)
    return np.full(3, number(node, lo, hi))
