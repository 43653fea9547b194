"""Writing images (and reading them back as sRGB). The extension of the path decides the format:

- `.png`: 8-bit sRGB, radiance × 2^exposure clamped to [0, 1] (opens anywhere);
- `.exr`: float32 linear RGB (OpenEXR, ZIP compression);
- `.npy`: float32 H×W×3 linear radiance, nothing applied.

Writes are atomic: a temporary file beside the target, then a rename, so an
interrupted or failed write never leaves a half-written image. A temporary's name holds
the host and process id of its writer, so a later write in the folder removes those of a
process that is gone (SIGKILL leaves no chance to clean up). The folder checks
(`check_folder`, `make_folder`) run before rendering, so a bad path fails at once.
"""
from __future__ import annotations

import os
import re
import socket
import tempfile
from pathlib import Path

import numpy as np

from .errors import ClraysError, OutputError

FORMATS = (".png", ".exr", ".npy")


def check_output_path(path: str | Path) -> Path:
    """Fail early (before rendering) on an unknown extension or an unwritable folder."""
    path = Path(path)
    check_name_length(path)
    if path.is_dir():
        raise OutputError(f"{path}: is a folder, not a file")
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise OutputError(f"{path}: unknown output extension {path.suffix or '(none)'!r}; "
                          f"expected one of {', '.join(FORMATS)}")
    return check_folder(path)


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


def make_folder(folder: str | Path, name: str = "folder") -> Path:
    """Create `folder` and its parents, and fail early (before any rendering) when that is
    impossible or nothing can be written into it; `name` says what it is in messages."""
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{folder}: cannot create {name}: {exc.strerror or exc}") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f"{folder}: {name} is not writable")
    return folder


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


def temporary_beside(path: Path) -> str:
    """A new empty file beside `path` (`.NAME.clrays-HOST-PID-XXXX.SUFFIX`) to write and then
    rename over it; created with the permissions of any new file (umask), not mkstemp's 0600."""
    # The name is cut so that the temporary's stays within NAME_MAX whatever the target's.
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name[:80]}.clrays-{_host()}-{os.getpid()}-",
                                         suffix=path.suffix.lower(), dir=path.parent or ".")
    os.close(handle)
    umask = os.umask(0o022)
    os.umask(umask)
    os.chmod(temporary, 0o666 & ~umask)
    return temporary


def write_atomic(path: Path, write) -> None:
    """Call `write(temporary)` on a file beside `path`, then rename it over `path`: readers
    see the old file or the whole new one, and a failure leaves nothing behind."""
    temporary = None
    try:
        remove_stale_temporaries(path.parent)
        temporary = temporary_beside(path)
        write(temporary)
        os.replace(temporary, path)
    except OSError as exc:
        raise OutputError(f"{path}: cannot write: {exc.strerror or exc}") from exc
    finally:
        if temporary is not None and os.path.exists(temporary):
            os.unlink(temporary)


def write_image(path: str | Path, radiance: np.ndarray, exposure: float = 0.0) -> Path:
    """Write (H, W, 3) linear radiance to `path` atomically; returns the path."""
    path = check_output_path(path)
    suffix = path.suffix.lower()
    radiance = np.ascontiguousarray(radiance, dtype=np.float32)

    def write(temporary: str) -> None:
        if suffix == ".png":
            from PIL import Image

            Image.fromarray(to_srgb8(radiance, exposure), mode="RGB").save(temporary, format="PNG")
        elif suffix == ".exr":
            import OpenEXR

            header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
            with OpenEXR.File(header, {"RGB": radiance}) as exr:
                exr.write(temporary)
        else:
            np.save(temporary, radiance)

    write_atomic(path, write)
    return path


def read_srgb8(path: str | Path, exposure: float = 0.0) -> np.ndarray:
    """A written image as 8-bit sRGB (H, W, 3): a PNG as stored, a float format encoded
    with `to_srgb8` at `exposure` (what the PNG would have held)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".png":
        from PIL import Image

        with Image.open(path) as image:
            return np.asarray(image.convert("RGB"))
    if suffix == ".npy":
        return to_srgb8(np.load(path), exposure)
    import OpenEXR

    with OpenEXR.File(str(path)) as exr:
        return to_srgb8(np.asarray(exr.channels()["RGB"].pixels), exposure)
