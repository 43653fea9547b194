"""Writing images (and reading them back as sRGB). The extension of the path decides the format:

- `.png`: 8-bit sRGB, radiance × 2^exposure clamped to [0, 1] (opens anywhere);
- `.exr`: float32 linear RGB (OpenEXR, ZIP compression);
- `.npy`: float32 H×W×3 linear radiance, nothing applied.

Writes are atomic: a temporary file beside the target, then a rename, so an
interrupted or failed write (Ctrl-C, a full disk) never leaves a half-written image, and
its error is one line naming the file. A temporary's name holds the host and process id
of its writer, so a later write in the folder removes those of a process that is gone
(SIGKILL leaves no chance to clean up). The folder checks (`check_folder`, `make_folder`)
run before rendering, so a bad path fails at once. A run that writes many files into a
folder holds its lock (`folder_lock`), so that two runs never write into one folder.
Every file written here follows `clrays.outputs`' rule: never through a symbolic link.
"""
from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import re
import secrets
import shlex
import socket
import stat
import sys
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from .errors import ClraysError, OutputError
from .outputs import check_replaceable, make_folder, open_file, same_file  # make_folder: for its callers

FORMATS = (".png", ".exr", ".npy")


def check_output_path(path: str | Path, folder_exists: bool = True) -> Path:
    """Fail early (before rendering) on an unknown extension, an unwritable folder (with
    `folder_exists` False, the folder may be missing yet: `make_output_folder` creates it),
    or a link or other non-regular file at `path` (clrays.outputs)."""
    path = Path(path)
    check_name_length(path)
    if path.is_dir():
        raise OutputError(f"{path}: is a folder, not a file")
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise OutputError(f"{path}: unknown output extension {path.suffix or '(none)'!r}; "
                          f"expected one of {', '.join(FORMATS)}")
    check_replaceable(path)
    return check_folder(path) if folder_exists else path


def check_name_length(path: Path) -> Path:
    """Refuse a file name or path longer than the file system takes (NAME_MAX, PATH_MAX),
    before anything is rendered."""
    folder = path.parent if str(path.parent) else Path(".")
    limits = {"PC_NAME_MAX": 255, "PC_PATH_MAX": 4096}
    for name in limits:
        try:
            limits[name] = os.pathconf(folder if folder.is_dir() else ".", name)
        except (OSError, ValueError):
            pass
    if len(os.fsencode(path.name)) > limits["PC_NAME_MAX"]:
        raise OutputError(f"{str(path)[:60]}...: file name too long: {len(os.fsencode(path.name))} bytes, "
                          f"the file system takes at most {limits['PC_NAME_MAX']}")
    if len(os.fsencode(str(path.absolute()))) >= limits["PC_PATH_MAX"]:
        raise OutputError(f"{str(path)[:60]}...: path too long: at most {limits['PC_PATH_MAX'] - 1} bytes")
    return path


def check_folder(path: Path) -> Path:
    """Fail early when the folder a file goes into is missing or not writable."""
    check_name_length(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise OutputError(f"{path}: folder {str(folder)!r} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f"{path}: folder {str(folder)!r} is not writable")
    return path


def check_finite(image: np.ndarray, subject: str) -> np.ndarray:
    """Refuse to write a render holding NaN or infinity: no scene should produce one."""
    if not np.isfinite(image).all():
        raise ClraysError(f"{subject}: the render produced non-finite values (a bug: please report the scene)")
    return image


def to_srgb8(radiance: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """Linear radiance → 8-bit sRGB (IEC 61966-2-1 transfer curve)."""
    x = np.clip(np.nan_to_num(radiance * (2.0**exposure), nan=0.0), 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(srgb * 255).astype(np.uint8)


#: A temporary's name: `.NAME.clrays-HOST-PID-XXXX.SUFFIX`, so that a later run can tell
#: whether the process that wrote it is still alive (`remove_stale_temporaries`).
_TEMPORARY = re.compile(r"^\..+\.clrays-(?P<host>[A-Za-z0-9_-]*)-(?P<pid>\d+)-[A-Za-z0-9_]+\.[a-z]+$")


def _host() -> str:
    return re.sub(r"[^A-Za-z0-9_-]", "_", socket.gethostname())[:64]


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # e.g. another user's process: alive
        return True
    return True


#: Folders this process has already cleaned: a writer that died before it started left its
#: temporaries there, so once is enough, and a sequence of many frames does not list its
#: folder again for each one.
_cleaned_folders: set[str] = set()


def remove_stale_temporaries(folder: str | Path, again: bool = False) -> list[Path]:
    """Remove the temporaries in `folder` left by a write whose process is gone (killed with
    SIGKILL, or a machine that crashed); returns them. A temporary of a live process, or
    of another host (a shared folder), is left alone. Once per folder and process unless
    `again`."""
    removed = []
    key = os.path.abspath(folder or ".")
    if key in _cleaned_folders and not again:
        return removed
    _cleaned_folders.add(key)
    try:
        entries = list(os.scandir(folder or "."))
    except OSError:
        return removed
    for entry in entries:
        match = _TEMPORARY.match(entry.name)
        if match is None or match["host"] != _host() or _process_alive(int(match["pid"])):
            continue
        try:
            os.unlink(entry.path)
            removed.append(Path(entry.path))
        except OSError:
            pass
    return removed


def _temporary_name(path: Path) -> str:
    """`.NAME.clrays-HOST-PID-XXXX.SUFFIX` beside `path`, with the name cut so that the
    temporary's stays within NAME_MAX whatever the target's."""
    return os.path.join(path.parent or ".", f".{path.name[:80]}.clrays-{_host()}-{os.getpid()}-"
                                            f"{secrets.token_hex(6)}{path.suffix.lower()}")


def _create(temporary: str) -> None:
    # O_EXCL: never another's file; mode 0o666 less the umask, as any new file (not mkstemp's 0600).
    os.close(os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))


def temporary_beside(path: Path) -> str:
    """A new empty file beside `path` (`.NAME.clrays-HOST-PID-XXXX.SUFFIX`) to write and then
    rename over it."""
    temporary = _temporary_name(path)
    _create(temporary)
    return temporary


def file_digest(path: str | Path) -> str | None:
    """The BLAKE2b of a regular file's bytes (hex), or None when there is no such file
    (missing, or a FIFO or device, which is never opened for long: O_NONBLOCK)."""
    try:  # a link is no file clrays wrote
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOFOLLOW", 0))
    except OSError:
        return None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        h = hashlib.blake2b(digest_size=16)
        while chunk := os.read(fd, 1 << 20):
            h.update(chunk)
        return h.hexdigest()
    except OSError:
        return None
    finally:
        os.close(fd)


def _failure(path: Path, exc: BaseException) -> str:
    """One line for a failed write; a library's message may name the temporary, so it is cut
    to its first line, and a full disk or a file-size limit is said as such."""
    if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
        return f"{path}: cannot write: {os.strerror(exc.errno)}"
    text = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
    return f"{path}: cannot write: {(text.strip().splitlines() or [type(exc).__name__])[0]}"


def write_atomic(path: Path, write: Callable[[str], None], content_digest: bool = False) -> str | None:
    """Call `write(temporary)` on a file beside `path`, then rename it over `path`: readers
    see the old file or the whole new one, and a failure or an interrupt (KeyboardInterrupt
    at any point) leaves nothing behind. An OSError (a full disk) becomes one OutputError
    naming `path`. With `content_digest`, returns the `file_digest` of what was written,
    taken from the temporary before the rename (no other writer can have changed it)."""
    path = Path(path)
    check_replaceable(path)  # a link or a FIFO there is refused, not replaced unseen
    # Named before it is created, so that the `finally` knows it whenever the interrupt comes.
    temporary = _temporary_name(path)
    try:
        remove_stale_temporaries(path.parent)
        _create(temporary)
        write(temporary)
        written = file_digest(temporary) if content_digest else None
        os.replace(temporary, path)
        return written
    except OSError as exc:
        raise OutputError(_failure(path, exc)) from exc
    finally:
        with contextlib.suppress(OSError):
            os.unlink(temporary)  # gone after the rename; only ours (the name holds our pid and a random part)


def write_text(path: str | Path, text: str, newline: str | None = None) -> None:
    """Write `text` (UTF-8) to `path` atomically (`write_atomic`)."""
    def write(temporary: str) -> None:
        with open(temporary, "w", encoding="utf-8", newline=newline) as handle:
            handle.write(text)

    write_atomic(Path(path), write)


def make_output_folder(path: str | Path) -> Path:
    """Create the folder of output file `path` (and its parents), as every command does."""
    path = Path(path)
    make_folder(path.parent if str(path.parent) else Path("."), "the output folder")
    return path


#: The lock file of a folder a run writes into (`folder_lock`).
LOCK = ".clrays-lock"


#: Attempts at taking a lock whose file its holder removed meanwhile (`folder_lock`).
_LOCK_ATTEMPTS = 50


@contextlib.contextmanager
def folder_lock(folder: str | Path) -> Iterator[Path]:
    """Hold `folder`'s lock (an flock on LOCK) while the block runs: a second run into the
    same folder fails at once with one line naming the first (its pid, host and command),
    rather than interleaving its files with the first's. The lock goes with the process,
    also when it is killed, and its file goes when the run ends.

    Removing a lock file is safe only with both halves of this scheme: the holder unlinks
    the file while it still holds the flock, then closes it; and whoever takes the flock
    then checks that the name still leads to the file it locked (`same_file`). A run that
    opened the file just before its holder unlinked it gets its flock on a file no one
    will open again, sees the name gone or leading to another file, and opens the name
    anew, so two runs never both hold a lock on the file the name leads to. Only the
    holder unlinks, and only while the name is still its file; a file system without
    flock runs unlocked and leaves the file."""
    folder = Path(folder)
    path = folder / LOCK
    for _ in range(_LOCK_ATTEMPTS):
        fd, locked = _lock(folder, path)
        if not locked or same_file(fd, path):
            break
        os.close(fd)  # its holder removed it between our open and our flock: the name is another file now
    else:
        raise OutputError(f"{path}: cannot lock the folder: its lock file keeps being replaced")
    try:
        command = shlex.join(["clrays", *sys.argv[1:]])
        holder = f"pid {os.getpid()} on {socket.gethostname()}: {command[:300]}\n".encode("utf-8", "replace")
        with contextlib.suppress(OSError):
            os.ftruncate(fd, 0)
            os.pwrite(fd, holder, 0)
        yield path
    finally:
        if locked and same_file(fd, path):
            with contextlib.suppress(OSError):
                os.unlink(path)  # while the flock is held: see above
        os.close(fd)  # releases the lock


def _lock(folder: Path, path: Path) -> tuple[int, bool]:
    """(fd, whether it is flocked) of the lock file `path`, opened as `clrays.outputs` asks; a
    lock held by another run is one OutputError naming it."""
    try:
        fd = open_file(path, os.O_RDWR | os.O_CREAT)
    except OSError as exc:
        raise OutputError(f"{path}: cannot lock the folder: {exc.strerror or exc}") from None
    import fcntl

    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return fd, True
    except BlockingIOError:
        holder = os.pread(fd, 512, 0).decode("utf-8", "replace").strip().splitlines()
        os.close(fd)
        raise OutputError(f"{folder}: in use by another clrays run ({holder[0] if holder else 'unknown'}); "
                          f"wait for it to end, or write elsewhere") from None
    except OSError as exc:  # a file system without locks (ENOLCK, EOPNOTSUPP): run unlocked
        if exc.errno not in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS):
            os.close(fd)
            raise OutputError(f"{path}: cannot lock the folder: {exc.strerror or exc}") from None
        return fd, False


def write_image(path: str | Path, radiance: np.ndarray, exposure: float = 0.0) -> Path:
    """Write (H, W, 3) linear radiance to `path` atomically; returns the path."""
    write_frame(path, radiance, exposure)
    return Path(path)


def write_exr(temporary: str, channels: dict[str, np.ndarray]) -> None:
    """An EXR of `channels` (OpenEXR's names: "RGB", or "R", "depth.Z", ...), ZIP-compressed.
    A failed write (a full disk), which OpenEXR reports as a RuntimeError, is an OSError."""
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    try:
        with OpenEXR.File(header, channels) as exr:
            exr.write(temporary)
    except RuntimeError as exc:
        raise OSError(_errno_in(str(exc)), _exr_reason(str(exc))) from exc


def write_frame(path: str | Path, radiance: np.ndarray, exposure: float = 0.0) -> str:
    """`write_image`, returning the `file_digest` of the bytes written (what a sequence's
    manifest ties the frame's scene to)."""
    path = check_output_path(path)
    suffix = path.suffix.lower()
    radiance = np.ascontiguousarray(radiance, dtype=np.float32)

    def write(temporary: str) -> None:
        if suffix == ".png":
            from PIL import Image

            Image.fromarray(to_srgb8(radiance, exposure), mode="RGB").save(temporary, format="PNG")
        elif suffix == ".exr":
            write_exr(temporary, {"RGB": radiance})
        else:
            np.save(temporary, radiance)

    return write_atomic(path, write, content_digest=True)


def _errno_in(text: str) -> int | None:
    """The errno whose message OpenEXR's text holds ("No space left on device"), if any."""
    return next((code for code in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO, errno.EACCES)
                 if os.strerror(code).lower() in text.lower()), None)


def _exr_reason(text: str) -> str:
    code = _errno_in(text)
    return os.strerror(code) if code is not None else (text.strip().splitlines() or ["OpenEXR failed"])[0]


def read_srgb8(path: str | Path, exposure: float = 0.0) -> np.ndarray:
    """A written image as 8-bit sRGB (H, W, 3): a PNG as stored, a float format encoded
    with `to_srgb8` at `exposure` (what the PNG would have held)."""
    path = Path(path)
    if path.suffix.lower() == ".png":
        from PIL import Image

        with Image.open(path) as image:
            return np.asarray(image.convert("RGB"))
    return to_srgb8(read_linear(path), exposure)


def read_linear(path: str | Path) -> np.ndarray:
    """A written .npy or .exr image's linear radiance (H, W, 3)."""
    path = Path(path)
    if path.suffix.lower() == ".npy":
        return np.load(path)
    import OpenEXR

    with OpenEXR.File(str(path)) as exr:
        return np.asarray(exr.channels()["RGB"].pixels)
