"""Where clrays writes, and how it opens what it writes (docs/limits.md, "What a run writes").

One rule for every file clrays writes, appends to or reads back inside a folder it writes
(an image, a pass, a temporary, a sequence's manifest, a folder's lock, a cached reference,
a tuned setting): it is opened without following a symbolic link and must be a regular
file, and a folder clrays makes inside one (`.references`, a frame number's folder) must
be a directory, not a link to one. Anything else there is one line naming the path, so a
link planted in an output folder (`out/.clrays-frames.jsonl -> ../victim.txt`) can neither
send a write elsewhere nor be replaced unseen. The folders a user names (`-o out`,
`--cache`, $CLRAYS_CACHE) are the user's choice: a link there is followed.

Caches live in one place, `cache_root()`: never the working directory.

Writes confined (`--confine`, CLRAYS_CONFINE, on the command line): a run writes only in
the folders of the outputs it was given (`allow_writes`) and in its cache; a write
elsewhere is one line and nothing is written.
"""
from __future__ import annotations

import errno
import os
import stat
import tempfile
from pathlib import Path

from .errors import OutputError

#: $CLRAYS_CACHE: the folder of every cache clrays keeps (`cache_root`).
CACHE_ENV = "CLRAYS_CACHE"

#: The folders the command being run may write into, links resolved (`allow_writes`);
#: None where no command declared them (the Python API): then writes are not confined.
_write_roots: list[str] | None = None
#: The same folders as named (absolute), so that a folder named through a link is allowed itself.
_named_roots: list[str] = []


def cache_root() -> Path:
    """The one folder of clrays' caches (exact references, tuned settings, the OpenCL vendors
    list, the marks of kernels built): $CLRAYS_CACHE, else the user's cache folder
    ($XDG_CACHE_HOME, else ~/.cache) / clrays; never the working directory (without a home,
    a folder of the user's own in the system's temporary folder)."""
    chosen = os.environ.get(CACHE_ENV, "").strip()
    if chosen:
        return Path(chosen).expanduser()
    base = os.environ.get("XDG_CACHE_HOME", "").strip()
    if not base:
        try:
            base = str(Path.home() / ".cache")
        except RuntimeError:  # no $HOME and no password entry: a container's anonymous user
            return Path(tempfile.gettempdir()) / f"clrays-cache-{os.getuid()}"
    return Path(base) / "clrays"


def allow_writes(*folders: str | Path) -> None:
    """Declare, for the command being run, the folders of the outputs it was given (an
    output file's folder, a sweep's folder, --cache). With confinement on (`--confine`),
    writes anywhere but in them, below them and in the cache are refused (`check_write`)."""
    global _write_roots
    if _write_roots is None:
        _write_roots, _named_roots[:] = [], []
        folders = (cache_root(), *folders)
    for folder in folders:
        folder = str(folder) or "."
        _write_roots.append(os.path.realpath(folder))
        _named_roots.append(os.path.abspath(folder))


def end_writes() -> None:
    """The command has ended: nothing is declared (`allow_writes`) any more."""
    global _write_roots
    _write_roots = None


def writes_confined() -> bool:
    """Whether this run's writes are confined (`--confine` or CLRAYS_CONFINE, and a command
    that declared its outputs)."""
    if _write_roots is None:
        return False
    from .scene.files import confinement  # lazily: clrays.scene loads the whole scene package

    return confinement() is not None


def check_write(path: str | Path) -> None:
    """Where writes are confined, refuse `path` unless it lies in a folder this run may
    write into (its outputs' and the cache), its folder's symbolic links resolved."""
    if not writes_confined():
        return
    named = os.path.abspath(path)
    # The folder resolved, the last name not: a link there is the rule's to refuse, not followed here.
    real = os.path.join(os.path.realpath(os.path.dirname(named)), os.path.basename(named))
    if named not in _named_roots and not any(os.path.commonpath([real, root]) == root for root in _write_roots):
        from .scene.files import confinement

        raise OutputError(f"{path}: outside the folders this run may write into (its outputs' and the cache "
                          f"{cache_root()}; writes confined by {confinement()})")


def _kind(mode: int) -> str:
    from .scene.files import kind_name

    return kind_name(mode)


def refused(path: str | Path, mode: int) -> OutputError:
    """The line for `path` being something clrays does not write through: a link, or not a
    regular file."""
    if stat.S_ISLNK(mode):
        return OutputError(f"{path}: is a symbolic link; clrays writes nothing through a link in a folder it writes "
                           f"(remove it)")
    return OutputError(f"{path}: is a {_kind(mode)}, not a regular file (remove it)")


def check_replaceable(path: str | Path) -> None:
    """Before a file is renamed over `path` (`clrays.image_io.write_atomic`): `path` is missing
    or a regular file, and may be written (`check_write`)."""
    check_write(path)
    try:
        mode = os.lstat(path).st_mode
    except OSError:
        return  # missing (or unreadable: the rename says why)
    if not stat.S_ISREG(mode):
        raise refused(path, mode)


def open_file(path: str | Path, flags: int, mode: int = 0o666) -> int:
    """`os.open(path, flags)` as the rule asks: the last component not followed where it is a
    link, never waiting on a FIFO (O_NONBLOCK), and the file opened a regular one; else one
    OutputError naming `path`. An OSError of the open itself (a missing folder, a full
    disk) is raised as it is, for the caller to say what it was doing."""
    if flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_APPEND):
        check_write(path)
    flags |= getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags, mode)
    except OSError as exc:
        if exc.errno in (errno.ELOOP, errno.EMLINK):  # O_NOFOLLOW met a link (EMLINK: FreeBSD)
            with_link = _lstat_mode(path)
            if with_link is not None and stat.S_ISLNK(with_link):
                raise refused(path, with_link) from None
        raise
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode):
        os.close(fd)
        raise refused(path, info.st_mode)
    return fd


def _lstat_mode(path: str | Path) -> int | None:
    try:
        return os.lstat(path).st_mode
    except OSError:
        return None


def make_folder(folder: str | Path, name: str = "folder") -> Path:
    """Create `folder`, a folder the user named (a link on its way is followed: the user's
    choice), and its parents, and fail early (before any rendering) when that is impossible
    or nothing can be written into it; `name` says what it is in messages."""
    folder = Path(folder)
    check_write(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{folder}: cannot create {name}: {exc.strerror or exc}") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f"{folder}: {name} is not writable")
    return folder


def make_folders_below(base: str | Path, folder: str | Path, name: str = "folder") -> Path:
    """Make `folder`, which lies in `base` (a folder the user named: created with its
    parents, links followed), and each folder between them: these clrays makes, so each
    must be a directory, not a link. `name` says what `folder` is in messages."""
    base, folder = Path(base), Path(folder)
    make_folder(base, name)
    current = base
    for part in folder.relative_to(base).parts:
        current = current / part
        check_write(current)
        try:
            os.mkdir(current)
        except FileExistsError:
            pass
        except OSError as exc:
            raise OutputError(f"{current}: cannot create {name}: {exc.strerror or exc}") from None
        mode = _lstat_mode(current)
        if mode is not None and not stat.S_ISDIR(mode):
            if stat.S_ISLNK(mode):
                raise OutputError(f"{current}: is a symbolic link; clrays makes its own folder there and writes "
                                  f"nothing through a link (remove it)")
            raise OutputError(f"{current}: is a {_kind(mode)}, where clrays makes {name} (remove it)")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f"{folder}: {name} is not writable")
    return folder


def same_file(fd: int, path: str | Path) -> bool:
    """Whether `path` (not followed) is the file open as `fd`."""
    try:
        opened, named = os.fstat(fd), os.lstat(path)
    except OSError:
        return False
    return (opened.st_dev, opened.st_ino) == (named.st_dev, named.st_ino)
