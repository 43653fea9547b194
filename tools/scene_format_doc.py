"""Write the key tables of docs/scene-format.md from `clrays.scene.fields`.

Each table sits between `<!-- fields:NAME -->` and `<!-- /fields -->`, NAME a section of
`clrays.scene.fields.SECTIONS` (`render`, `lights.spot`, ...); the text around the
markers is left as written.

    .venv/bin/python tools/scene_format_doc.py           # rewrite the tables in place
    .venv/bin/python tools/scene_format_doc.py --check   # exit 1 if a table is stale
"""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from clrays.scene.fields import SECTIONS, Field, Section

DOC = Path(__file__).resolve().parents[1] / "docs" / "scene-format.md"
_BLOCK = re.compile(r"(<!-- fields:(?P<name>[\w.]+) -->\n)(?P<body>.*?)(<!-- /fields -->)", re.DOTALL)


def _number(value: float) -> str:
    """1024, 0.8, 1e30, 1e-6: as a person writes them."""
    if float(value).is_integer() and abs(value) < 1e6:
        return str(int(value))
    return re.sub(r"e\+?(-?)0*(\d)", r"e\1\2", f"{value:g}")


def _value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, (int, float)):
        return _number(value)
    return str(value)


def _range(field: Field) -> str:
    parts = []
    if field.choices:
        parts.append(", ".join(f"`{choice}`" for choice in field.choices))
    elif field.type == "boolean":
        parts.append("`true`, `false`")
    low, high = field.low, field.high
    if low is not None and high is not None:
        opening, closing = "(" if field.low_open else "[", ")" if field.high_open else "]"
        parts.append(f"{opening}{_number(low)}, {_number(high)}{closing}")
    elif low is not None:
        parts.append(f"{'>' if field.low_open else '≥'} {_number(low)}")
    elif high is not None:
        parts.append(f"{'<' if field.high_open else '≤'} {_number(high)}")
    if field.rule:
        parts.append(field.rule)
    return ", ".join(parts)


def _default(field: Field) -> str:
    if field.shown_default:
        return field.shown_default
    if field.required or field.default is None:
        return "—"
    return f"`{_value(field.default)}`"


def table(section: Section) -> str:
    """The section's markdown table, then its rules, one paragraph each."""
    cells = [("key", "type", "required", "default", "range / values", "notes"), ("---",) * 6]
    if section.kind:
        cells.append(("`type`", "string", "yes", "—", f"`{section.kind}`", ""))
    cells += [(f"`{field.key}`", field.type, "yes" if field.required else "no", _default(field), _range(field),
               field.notes) for field in section.fields]
    rows = ["| " + " | ".join(row) + " |" for row in cells]
    return "\n".join(rows) + "\n" + "".join(f"\n{rule}\n" for rule in section.rules)


def generate(text: str) -> str:
    """The document with every marked table written afresh. Raises ValueError for a
    marker naming no section, and for a section (with keys) that no marker names."""
    named = set()

    def fill(match: re.Match) -> str:
        name = match["name"]
        if name not in SECTIONS:
            raise ValueError(f"<!-- fields:{name} -->: no such section; expected one of {', '.join(SECTIONS)}")
        named.add(name)
        return f"{match[1]}\n{table(SECTIONS[name])}\n{match[4]}"

    result = _BLOCK.sub(fill, text)
    missing = [name for name, section in SECTIONS.items() if section.fields and name not in named]
    if missing:
        raise ValueError(f"sections without a table in the document: {', '.join(missing)}")
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if the document's tables are stale")
    parser.add_argument("--doc", type=Path, default=DOC, help=f"the document (default: {DOC})")
    args = parser.parse_args(argv)
    text = args.doc.read_text(encoding="utf-8")
    try:
        fresh = generate(text)
    except ValueError as exc:
        print(f"{args.doc}: {exc}", file=sys.stderr)
        return 1
    if args.check:
        if fresh != text:
            print(f"{args.doc}: the key tables are stale; run tools/scene_format_doc.py", file=sys.stderr)
            return 1
        return 0
    if fresh != text:
        args.doc.write_text(fresh, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
