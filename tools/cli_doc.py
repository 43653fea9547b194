"""Write the `--help` blocks of docs/cli.md from the `clrays` click commands.

Each block sits between `<!-- help:NAME -->` and `<!-- /help -->`, NAME `clrays` (the
group) or one of its commands (`render`, `relief-to-mesh`, ...); it holds that command's
`--help` at a fixed width, so the document does not depend on the terminal that wrote it.
The text around the markers is left as written.

    .venv/bin/python tools/cli_doc.py           # rewrite the blocks in place
    .venv/bin/python tools/cli_doc.py --check   # exit 1 if a block is stale
"""
from __future__ import annotations

import sys
from pathlib import Path

import click

from clrays.cli import main as clrays

sys.path.insert(0, str(Path(__file__).resolve().parent))  # the tools' shared helpers, also when loaded by path
import doc_blocks  # noqa: E402

DOC = Path(__file__).resolve().parents[1] / "docs" / "cli.md"
#: The group's own name in the markers; every other name is a command of it.
GROUP = "clrays"


def help_text(name: str) -> str:
    """`clrays --help` (name `clrays`) or `clrays NAME --help`, wrapped at the group's
    max_content_width whatever the terminal."""
    width = clrays.context_settings["max_content_width"]
    settings = {**clrays.context_settings, "terminal_width": width + 2}  # click keeps 2 columns spare
    group = click.Context(clrays, info_name=GROUP, **settings)
    if name == GROUP:
        return clrays.get_help(group)
    command = clrays.commands[name]
    return command.get_help(click.Context(command, info_name=name, parent=group))


def command_names() -> list[str]:
    """The group, then every command `clrays --help` lists, in its order."""
    context = click.Context(clrays, info_name=GROUP)
    return [GROUP] + [name for name in clrays.list_commands(context) if not clrays.commands[name].hidden]


def generate(text: str) -> str:
    """The document with every marked block written afresh. Raises ValueError for a
    marker naming no command, and for a command that no marker names."""
    names = command_names()
    return doc_blocks.fill(text, "help", names, lambda name: f"```text\n{help_text(name)}\n```\n", needed=names,
                           kind="command", missing="commands without a help block")


def main(argv: list[str] | None = None) -> int:
    return doc_blocks.main(argv, description=__doc__.split("\n\n")[0], doc=DOC, generate=generate,
                           blocks="help blocks", tool="tools/cli_doc.py")


if __name__ == "__main__":
    sys.exit(main())
