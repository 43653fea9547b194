"""The command line that the tools writing marked blocks of a document share
(tools/scene_format_doc.py, tools/cli_doc.py): rewrite the blocks in place, or with
`--check` only say, with exit code 1, that they are stale."""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from typing import Callable


def main(argv: list[str] | None, *, description: str, doc: Path, generate: Callable[[str], str], blocks: str,
         tool: str) -> int:
    """Run a block-writing tool: `generate` turns the document's text into the fresh text
    (raising ValueError for a marker it cannot fill); `blocks` names them in messages
    ("key tables"), `tool` is the script to run when they are stale."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--check", action="store_true", help=f"exit 1 if the document's {blocks} are stale")
    parser.add_argument("--doc", type=Path, default=doc, help=f"the document (default: {doc})")
    args = parser.parse_args(argv)
    text = args.doc.read_text(encoding="utf-8")
    try:
        fresh = generate(text)
    except ValueError as exc:
        print(f"{args.doc}: {exc}", file=sys.stderr)
        return 1
    if fresh == text:
        return 0
    if args.check:
        print(f"{args.doc}: the {blocks} are stale; run {tool}", file=sys.stderr)
        return 1
    args.doc.write_text(fresh, encoding="utf-8")
    return 0


def fill(text: str, marker: str, names: list[str], body: Callable[[str], str], needed: list[str], kind: str,
         missing: str) -> str:
    """The document with each block between `<!-- MARKER:NAME -->` and `<!-- /MARKER -->`
    holding body(NAME) afresh. Raises ValueError for a NAME not in `names` (a `kind`:
    "section", "command"), and for names in `needed` that no marker names (`missing`
    begins that message: "sections without a table")."""
    block = re.compile(rf"(<!-- {marker}:(?P<name>[\w.-]+) -->\n).*?(<!-- /{marker} -->)", re.DOTALL)
    named = set()

    def write(match: re.Match) -> str:
        name = match["name"]
        if name not in names:
            raise ValueError(f"<!-- {marker}:{name} -->: no such {kind}; expected one of {', '.join(names)}")
        named.add(name)
        return f"{match[1]}{body(name)}{match[3]}"

    result = block.sub(write, text)
    left = [name for name in needed if name not in named]
    if left:
        raise ValueError(f"{missing} in the document: {', '.join(left)}")
    return result
