"""Write the key tables of docs/scene-format.md from `clrays.scene.fields`.

Each table sits between `<!-- fields:NAME -->` and `<!-- /fields -->`, NAME a section of
`clrays.scene.fields.SECTIONS` (`render`, `lights.spot`, ...); the text around the
markers is left as written.

    .venv/bin/python tools/scene_format_doc.py           # rewrite the tables in place
    .venv/bin/python tools/scene_format_doc.py --check   # exit 1 if a table is stale
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

from clrays.scene.fields import SECTIONS, Field, Section

sys.path.insert(0, str(Path(__file__).resolve().parent))  # the tools' shared helpers, also when loaded by path
import doc_blocks  # noqa: E402

DOC = Path(__file__).resolve().parents[1] / "docs" / "scene-format.md"


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
    return doc_blocks.fill(text, "fields", list(SECTIONS), lambda name: f"\n{table(SECTIONS[name])}\n",
                           needed=[name for name, section in SECTIONS.items() if section.fields], kind="section",
                           missing="sections without a table")


def main(argv: list[str] | None = None) -> int:
    return doc_blocks.main(argv, description=__doc__.split("\n\n")[0], doc=DOC, generate=generate,
                           blocks="key tables", tool="tools/scene_format_doc.py")


if __name__ == "__main__":
    sys.exit(main())
