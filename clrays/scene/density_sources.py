"""Where a medium's density grid comes from (`medium.density: {type: grid}` and `{type: noise}`,
docs/scene-format.md): a file read into a checked float32 (nz, ny, nx) array, or procedural
noise baked to one. Every failure is one line that starts with `where`, the file and field."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import ClraysError
from .model import Box

#: The most voxels a density grid may have (64 MiB of float32), counted before reading it.
GRID_VOXELS_MAX = 1 << 24


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
    """The density grid in `path` (a `.npy` of axes z, y, x), checked by `check_grid`."""
    path = Path(path)
    if path.suffix.lower() != ".npy":
        raise ClraysError(f"{where}: expected a .npy grid, got {path.name!r}")
    try:
        values = np.load(path, mmap_mode="r", allow_pickle=False)  # the header only, until checked
    except (OSError, ValueError) as error:
        raise ClraysError(f"{where}: cannot read {path}: {error}") from None
    if values.ndim == 3 and values.size > GRID_VOXELS_MAX:
        raise ClraysError(f"{where}: expected at most {GRID_VOXELS_MAX} voxels, got {values.size}")
    return check_grid(np.asarray(values), where)


def bake_noise(frequency: float, octaves: int, seed: int, offset: Sequence[float], bounds: Box,
               resolution: Sequence[int], where: str) -> np.ndarray:
    """Procedural fBm noise over `bounds`, baked to a (nz, ny, nx) grid of `resolution` (x, y, z)."""
    raise ClraysError(f"{where}: noise needs the `noise` extra (pip install 'clrays[noise]')")


__all__ = ["GRID_VOXELS_MAX", "check_grid", "load_grid_file", "bake_noise"]
