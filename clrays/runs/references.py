"""Reference images to measure error against, computed once and kept on disk: `exact`
(the float64 renderer) or `raymarch:N` (N steps per ray), of whole frames (`clrays sweep
--reference`) or of a fixed subset of pixels (`clrays bench`: exact costs pixels ×
triangles, so it is measured where it is needed only).

An entry's key is the reference, the digest of the scene as the reference renders it
(`clrays.reuse.scene_digest` of `reference_scene`) and the pixels: points of a study that
differ only in settings the reference does not read share one image. The depth-edge
masks that `clrays.reference.metrics.image_error` leaves out are kept the same way.
"""
from __future__ import annotations

import io
import os
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np

from ..errors import ClraysError
from ..image_io import write_atomic
from ..outputs import check_replaceable, make_folders_below
from ..reference.metrics import ImageError, depth_edges, depth_edges_at, depth_map, image_error
from ..reuse import StageCache, digest, scene_digest
from ..scene.files import FileRefused, read_regular_file
from ..scene.load import MAX_STEPS
from ..scene.model import Render, Scene
from ..session import Renderer

#: (ys, xs): the rows and columns of the pixels a reference is computed on.
Pixels = tuple[np.ndarray, np.ndarray]


class Reference(NamedTuple):
    """What the error is measured against: `exact`, or `raymarch` at `steps` per ray."""

    method: str
    steps: int = 0

    @property
    def name(self) -> str:
        """As `--reference` spells it."""
        return self.method if self.method == "exact" else f"{self.method}:{self.steps}"


EXACT = Reference("exact")


def parse_reference(text: str | None) -> Reference | None:
    """`exact` or `raymarch:N` (N steps per ray, 1 to MAX_STEPS); None: no reference."""
    if text is None:
        return None
    method, _, steps = text.strip().partition(":")
    if method == "exact" and not steps:
        return EXACT
    if method == "raymarch" and steps.strip().isdecimal() and 1 <= int(steps) <= MAX_STEPS:
        return Reference("raymarch", int(steps))
    raise ClraysError(f"--reference {text}: expected exact or raymarch:N (N steps per ray, 1 to {MAX_STEPS}), "
                      f"got {text!r}")


def reference_scene(scene: Scene, reference: Reference) -> Scene:
    """The scene as the reference renders it: only the render settings it reads are kept
    (none for exact), so scenes that differ in nothing else share one reference."""
    if reference.method == "exact":
        return replace(scene, render=Render(method="exact"), source=None, animation=None)
    render = scene.render
    return replace(scene, render=Render(method="raymarch", steps=reference.steps, jitter=render.jitter,
                                        shadow_map=render.shadow_map, surface_shadows=render.surface_shadows,
                                        pcf=render.pcf), source=None, animation=None)


class ReferenceCache:
    """Reference radiance and depth-edge masks, as `.npy` files in `folder` (created on
    the first write) and the last few in memory; entries are never stale, because the
    key holds everything they are computed from.

    renderer: renders whole-frame references (default: a new session); they are
    rendered with `reuse=False`, so they neither use nor evict what the renderer keeps
    for the study's own frames. progress: a progress bar while a reference renders. An
    entry that cannot be read back (a corrupted file) is computed again and replaced.
    below: the folder the user named that `folder` lies in (a sweep's), when clrays makes
    `folder` itself (`.references`): then it must be a directory, not a link
    (clrays.outputs); None: `folder` is the user's (the cache)."""

    def __init__(self, folder: str | Path, renderer: Renderer | None = None, progress: bool = False,
                 memory_entries: int = 4, notice: Callable[[str], None] | None = None,
                 below: str | Path | None = None):
        self.folder = Path(folder)
        self.below = Path(below) if below is not None else self.folder
        self._check_folder()  # a link planted there is one line before anything is rendered
        #: Says, in one line, that a kept entry was unreadable and is computed again (default: stderr).
        self.notice = notice or _stderr_notice
        self.renderer = renderer or Renderer()
        self.progress = progress
        self._memory = StageCache(memory_entries)  # least recently used first out, per kind
        #: Host time of what the last `error` computed: reference_ms, edges_ms (absent: cached).
        self.last_ms: dict[str, float] = {}
        self._computed = False

    def radiance(self, scene: Scene, reference: Reference, pixels: Pixels | None = None) -> np.ndarray:
        """The reference's linear radiance of `scene`: (H, W, 3), or (N, 3) on `pixels`."""
        as_rendered = reference_scene(scene, reference)
        key = digest(reference, scene_digest(as_rendered), pixels)
        return self._cached(reference.name.replace(":", ""), key,
                            lambda: self._render(as_rendered, reference, pixels), _shape(scene, pixels) + (3,))

    def edges(self, scene: Scene, pixels: Pixels | None = None) -> np.ndarray:
        """Pixels at depth discontinuities: (H, W), or (N,) on `pixels`."""
        key = digest("edges", scene.camera, scene.image, scene.geometry.triangles, pixels)
        if pixels is None:
            return self._cached("edges", key, lambda: depth_edges(depth_map(scene)), _shape(scene, pixels))
        return self._cached("edges", key, lambda: depth_edges_at(scene, *pixels), _shape(scene, pixels))

    def error(self, scene: Scene, reference: Reference, image: np.ndarray, pixels: Pixels | None = None) -> ImageError:
        """`image_error` of a whole rendered frame (H, W, 3) against the reference, depth
        edges left out; on `pixels` only, when given."""
        if pixels is not None:
            image = image[pixels]
        self.last_ms = {}
        return image_error(image, self._timed("reference_ms", lambda: self.radiance(scene, reference, pixels)),
                           self._timed("edges_ms", lambda: self.edges(scene, pixels)))

    def _timed(self, label: str, get: Callable[[], np.ndarray]) -> np.ndarray:
        """`get()`, its time kept in `last_ms[label]` when it computed or loaded the entry."""
        start, self._computed = time.perf_counter(), False
        array = get()
        if self._computed:
            self.last_ms[label] = (time.perf_counter() - start) * 1e3
        return array

    def _render(self, scene: Scene, reference: Reference, pixels: Pixels | None) -> np.ndarray:
        if pixels is not None and reference.method == "exact":
            from ..reference.exact import exact_pixels

            return exact_pixels(scene, *pixels, progress=self.progress)
        image = self.renderer.render(scene, reuse=False, progress=self.progress).image
        return image if pixels is None else image[pixels]

    def _cached(self, kind: str, key: bytes, compute: Callable[[], np.ndarray], shape: tuple[int, ...]) -> np.ndarray:
        found, array = self._memory.get(kind, key)
        if found:
            return array
        self._computed = True
        path = self.folder / f"{kind}-{key.hex()[:24]}.npy"
        if self._check_folder():
            check_replaceable(path)
        array = self._load(path, shape) if os.path.lexists(path) else None
        if array is None:
            array = compute()
            make_folders_below(self.below, self.folder, "the reference folder")
            write_atomic(path, lambda temporary: np.save(temporary, array))
        self._memory.put(kind, key, array)
        return array

    def _check_folder(self) -> bool:
        """Whether `folder` is there; where it is, it must be a directory (not a link, where
        clrays makes it: clrays.outputs)."""
        if not os.path.lexists(self.folder):
            return False
        make_folders_below(self.below, self.folder, "the reference folder")
        return True

    def _load(self, path: Path, shape: tuple[int, ...]) -> np.ndarray | None:
        """A kept entry, or None (with a notice) when it cannot be what was written: not a
        regular file, not an .npy, or of another shape or type; it is then computed again
        and replaced."""
        try:
            data = read_regular_file(path, int(np.prod(shape)) * 8 + 4096,  # float64 at most, and the header
                                     follow_links=False)
            array = np.load(io.BytesIO(data), allow_pickle=False)
            if array.shape != shape or array.dtype.kind not in "fb" or not np.isfinite(array).all():
                raise ValueError(f"a {array.dtype} array of shape {array.shape}, expected {shape}")
            return array
        except (FileRefused, OSError, ValueError, EOFError) as exc:
            reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            self.notice(f"{path}: unreadable cached reference ({reason}); computing it again")
            return None


def _shape(scene: Scene, pixels: Pixels | None) -> tuple[int, ...]:
    """The shape of a reference entry without its channels: the image's, or the pixels'."""
    return (scene.image.height, scene.image.width) if pixels is None else (len(pixels[0]),)


def _stderr_notice(line: str) -> None:
    print(f"clrays: notice: {line}", file=sys.stderr)
