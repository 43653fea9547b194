"""Reading a file the user named (a scene, a mesh) without trusting it: it must be a
regular file under a size limit. /dev/zero, a FIFO or a directory is refused before a
byte is read, and the open cannot block (docs/limits.md).
"""
from __future__ import annotations

import os
import stat
from pathlib import Path


class FileRefused(Exception):
    """The file cannot be read; the message is one line, without the path."""


def read_regular_file(path: Path | str, limit: int, too_big_hint: str = "") -> bytes:
    """The bytes of a regular file of at most `limit` bytes.

    Raises FileRefused naming the problem: a missing or unreadable file, something other
    than a regular file (a device, a FIFO, a directory), or a file over the limit (then
    `too_big_hint` says what to do instead).
    """
    try:
        # O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer.
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    except OSError as exc:
        raise FileRefused(exc.strerror or str(exc)) from None
    try:
        info = os.fstat(fd)  # of what was opened, not of what the name pointed to before
        if not stat.S_ISREG(info.st_mode):
            raise FileRefused(f"not a regular file (a {_kind(info.st_mode)})")
        if info.st_size > limit:
            raise FileRefused(f"{_size(info.st_size)}, more than the limit of {_size(limit)}"
                              + (f"; {too_big_hint}" if too_big_hint else ""))
        chunks, total = [], 0
        while True:  # read to the end, but never past the limit (a file may grow meanwhile)
            chunk = os.read(fd, min(1 << 20, limit + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
            if total > limit:
                raise FileRefused(f"more than the limit of {_size(limit)}"
                                  + (f"; {too_big_hint}" if too_big_hint else ""))
        return b"".join(chunks)
    except OSError as exc:
        raise FileRefused(exc.strerror or str(exc)) from None
    finally:
        os.close(fd)


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "directory"), (stat.S_ISCHR, "character device"),
                       (stat.S_ISBLK, "block device"), (stat.S_ISFIFO, "FIFO"), (stat.S_ISSOCK, "socket")):
        if test(mode):
            return name
    return "special file"


def _size(n: int) -> str:
    return f"{n / 2**20:.1f} MiB" if n >= 1 << 20 else f"{n} bytes"
