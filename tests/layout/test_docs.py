"""The front door and the reference stay true: the README is short, starts with the two
commands and names files, make targets and commands that exist; docs/cli.md's help blocks
are the ones tools/cli_doc.py writes from the click commands; relative links lead somewhere."""
from __future__ import annotations

import importlib.util
import re
import shlex
import subprocess
import sys
from pathlib import Path

import click
import pytest

from clrays import cli
from clrays.scene import gltf as gltf_files

REPO = Path(__file__).resolve().parents[2]
README = REPO / "README.md"
TOOL = REPO / "tools" / "cli_doc.py"
CLI_DOC = REPO / "docs" / "cli.md"
#: Where the README sends a newcomer first: their anchors are checked as well as their files.
FRONT_DOCS = [README, *(REPO / "docs" / name for name in ("cli.md", "devices.md", "methods.md", "layout.md",
                                                          "dependencies.md"))]


def tool():
    spec = importlib.util.spec_from_file_location("cli_doc", TOOL)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _prose(text: str) -> str:
    """The text without its fenced code blocks (a `#` in a shell comment is no heading)."""
    return re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)


def _code_blocks(text: str, language: str) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)^```", text, flags=re.S | re.M)


# --------------------------------------------------------------------------- the CLI reference


def test_cli_doc_is_current():
    result = subprocess.run([sys.executable, str(TOOL), "--check"], capture_output=True, text=True, cwd=REPO)
    assert result.returncode == 0, result.stderr


def test_cli_doc_check_fails_on_a_stale_missing_or_unknown_block(tmp_path):
    text = CLI_DOC.read_text(encoding="utf-8")
    line = "  render          Render SCENE (a YAML file, or glTF: .glb, .gltf) to an image."
    assert line in text
    stale = tmp_path / "stale.md"
    stale.write_text(text.replace(line, line.replace("an image", "a picture")), encoding="utf-8")
    assert tool().main(["--check", "--doc", str(stale)]) == 1
    assert stale.read_text(encoding="utf-8") != text  # --check reports, it does not rewrite
    assert tool().main(["--doc", str(stale)]) == 0 and stale.read_text(encoding="utf-8") == text
    with pytest.raises(ValueError, match=r"help:rendr -->: no such command; expected one of clrays, render, "):
        tool().generate(text.replace("<!-- help:render -->", "<!-- help:rendr -->"))
    block = re.search(r"<!-- help:info -->\n.*?<!-- /help -->\n", text, re.S)[0]
    with pytest.raises(ValueError, match=r"commands without a help block in the document: info$"):
        tool().generate(text.replace(block, ""))


def test_cli_doc_does_not_depend_on_the_terminal(monkeypatch):
    monkeypatch.setenv("COLUMNS", "40")
    assert max(len(line) for line in tool().help_text("render").splitlines()) > 40


# --------------------------------------------------------------------------- the README


def test_readme_is_a_front_door():
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 200
    # The two commands a newcomer needs come first, before any section.
    first_block = _code_blocks(text, "sh")[0]
    assert text.index(first_block) < text.index("\n## ")
    assert [line.split("#")[0].strip() for line in first_block.splitlines()] == ["make demo", "make test"]
    for doc in ("docs/cli.md", "docs/scene-format.md", "docs/design.md", "bench/RESULTS.md", "docs/limits.md"):
        assert f"]({doc})" in text, doc


def test_readme_names_the_papers_four_kernels():
    text = README.read_text(encoding="utf-8")
    table = text[text.index("| the paper's step |"):]
    rows = table[:table.index("\n\n")].splitlines()[2:]
    assert len(rows) == 4
    for row, stage in zip(rows, ("raster", "rectify", "minmax", "sampling")):
        assert f"`cl/{stage}.cl`" in row and f"`clrays/stages/{stage}.py`" in row, row


def test_every_path_the_readme_names_exists():
    text = README.read_text(encoding="utf-8")
    paths = set(re.findall(r"`((?:cl|clrays|scenes|docs|tools|bench|tests)/[\w./*-]+)`", text))
    paths |= {f"scenes/{name}" for name in re.findall(r"^\| `(\w+\.(?:yaml|glb))`", text, re.M)}
    assert len(paths) >= 15
    for path in sorted(paths):
        assert list(REPO.glob(path)), f"README names {path}, which does not exist"


def test_every_make_target_the_readme_names_exists():
    targets = set(re.findall(r"^([\w-]+):", (REPO / "Makefile").read_text(), re.M))
    named = set(re.findall(r"`make ([\w-]+)", README.read_text(encoding="utf-8")))
    assert {"demo", "test"} <= named and named <= targets, named - targets


def _command_lines(text: str) -> list[list[str]]:
    """The arguments after `clrays` of every command in the text's shell blocks."""
    commands = []
    for block in _code_blocks(text, "sh"):
        for line in block.replace("\\\n", " ").splitlines():
            words = shlex.split(line, comments=True)
            while words and words[0] != ".venv/bin/clrays" and words[0] != "clrays":
                words.pop(0)  # `make intel-cpu && ...`, `CLRAYS_DEVICE=0:0 ...`
            if words:
                commands.append(words[1:])
    return commands


@pytest.mark.parametrize("doc", [README, CLI_DOC], ids=lambda path: path.name)
def test_every_command_in_the_docs_parses(doc):
    # Options renamed or removed, or a value a choice no longer holds, fail here.
    commands = _command_lines(doc.read_text(encoding="utf-8"))
    assert len(commands) >= 5
    group = click.Context(cli.main, info_name="clrays")
    try:
        for words in commands:
            name = words[0]
            assert name in cli.main.commands, f"{doc.name}: no command {name}: clrays {shlex.join(words)}"
            try:
                with cli.main.commands[name].make_context(name, words[1:], parent=group):
                    pass
            except click.UsageError as exc:
                pytest.fail(f"{doc.name}: clrays {shlex.join(words)}: {exc.format_message()}")
    finally:
        gltf_files.verbose_notice = None  # --verbose's callback sets it


# --------------------------------------------------------------------------- links


def _slug(heading: str) -> str:
    """A markdown heading's anchor as GitHub makes it."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _links(doc: Path) -> list[tuple[Path, str]]:
    """(file, anchor) of every relative link of the document."""
    found = []
    for target in re.findall(r"\]\(([^)\s]+)\)", _prose(doc.read_text(encoding="utf-8"))):
        if not re.match(r"[a-z]+:", target):
            file, _, anchor = target.partition("#")
            found.append(((doc.parent / file).resolve() if file else doc, anchor))
    return found


@pytest.mark.parametrize("doc", [README, *sorted((REPO / "docs").glob("*.md"))], ids=lambda path: path.name)
def test_relative_links_lead_to_files(doc):
    for path, _ in _links(doc):
        assert path.exists(), f"{doc.name} links to {path.relative_to(REPO)}, which does not exist"


@pytest.mark.parametrize("doc", FRONT_DOCS, ids=lambda path: path.name)
def test_links_from_the_front_door_lead_to_headings(doc):
    for path, anchor in _links(doc):
        if anchor and path.suffix == ".md":
            headings = {_slug(h) for h in re.findall(r"^#+ (.*)$", _prose(path.read_text(encoding="utf-8")), re.M)}
            assert anchor in headings, f"{doc.name} links to {path.name}#{anchor}, no such heading"
