"""`clrays watch`: render a scene again whenever its file, or another file named with
`--also` (a mesh, a texture, a glTF file it reads), is saved, in one warm session.

The session (`clrays.session.Renderer`) keeps its kernels and the stage results of the last
frames, so an edit re-runs only the stages whose inputs it changed: a new medium keeps the
shadow maps and the camera depth, a moved camera the shadow maps. Each render writes the
image atomically (and its passes, `render.aovs`) and prints one line: the frame's time and
the stages it reused. An edit that does not load or render prints its one-line error and
the image stays as it was, until the next save.

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
from ..passes import write_render
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
