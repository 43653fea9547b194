"""Where a medium's density grid comes from (`medium.density: {type: grid}` and `{type: noise}`,
docs/scene-format.md): a file read into a checked float32 (nz, ny, nx) array, or procedural
noise baked to one. Every failure is one line that starts with `where`, the file and field."""
from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import ClraysError
from .files import FileRefused, read_regular_file
from .model import Box

#: The most voxels a density grid may have (64 MiB of float32), counted before reading it.
GRID_VOXELS_MAX = 1 << 24
#: The largest grid file read: GRID_VOXELS_MAX float64 voxels and a header.
GRID_FILE_BYTES = 8 * GRID_VOXELS_MAX + (1 << 16)


def check_grid(values: np.ndarray, where: str) -> np.ndarray:
    """`values` as a float32 C-contiguous (nz, ny, nx) grid: 3 axes, at most GRID_VOXELS_MAX
    voxels, finite and ≥ 0; else a ClraysError naming `where`."""
    if values.ndim != 3 or min(values.shape) < 1:
        raise ClraysError(f"{where}: expected a 3D grid (axes z, y, x), got shape {values.shape}")
    if values.size > GRID_VOXELS_MAX:
        raise ClraysError(f"{where}: expected at most {GRID_VOXELS_MAX} voxels, got {values.size} "
                          f"({' × '.join(map(str, values.shape))})")
    grid = np.ascontiguousarray(values, dtype=np.float32)
    if not np.isfinite(grid).all():
        raise ClraysError(f"{where}: expected finite densities, got {int((~np.isfinite(grid)).sum())} NaN or infinite")
    if (grid < 0).any():
        raise ClraysError(f"{where}: expected densities ≥ 0, got {float(grid.min()):g}")
    return grid


def load_grid_file(path: Path, where: str) -> np.ndarray:
    """The density grid in `path` (a `.npy` of axes z, y, x), checked by `check_grid`: a
    regular file (clrays.scene.files: no device or FIFO, confined with the scene's files) of
    at most GRID_FILE_BYTES, its voxels counted from its header before the array is read."""
    path = Path(path)
    if path.suffix.lower() != ".npy":
        raise ClraysError(f"{where}: expected a .npy grid, got {path.name!r}")
    try:
        data = io.BytesIO(read_regular_file(path, GRID_FILE_BYTES, "a grid of at most "
                                                                   f"{GRID_VOXELS_MAX} float64 voxels"))
        version = np.lib.format.read_magic(data)
        read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else \
            np.lib.format.read_array_header_2_0
        shape, _, _ = read_header(data)
        if len(shape) == 3 and math.prod(shape) > GRID_VOXELS_MAX:
            raise ClraysError(f"{where}: expected at most {GRID_VOXELS_MAX} voxels, got {math.prod(shape)} "
                              f"({' × '.join(map(str, shape))})")
        data.seek(0)
        values = np.load(data, allow_pickle=False)
    except FileRefused as error:
        raise ClraysError(f"{where}: {path}: {error}") from None
    except (ValueError, EOFError) as error:
        raise ClraysError(f"{where}: cannot read {path} as .npy: {error}") from None
    return check_grid(values, where)


def bake_noise(frequency: float, octaves: int, seed: int, offset: Sequence[float], bounds: Box,
               resolution: Sequence[int], where: str) -> np.ndarray:
    """Procedural fBm noise over `bounds`, baked to a (nz, ny, nx) grid of `resolution` (x, y, z)."""
    raise ClraysError(f"{where}: noise needs the `noise` extra (pip install 'clrays[noise]')")


__all__ = ["GRID_VOXELS_MAX", "check_grid", "load_grid_file", "bake_noise"]
