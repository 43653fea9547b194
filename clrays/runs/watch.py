"""`clrays watch`: render a scene again whenever its file, or another file named with
`--also` (a mesh, a texture, a glTF file it reads), is saved, in one warm session.

The session (`clrays.session.Renderer`) keeps its kernels and the stage results of the last
frames, so an edit re-runs only the stages whose inputs it changed: a new medium keeps the
shadow maps and the camera depth, a moved camera the shadow maps. Each render writes the
image atomically (and its passes, `render.aovs`) and prints one line: the frame's time and
the stages it reused. An edit that does not load or render prints its one-line error and
the image stays as it was, until the next save. A render that writes fewer passes than the
one before (an edit dropped `render.aovs`) removes the pass files that render wrote, so
no stale pass stays beside the new image; files clrays did not write are left alone.

Saves are found by polling each file's (mtime, size, inode) every `interval` seconds, which
an editor's write-and-rename changes as well as a write in place: no file-watching package.
"""
from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Callable

from ..errors import ClraysError
from ..exposure import exposure_setting, frame_exposure
from ..passes import pass_paths, write_render
from ..scene.load import load_scene
from ..session import Renderer

#: Seconds between two looks at the files' modification times.
POLL_SECONDS = 0.2


def _state(path: Path):
    """What changes when a file is saved: (mtime, size, inode); None while it is missing
    (an editor between removing and renaming)."""
    try:
        stat = os.stat(path)
    except OSError:
        return None
    return stat.st_mtime_ns, stat.st_size, stat.st_ino


def _identity(path: Path):
    """What tells the file at `path` (not followed) from any other written later: (device,
    inode, mtime, size); None where there is none."""
    try:
        info = os.lstat(path)
    except OSError:
        return None
    return info.st_dev, info.st_ino, info.st_mtime_ns, info.st_size


def _remove_dropped_passes(written: dict[Path, tuple], kept: set[Path]) -> None:
    """Remove the pass files of `written` (path → `_identity` when written) that a new render
    did not write again (not in `kept`), each only while it is still the file written then."""
    for path, identity in written.items():
        if path not in kept and identity is not None and _identity(path) == identity:
            try:
                os.unlink(path)
            except OSError:
                pass  # gone meanwhile, or the folder turned read-only: nothing of ours to report


def watch(scene: Path, output: Path, *, overrides=(), method: str | None = None, exposure: float | str | None = None,
          renderer: Renderer | None = None, also=(), interval: float = POLL_SECONDS,
          stop: threading.Event | None = None, max_renders: int | None = None,
          echo: Callable[[str], None] = print) -> tuple[int, int]:
    """Render `scene` to `output` now and after every save of it or of a file in `also`,
    until `stop` is set or `max_renders` renders were written; returns (renders, errors).
    Each render echoes `render N: T ms  reused: stages`, then (8-bit output) the EV `auto`
    chose and a warning for a black or mostly white frame; a failed one `clrays: error: ...`.
    exposure: stops or AUTO (clrays.exposure), each render's own; None: the scene's
    render.exposure."""
    scene, output = Path(scene), Path(output)
    files = [scene, *(Path(path) for path in also)]
    renderer = renderer or Renderer()
    stop = stop or threading.Event()
    renders = errors = 0
    seen = None
    passes: dict[Path, tuple] = {}  # the pass files the last render wrote (path → `_identity`)
    while not stop.is_set():
        states = [_state(path) for path in files]
        if states != seen:
            seen = states
            try:
                loaded = load_scene(scene, overrides)
                result = renderer.render(loaded, method)
                notes: list[str] = []  # said after the render's line
                stops = frame_exposure(exposure_setting(exposure, loaded), result.image, output, notes.append)
                write_render(output, result, loaded, stops, str(scene))
                written = pass_paths(output, loaded.render.aovs)[1:]
                _remove_dropped_passes(passes, set(written))
                passes = {path: _identity(path) for path in written}
            except ClraysError as exc:
                errors += 1
                echo(f"clrays: error: {exc}")
            else:
                renders += 1
                reused = " ".join(result.reused) or "-"
                echo(f"render {renders}: {result.wall_ms:8.1f} ms  reused: {reused}")
                for line in notes:
                    echo(line)
                if max_renders is not None and renders >= max_renders:
                    break
        stop.wait(interval)
    return renders, errors
