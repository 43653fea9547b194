"""The layers of clrays, as its imports make them (clrays/physics/__init__.py):
scene ← physics ← {stages, reference}, no cycle anywhere, and the float64 reference that
every test trusts kept apart from what a frame runs.

Every import counts, those inside functions too; only `if TYPE_CHECKING:` blocks, which
never run, are left out, but where a test says otherwise: no two modules import each other,
even for an annotation (the frame's inputs hold data, and the stages read them).
"""
from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "clrays"


def _modules() -> dict[str, Path]:
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return modules


def _imports(name: str, path: Path, modules: dict[str, Path], annotations: bool = False) -> set[str]:
    """The clrays modules that module `name` imports (a name imported from a package counts
    as its module where it is one, else as the package); `annotations`: those of its
    `if TYPE_CHECKING:` blocks too."""
    tree = ast.parse(path.read_text())
    unused = set() if annotations else {
        id(node) for block in ast.walk(tree) if isinstance(block, ast.If) and "TYPE_CHECKING" in ast.unparse(block.test)
        for statement in block.body for node in ast.walk(statement)}
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if id(node) in unused:
            continue
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([node.module] if node.module else []))
            found.update(f"{base}.{alias.name}" if f"{base}.{alias.name}" in modules else base for alias in node.names)
    return {module for module in found if module in modules and module != name}


def _graph(annotations: bool = False) -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, path, modules, annotations) for name, path in modules.items()}


def _mutual(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    """The pairs of modules that import each other."""
    return sorted((module, other) for module, imported in graph.items() for other in imported
                  if module < other and module in graph.get(other, ()))


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(module: str) -> None:
        index[module] = low[module] = len(index)
        stack.append(module)
        on_stack.add(module)
        for other in sorted(graph[module]):
            if other not in index:
                visit(other)
                low[module] = min(low[module], low[other])
            elif other in on_stack:
                low[module] = min(low[module], index[other])
        if low[module] == index[module]:
            component = []
            while True:
                other = stack.pop()
                on_stack.discard(other)
                component.append(other)
                if other == module:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return found


def test_no_import_cycle():
    assert _cycles(_graph()) == []


def test_the_cycle_finder_finds_one():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_module_imports_one_that_imports_it():
    # Annotations included: a module that names another's types only under TYPE_CHECKING
    # still leans on it, and the imports run one way (scene ← physics ← inputs ← stages).
    graph = _graph(annotations=True)
    assert _mutual(graph) == []
    assert sorted(other for other in graph["clrays.inputs"] if other.startswith("clrays.stages")) == []


def test_the_mutual_finder_finds_a_pair_and_reads_annotations():
    assert _mutual({"a": {"b"}, "b": {"a", "c"}, "c": set(), "d": {"a"}}) == [("a", "b")]
    # (stages.light_texture names rectify's Epipolar for its annotations alone)
    assert "clrays.stages.rectify" in _graph(annotations=True)["clrays.stages.light_texture"]
    assert "clrays.stages.rectify" not in _graph()["clrays.stages.light_texture"]


def test_what_a_frame_runs_imports_no_reference():
    # The session dispatches the `exact` method itself; commands (cli, runs) compare with it.
    apart = ("clrays.stages", "clrays.scene", "clrays.physics", "clrays.inputs", "clrays.bvh", "clrays.device",
             "clrays.reuse", "clrays.structs")
    leaning = {module: sorted(other for other in imported if other.startswith("clrays.reference"))
               for module, imported in _graph().items() if module.startswith(apart)}
    assert {module: others for module, others in leaning.items() if others} == {}
    assert {other for other in _graph()["clrays.session"] if other.startswith("clrays.reference")} == {
        "clrays.reference.exact"}


def test_physics_stands_on_the_scene_alone():
    graph = _graph()
    physics = {module for module in graph if module.startswith("clrays.physics")}
    below = {other for module in physics for other in graph[module]} - physics
    assert all(other.startswith(("clrays.scene", "clrays.structs")) for other in below), sorted(below)
