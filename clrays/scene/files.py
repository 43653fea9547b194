"""Reading a file the user named (a scene, a mesh) without trusting it: it must be a
regular file under a size limit. /dev/zero, a FIFO or a directory is refused before a
byte is read, and the open cannot block (docs/limits.md).

Confinement (`--confine`, `CLRAYS_CONFINE=1`): while a scene is read (`scene_files`),
every file it names (meshes, relief maps, light textures: all opened here) must lie in the
scene's folder or below it, symbolic links resolved, so a scene from elsewhere cannot read
the rest of the machine into its image.
"""
from __future__ import annotations

import contextlib
import contextvars
import os
import stat
from pathlib import Path
from typing import Iterator

#: Turns confinement on for every scene this process loads, whatever the command line says:
#: any value but empty, 0, false, no or off.
CONFINE_ENV = "CLRAYS_CONFINE"

_confine_option = False  # --confine, set by the command line
#: The folder the files of the scene being read must lie in (resolved), or None when not confined.
_scene_folder: contextvars.ContextVar[str | None] = contextvars.ContextVar("clrays_scene_folder", default=None)


def confine_scene_files(on: bool) -> None:
    """--confine: confine the files of every scene loaded from now on (or not, where
    CLRAYS_CONFINE does not ask for it)."""
    global _confine_option
    _confine_option = bool(on)


def confinement() -> str | None:
    """What confines scene files, as a user would name it ("--confine", "CLRAYS_CONFINE"),
    or None when they are not confined."""
    if os.environ.get(CONFINE_ENV, "").strip().lower() not in ("", "0", "false", "no", "off"):
        return CONFINE_ENV
    return "--confine" if _confine_option else None


@contextlib.contextmanager
def scene_files(scene_folder: Path | str) -> Iterator[None]:
    """While a scene is read: the files it names are confined to `scene_folder` (the
    folder of the scene file) when `confinement()` asks for it."""
    token = _scene_folder.set(os.path.realpath(scene_folder) if confinement() else None)
    try:
        yield
    finally:
        _scene_folder.reset(token)


def confined(path: Path | str) -> str:
    """`path`, resolved (symbolic links and `..` followed) where scene files are confined;
    FileRefused where it then lies outside the scene's folder."""
    folder = _scene_folder.get()
    if folder is None:
        return os.fspath(path)
    real = os.path.realpath(path)
    if os.path.commonpath([real, folder]) != folder:
        shown = f", which is {real}" if real != os.path.abspath(path) else ""
        raise FileRefused(f"outside the scene's folder {folder}{shown} (files confined by {confinement()})")
    return real


class FileRefused(Exception):
    """The file cannot be read; the message is one line, without the path."""


def read_regular_file(path: Path | str, limit: int, too_big_hint: str = "", follow_links: bool = True) -> bytes:
    """The bytes of a regular file of at most `limit` bytes.

    Raises FileRefused naming the problem: a missing or unreadable file, something other
    than a regular file (a device, a FIFO, a directory), a file over the limit (then
    `too_big_hint` says what to do instead), or, while a scene's files are confined, a file
    outside its folder (`confined`). Not `follow_links`: a symbolic link is refused too (a
    file clrays wrote and reads back: clrays.outputs).
    """
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0)
    if not follow_links:
        flags |= getattr(os, "O_NOFOLLOW", 0)
    if _scene_folder.get() is not None:
        # Open what was checked: a name swapped for a link since can only fail.
        path, flags = confined(path), flags | getattr(os, "O_NOFOLLOW", 0)
    try:
        # O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer.
        fd = os.open(path, flags)
    except OSError as exc:
        if flags & getattr(os, "O_NOFOLLOW", 0) and os.path.islink(path):
            raise FileRefused("a symbolic link, which clrays does not follow here") from None
        raise FileRefused(exc.strerror or str(exc)) from None
    try:
        info = os.fstat(fd)  # of what was opened, not of what the name pointed to before
        if not stat.S_ISREG(info.st_mode):
            raise FileRefused(f"not a regular file (a {kind_name(info.st_mode)})")
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


def kind_name(mode: int) -> str:
    """What a file that is no regular file is, in words ("FIFO", "character device", ...)."""
    for test, name in ((stat.S_ISDIR, "directory"), (stat.S_ISCHR, "character device"),
                       (stat.S_ISBLK, "block device"), (stat.S_ISFIFO, "FIFO"), (stat.S_ISSOCK, "socket")):
        if test(mode):
            return name
    return "special file"


def _size(n: int) -> str:
    return f"{n / 2**20:.1f} MiB" if n >= 1 << 20 else f"{n} bytes"


def missing(path: Path | str) -> bool:
    """Whether `path` does not exist, for a reader's "no such file": asked only inside the
    scene's folder where files are confined (outside, the open refuses the path first, so a
    scene cannot learn which files exist elsewhere)."""
    try:
        real = confined(path)
    except FileRefused:
        return False
    return not os.path.exists(real)
