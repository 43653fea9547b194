"""Citations into the docs resolve: every "docs/design.md §N[.M]" that code, tests, tools,
the bench or the docs cite names a numbered heading of docs/design.md, every
"docs/<file>.md" they name exists, and every link between the docs (a file, and an anchor
in it) lands on a file and a heading that exist. Code cites design.md's sections by number,
so a section renumbered or dropped fails here rather than leaving comments that point
nowhere."""
from __future__ import annotations

import re
from functools import lru_cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
#: What is searched for citations: the package, kernels, tests, tools, bench and docs, and
#: the top-level text files.
SEARCHED = ("clrays", "cl", "tests", "tools", "bench", "docs", "scenes")
TOP_LEVEL = ("README.md", "CHANGELOG.md", "pyproject.toml", "Makefile")
TEXT_SUFFIXES = {".py", ".cl", ".h", ".md", ".yaml", ".yml", ".toml", ".txt", ".cfg"}

#: "design.md §4.5", "design.md, §4.5", "[docs/design.md](design.md) §4.5", a comment's
#: line break between them ("design.md\n * §4.5"), and lists ("§5, §7", "§2–§3", "§2 and §3").
SECTION_CITATION = re.compile(
    r"design\.md(?:\]\([^)]*\))?[),]?\s*(?:[*#]\s*)?"
    r"(§\d+(?:\.\d+)?(?:\s*(?:,|–|-|and|or)\s*§\d+(?:\.\d+)?)*)")
SECTION_NUMBER = re.compile(r"§(\d+(?:\.\d+)?)")
NUMBERED_HEADING = re.compile(r"^#{1,6}\s+(\d+(?:\.\d+)?)\.?\s")
DOC_PATH = re.compile(r"\bdocs/([\w.-]+\.md)\b")
#: A markdown link from one doc to a sibling doc, with an optional anchor.
SIBLING_LINK = re.compile(r"\]\(((?:\.\./docs/)?[\w.-]+\.md)?(#[^)\s]*)?\)")
#: An anchor into a doc from anywhere ("design.md#9-filtered-surface-shadows").
ANCHORED_DOC = re.compile(r"\b([\w.-]+\.md)#([\w-]+)")
EXPLICIT_ANCHOR = re.compile(r"<a (?:id|name)=\"([\w-]+)\"")


def searched_files() -> list[Path]:
    files = [ROOT / name for name in TOP_LEVEL if (ROOT / name).is_file()]
    for folder in SEARCHED:
        files += sorted(path for path in (ROOT / folder).rglob("*")
                        if path.is_file() and path.suffix in TEXT_SUFFIXES)
    return files


@lru_cache(maxsize=None)
def text_of(path: Path) -> str:
    return path.read_text(encoding="utf-8", errors="replace")


def line_of(text: str, offset: int) -> int:
    return text.count("\n", 0, offset) + 1


def design_sections() -> set[str]:
    """The numbers of docs/design.md's numbered headings ("## 4. …" → "4", "### 4.5 …" → "4.5")."""
    return {match.group(1) for line in text_of(DOCS / "design.md").splitlines()
            if (match := NUMBERED_HEADING.match(line))}


def heading_anchor(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces as hyphens."""
    words = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return words.replace(" ", "-")


def anchors(doc: Path) -> set[str]:
    in_code = False
    found = set()
    for line in text_of(doc).splitlines():
        if line.startswith("```"):
            in_code = not in_code
        elif not in_code and (match := re.match(r"^#{1,6}\s+(.*)$", line)):
            found.add(heading_anchor(match.group(1)))
        if not in_code:  # an explicit anchor, kept where a heading's own changed
            found.update(EXPLICIT_ANCHOR.findall(line))
    return found


def citations(pattern: re.Pattern, files) -> list[tuple[str, re.Match]]:
    """("path:line", match) of every match of `pattern` in `files`."""
    found = []
    for path in files:
        text = text_of(path)
        found += [(f"{path.relative_to(ROOT)}:{line_of(text, match.start())}", match)
                  for match in pattern.finditer(text)]
    return found


def test_every_cited_design_section_exists():
    sections = design_sections()
    assert {"1", "2", "3", "4", "4.1", "4.5", "4.6", "9", "10"} <= sections, sorted(sections)
    missing = [f"{where}: design.md §{number}" for where, citation in citations(SECTION_CITATION, searched_files())
               for number in SECTION_NUMBER.findall(citation.group(1)) if number not in sections]
    assert not missing, "cited sections with no heading in docs/design.md:\n" + "\n".join(missing)


def test_every_cited_doc_exists():
    missing = [f"{where}: {match.group(0)}" for where, match in citations(DOC_PATH, searched_files())
               if not (DOCS / match.group(1)).is_file()]
    assert not missing, "docs cited but absent:\n" + "\n".join(missing)


def test_links_between_docs_land():
    broken = []
    for where, match in citations(SIBLING_LINK, sorted(DOCS.glob("*.md"))):
        target, anchor = match.group(1), match.group(2)
        if target is None and anchor is None:
            continue
        target_path = DOCS / Path(target).name if target else ROOT / where.split(":")[0]
        if not target_path.is_file():
            broken.append(f"{where}: {target}")
        elif anchor and anchor[1:] not in anchors(target_path):
            broken.append(f"{where}: {target or ''}{anchor}")
    assert not broken, "links between the docs that land nowhere:\n" + "\n".join(broken)


def test_every_anchor_into_the_docs_lands():
    broken = [f"{where}: {match.group(0)}" for where, match in citations(ANCHORED_DOC, searched_files())
              if (DOCS / match.group(1)).is_file() and match.group(2) not in anchors(DOCS / match.group(1))]
    assert not broken, "anchors into the docs with no such heading:\n" + "\n".join(broken)


@pytest.mark.parametrize("heading, anchor", [
    ("9. Filtered surface shadows", "9-filtered-surface-shadows"),
    ("Translucent occluders: the light side", "translucent-occluders-the-light-side"),
    ("4.1 raster — `stages/raster.py`", "41-raster--stagesrasterpy"),
])
def test_heading_anchor_follows_github(heading, anchor):
    assert heading_anchor(heading) == anchor


def test_a_missing_section_is_caught():
    """The citation pattern finds the forms the code uses, so a dropped section cannot hide."""
    forms = ["docs/design.md §4.5", "docs/design.md, §4.6", "[docs/design.md](design.md) §4.8",
             "docs/design.md\n * §4.5", "docs/design.md §5, §7", "[design.md](design.md) §2–§3"]
    found = [SECTION_NUMBER.findall(match.group(1)) for form in forms
             for match in SECTION_CITATION.finditer(form)]
    assert found == [["4.5"], ["4.6"], ["4.8"], ["4.5"], ["5", "7"], ["2", "3"]]
