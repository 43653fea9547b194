"""The host's steps whose cost follows the triangle count, timed for `--stats`: reading the
scene (`load`, which holds the next two), putting meshes in spatial order, finding their
closed solids, and linking the triangles' edges for the walks (`edge links`, kept on the
geometry, so a sequence that does not move it pays once). Each step adds its wall time
under its name while it runs; the command line reads and clears them after a frame."""
from __future__ import annotations

import contextlib
import time

_taken: dict[str, float] = {}


@contextlib.contextmanager
def timed(step: str):
    """Add the block's wall time (ms) to `step`; also a decorator."""
    _taken.setdefault(step, 0.0)  # listed in the order the steps began
    start = time.perf_counter()
    try:
        yield
    finally:
        _taken[step] = _taken.get(step, 0.0) + (time.perf_counter() - start) * 1e3


def taken() -> dict[str, float]:
    """The steps timed since the last call, ms each, in the order they first began."""
    found = dict(_taken)
    _taken.clear()
    return found
