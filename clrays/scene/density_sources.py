"""Where a medium's density grid comes from (docs/density-sources.md): a file, or procedural
noise baked to a grid. Each returns the grid's density factors as float32 of shape
(nz, ny, nx), C-contiguous, finite and ≥ 0, for `model.GridDensity.values`.

    values = load_grid_file(Path("smoke.npy"), "scenes/smoke.yaml: medium.density.file")
    values = bake_noise(0.5, 5, 7, (0, 0, 0), box, (64, 32, 64), "scenes/x.yaml: medium.density")

- `.npy`: a 3D array indexed [z, y, x] of floats (16, 32 or 64 bits), integers or booleans;
  its shape and dtype are read from the header and checked before the data is (no pickles).
- `.vdb`: OpenVDB, through tinyvdb (the `vdb` extra, imported only here); the float grid
  named `density` (or the file's one float grid), its active voxels densified over their
  bounding box.
- noise: OpenSimplex2 fBm through pyfastnoiselite (the `noise` extra), mapped to
  max(0, 1 + 3·fbm).

Every problem raises SceneError with one line that starts with `where` (the file and field)
and names the bad value; sizes are checked against GRID_VOXELS_MAX before anything of that
size is allocated.
"""
from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import SceneError
from .files import FileRefused, read_regular_file
from .image_files import ImageFileError, npy_header
from .model import Box

#: The largest grid accepted, in voxels: 256³, 64 MiB as float32 (the device holds it and a
#: per-light optical-depth grid beside it; docs/limits.md).
GRID_VOXELS_MAX = 256 ** 3
#: The largest grid file read: a float64 `.npy` at GRID_VOXELS_MAX, with room for its header.
#: A `.vdb` holds its active voxels (4 bytes each, less compressed) and its tree's masks.
MAX_GRID_FILE_BYTES = GRID_VOXELS_MAX * 8 + (1 << 20)
GRID_FORMATS = (".npy", ".vdb")
#: Active voxels in all the grids of a `.vdb` (its density and the temperature, velocity or
#: flame grids a simulation cache holds beside it), from its statistics, before it is read:
#: tinyvdb reads every grid of the file.
VDB_ACTIVE_VOXELS_MAX = 4 * GRID_VOXELS_MAX
#: OpenVDB's name for a FloatGrid's tree (a half-float grid is saved under the same name).
_VDB_FLOAT_GRID = "Tree_float_5_4_3"
#: Octaves of fBm: each halves the feature size (lacunarity 2); past 16 they are finer than
#: float32 coordinates resolve, and each costs a full pass over the grid.
MAX_NOISE_OCTAVES = 16
#: Noise is evaluated in slabs of this many voxels, so its float32 coordinates (12 bytes a
#: voxel, twice: the axes' grids and their stack) stay under 100 MiB whatever the grid's size.
_NOISE_CHUNK_VOXELS = 1 << 22
#: density = max(0, 1 + NOISE_CONTRAST·fbm): fbm (normalised to [-1, 1], standard deviation
#: about 0.26 at 5 octaves) around a mean density of 1, so σs and σa keep their meaning as
#: the medium's mean coefficients, with wisps up to ~3.6 and about a tenth of the box clear
#: (docs/density-sources.md).
NOISE_CONTRAST = 3.0


def check_grid(values, where: str) -> np.ndarray:
    """`values` as a density grid: float32 (nz, ny, nx), C-contiguous.

    Raises SceneError (one line starting with `where`) for an array that is not numbers,
    not 3D or empty, larger than GRID_VOXELS_MAX (checked before it is converted), or that
    holds NaN or infinite values (their count and the first one's [z, y, x] index),
    negative values, or values beyond float32."""
    grid = np.asarray(values)
    if grid.dtype.kind not in "biuf" or grid.dtype.fields is not None:
        raise SceneError(f"{where}: expected an array of numbers, got dtype {grid.dtype}")
    _check_shape(grid.shape, where)
    bad = ~np.isfinite(grid)
    if bad.any():
        first = _index(np.argwhere(bad)[0])
        raise SceneError(f"{where}: expected finite densities, got {int(bad.sum())} NaN or infinite, the first "
                         f"{grid[first]} at [z, y, x] = {list(first)}")
    negative = grid < 0
    if negative.any():
        first = _index(np.argwhere(negative)[0])
        raise SceneError(f"{where}: expected densities ≥ 0, got {grid[first]:g} at [z, y, x] = {list(first)} "
                         f"({int(negative.sum())} negative in all)")
    if grid.dtype.itemsize > 4 and float(grid.max()) > float(np.finfo(np.float32).max):
        raise SceneError(f"{where}: expected densities within float32 (≤ {np.finfo(np.float32).max:.3g}), "
                         f"got {float(grid.max()):g}")
    return np.ascontiguousarray(grid, dtype=np.float32)


def load_grid_file(path: Path, where: str) -> np.ndarray:
    """The density grid in a `.npy` or `.vdb` file (module docstring), through `check_grid`.

    Raises SceneError (one line starting with `where`) for a missing, unreadable or
    oversized file (MAX_GRID_FILE_BYTES), an unknown extension, a broken header, a grid over
    GRID_VOXELS_MAX voxels (from the header, before the data is read), bad values, and a
    `.vdb` without the `vdb` extra installed."""
    suffix = Path(path).suffix.lower()
    if suffix == ".nvdb":
        # tinyvdb's Python API reads NanoVDB voxels one call at a time and cannot list a
        # grid's active voxels, so a NanoVDB grid could not be densified in reasonable time.
        raise SceneError(f"{where}: expected a .npy or .vdb file, got a NanoVDB (.nvdb) file, which clrays does "
                         f"not read: convert it to OpenVDB (nanovdb_convert file.nvdb file.vdb) or to .npy")
    if suffix not in GRID_FORMATS:
        raise SceneError(f"{where}: expected a .npy or .vdb file, got a {suffix or 'file without an extension'} "
                         f"file")
    try:
        data = read_regular_file(path, MAX_GRID_FILE_BYTES,
                                 too_big_hint=f"a density grid holds at most {GRID_VOXELS_MAX} voxels")
    except FileRefused as exc:
        raise SceneError(f"{where}: {path}: {exc}") from None
    grid = check_grid(_npy_grid(data, where) if suffix == ".npy" else _vdb_grid(data, where), where)
    # A float32 .npy comes back as a view of the file's bytes, read-only: the scene owns its own.
    return grid if grid.flags.writeable else grid.copy()


def bake_noise(frequency: float, octaves: int, seed: int, offset: Sequence[float], bounds: Box,
               resolution: Sequence[int], where: str) -> np.ndarray:
    """Procedural fBm density over `bounds`, baked to a grid float32 (nz, ny, nx) ≥ 0.

    frequency: noise cells per scene unit (> 0). octaves: fBm octaves in [1, 16], each of
    twice the frequency and half the amplitude of the one before. seed: an integer that
    fits in 32 bits; the same seed gives the same bits. offset: (x, y, z) in scene units,
    how far the pattern has moved: the density at p is that of p − offset, so animating
    offset makes the fog drift by it. bounds: the box the grid covers. resolution: voxels
    along (x, y, z), as the box's corners are written; each voxel is sampled at its centre.
    The density is max(0, 1 + NOISE_CONTRAST·fbm) (module docstring). Needs the `noise`
    extra (pyfastnoiselite)."""
    shape_xyz = _noise_resolution(resolution, where)
    frequency = _finite(frequency, f"{where}.frequency")
    if frequency <= 0:
        raise SceneError(f"{where}.frequency: expected a number > 0, got {frequency:g}")
    if isinstance(octaves, bool) or not isinstance(octaves, (int, np.integer)) \
            or not 1 <= octaves <= MAX_NOISE_OCTAVES:
        raise SceneError(f"{where}.octaves: expected an integer in [1, {MAX_NOISE_OCTAVES}], got {_shown(octaves)}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not -2**31 <= seed < 2**31:
        raise SceneError(f"{where}.seed: expected an integer in [-2³¹, 2³¹), got {_shown(seed)}")
    shift = np.array([_finite(v, f"{where}.offset") for v in _three(offset, f"{where}.offset")])
    low, high = (np.array([_finite(v, f"{where}.bounds") for v in _three(corner, f"{where}.bounds")])
                 for corner in (bounds.min, bounds.max))
    if (low > high).any():
        axis = int(np.argmax(low > high))
        raise SceneError(f"{where}.bounds: expected max ≥ min on every axis, got {'xyz'[axis]}: min "
                         f"{low[axis]:g}, max {high[axis]:g}")
    fast_noise = _import_extra("pyfastnoiselite.pyfastnoiselite", "noise", "noise", where)

    noise = fast_noise.FastNoiseLite(seed=int(seed))
    noise.noise_type = fast_noise.NoiseType.NoiseType_OpenSimplex2
    noise.fractal_type = fast_noise.FractalType.FractalType_FBm
    noise.fractal_octaves = int(octaves)
    noise.frequency = 1.0  # coordinates go in already scaled, in float64 before they are rounded to float32
    nx, ny, nz = shape_xyz
    # Voxel centres, moved back by the offset and scaled to noise cells, per axis.
    axes = [(((low[axis] + (np.arange(n) + 0.5) * (high[axis] - low[axis]) / n) - shift[axis]) * frequency)
            .astype(np.float32) for axis, n in enumerate(shape_xyz)]
    values = np.empty(nz * ny * nx, dtype=np.float32)
    slab = max(1, _NOISE_CHUNK_VOXELS // (ny * nx))
    for z0 in range(0, nz, slab):
        z, y, x = np.meshgrid(axes[2][z0:z0 + slab], axes[1], axes[0], indexing="ij")
        coords = np.stack([x.ravel(), y.ravel(), z.ravel()])
        values[z0 * ny * nx:z0 * ny * nx + coords.shape[1]] = noise.gen_from_coords(coords)
    np.maximum(1.0 + NOISE_CONTRAST * values, 0.0, out=values)
    return values.reshape(nz, ny, nx)


# --------------------------------------------------------------------------- .npy

def _npy_grid(data: bytes, where: str) -> np.ndarray:
    """A `.npy` file's array, its shape and dtype checked from the header before the data is
    read, then viewed in place (no copy but the caller's float32 one)."""
    from numpy.lib import format as npy_format

    stream = io.BytesIO(data)
    try:  # the header alone first: a grid too large is refused before its size is compared with the file's
        version = npy_format.read_magic(stream)
        read_header = npy_format.read_array_header_1_0 if version == (1, 0) else npy_format.read_array_header_2_0
        shape, fortran_order, dtype = read_header(stream)
    except (ValueError, SyntaxError, TypeError, EOFError) as exc:
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SceneError(f"{where}: expected a .npy array, got a file that is not one ({detail[:120]})") from None
    if dtype.hasobject or dtype.kind not in "biuf" or dtype.fields is not None:
        raise SceneError(f"{where}: expected an array of numbers, got dtype {dtype}")
    _check_shape(shape, where)
    try:
        shape, dtype, data_offset = npy_header(data)  # and the data's size against the file's
    except ImageFileError as exc:
        raise SceneError(f"{where}: {exc}") from None
    flat = np.frombuffer(data, dtype=dtype, count=math.prod(shape), offset=data_offset)
    return flat.reshape(shape, order="F" if fortran_order else "C")


# --------------------------------------------------------------------------- .vdb

def _vdb_grid(data: bytes, where: str) -> np.ndarray:
    """The density grid of an OpenVDB file: the float grid named `density`, or the file's
    one float grid; its active voxels, densified over their bounding box to [z, y, x]
    (inactive voxels inside it are 0). The grid's transform is not used: the scene's
    `bounds` place it."""
    tinyvdb = _import_extra("tinyvdb", "vdb", "reading .vdb files", where)
    _check_vdb_header(data, where)
    try:
        vdb_file = tinyvdb.from_bytes(data)
        try:
            vdb_file.read_grids()
            grid = _density_grid(vdb_file, where)
            active = int(grid.active_voxel_count())
            if active > GRID_VOXELS_MAX:  # they could not fit the dense grid: refused before they are listed
                raise SceneError(f"{where}: expected at most {GRID_VOXELS_MAX} voxels, got {active} active "
                                 f"voxels")
            sparse = grid.to_sparse()
            stored = grid.metadata.get("file_voxel_count")
        finally:
            vdb_file.close()
    except (tinyvdb.VDBError, OSError, ValueError) as exc:
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SceneError(f"{where}: expected an OpenVDB file, got one that cannot be read ({detail[:120]})") \
            from None
    count = int(sparse["count"])
    if stored is not None and int(stored) > count:
        raise SceneError(f"{where}: expected every active value stored as a voxel, got {int(stored)} active voxels, "
                         f"{int(stored) - count} of them in tiles, which are not read: voxelize the grid's active "
                         f"tiles before saving it")
    if count == 0:
        raise SceneError(f"{where}: expected a grid with active voxels, got none")
    xyz = np.frombuffer(sparse["coords"], dtype=np.int32).reshape(count, 3).astype(np.int64)
    low = xyz.min(axis=0)
    shape_zyx = tuple(int(n) for n in (xyz.max(axis=0) - low + 1)[::-1])
    _check_shape(shape_zyx, where)
    values = np.frombuffer(sparse["values"], dtype=np.float32, count=count)
    grid_zyx = np.zeros(shape_zyx, dtype=np.float32)
    index = xyz - low
    grid_zyx[index[:, 2], index[:, 1], index[:, 0]] = values
    return grid_zyx


def _density_grid(vdb_file, where: str):
    """The grid a `.vdb` file's density is read from (`_density_index`); a fog volume, not a
    level set."""
    names = [vdb_file.grid_name(i) for i in range(vdb_file.grid_count)]
    index = _density_index(names, [vdb_file.grid_type_name(i) for i in range(vdb_file.grid_count)], where)
    grid = vdb_file.grid(index)
    if grid.metadata.get("class") == "level set":
        raise SceneError(f"{where}: expected a fog volume of densities, got grid `{names[index]}`, a level set "
                         f"(signed distances)")
    return grid


def _density_index(names: list[str], types: list[str], where: str) -> int:
    """Which of a `.vdb` file's grids holds the density: its float grid named `density`, or
    its only float grid."""
    floats = [i for i, grid_type in enumerate(types) if grid_type == _VDB_FLOAT_GRID]
    chosen = [i for i in floats if names[i] == "density"] or (floats if len(floats) == 1 else [])
    if not chosen:
        found = ", ".join(f"{name} ({grid_type})" for name, grid_type in zip(names, types)) or "no grids"
        raise SceneError(f"{where}: expected a float grid named `density` or a single float grid, got {found}")
    return chosen[0]


def _check_vdb_header(data: bytes, where: str) -> None:
    """Refuse a `.vdb` whose own statistics say it is too large, before tinyvdb reads its
    trees: the density grid's bounding box over GRID_VOXELS_MAX voxels, or more than
    VDB_ACTIVE_VOXELS_MAX active voxels in all its grids. OpenVDB writes these statistics
    (`file_bbox_min`, `file_bbox_max`, `file_voxel_count`) in each grid's metadata; a file
    without them, or that does not parse as expected, is left to tinyvdb and the checks on
    what it read."""
    grids = _vdb_grid_statistics(data)
    if not grids:
        return
    names, types = [grid[0] for grid in grids], [grid[1] for grid in grids]
    total = sum(stats.get("file_voxel_count", 0) for _, _, stats in grids)
    if total > VDB_ACTIVE_VOXELS_MAX:
        raise SceneError(f"{where}: expected at most {VDB_ACTIVE_VOXELS_MAX} active voxels in all the file's grids, "
                         f"got {total} in {len(grids)} grids (save the density grid alone)")
    stats = grids[_density_index(names, types, where)][2]
    if "file_bbox_min" in stats and "file_bbox_max" in stats:
        extent = np.array(stats["file_bbox_max"], dtype=np.int64) - np.array(stats["file_bbox_min"], dtype=np.int64) + 1
        if (extent > 0).all():
            _check_shape(tuple(int(n) for n in extent[::-1]), where)


def _vdb_grid_statistics(data: bytes) -> list[tuple[str, str, dict]] | None:
    """(name, type, {file_voxel_count: int, file_bbox_min/max: (x, y, z)}) of each grid in an
    OpenVDB file, from its grid descriptors and metadata (format 222 and later, with grid
    offsets, as OpenVDB 3 and later write), or None where the file is not that."""
    import struct

    position = 0

    def take(count: int) -> bytes:
        nonlocal position
        if count < 0 or position + count > len(data):
            raise ValueError("past the end")
        position += count
        return data[position - count:position]

    def number(form: str):
        return struct.unpack("<" + form, take(struct.calcsize(form)))[0]

    def text() -> str:
        return take(number("I")).decode("latin-1")

    def metadata() -> dict[str, tuple[str, bytes]]:
        return {text(): (text(), take(number("I"))) for _ in range(number("i"))}

    try:
        if number("q") != 0x56444220 or number("I") < 222:
            return None
        take(8)  # the library's version
        if take(1) != b"\x01":  # no grid offsets: descriptors cannot be read without the trees
            return None
        take(36)  # the file's UUID
        metadata()
        grids = []
        for _ in range(number("i")):
            name, grid_type, _parent = text(), text(), text()
            grid_start, _, grid_end = number("q"), number("q"), number("q")
            position = grid_start
            take(4)  # the grid's compression flags
            stats = {}
            for key, (value_type, value) in metadata().items():
                if key == "file_voxel_count" and value_type == "int64" and len(value) == 8:
                    stats[key] = struct.unpack("<q", value)[0]
                elif key in ("file_bbox_min", "file_bbox_max") and value_type == "vec3i" and len(value) == 12:
                    stats[key] = struct.unpack("<3i", value)
            grids.append((name.split("\x1e")[0], grid_type.removesuffix("_HalfFloat"), stats))
            position = grid_end
        return grids
    except (ValueError, struct.error, UnicodeDecodeError):
        return None


# --------------------------------------------------------------------------- shared checks

def _check_shape(shape, where: str) -> None:
    """A grid's shape: 3D, no empty axis, at most GRID_VOXELS_MAX voxels (counted as Python
    integers, so a header's 10¹² cannot overflow)."""
    shape = tuple(int(n) for n in shape)
    if len(shape) != 3:
        raise SceneError(f"{where}: expected a 3D grid (axes z, y, x), got shape {shape}")
    if min(shape) < 1:
        raise SceneError(f"{where}: expected at least one voxel along each axis, got shape {shape}")
    _check_voxels(shape, where)


def _check_voxels(counts: Sequence[int], where: str) -> None:
    """At most GRID_VOXELS_MAX voxels, `counts` along the axes in the order the user wrote them."""
    voxels = math.prod(counts)
    if voxels > GRID_VOXELS_MAX:
        raise SceneError(f"{where}: expected at most {GRID_VOXELS_MAX} voxels, got {voxels} "
                         f"({' × '.join(map(str, counts))})")


def _noise_resolution(resolution, where: str) -> tuple[int, int, int]:
    """A noise grid's voxels along (x, y, z), checked against the limit before any allocation."""
    counts = _three(resolution, f"{where}.resolution")
    if not all(isinstance(n, (int, np.integer)) and not isinstance(n, bool) for n in counts):
        raise SceneError(f"{where}.resolution: expected three integers, got [{', '.join(map(_shown, counts))}]")
    nx, ny, nz = (int(n) for n in counts)
    if min(nx, ny, nz) < 1:
        raise SceneError(f"{where}.resolution: expected integers ≥ 1, got [{nx}, {ny}, {nz}]")
    _check_voxels((nx, ny, nz), f"{where}.resolution")
    return nx, ny, nz


def _three(values, where: str) -> tuple:
    try:
        items = tuple(values)
    except TypeError:
        items = ()
    if len(items) != 3:
        raise SceneError(f"{where}: expected three values (x, y, z), got {values!r}")
    return items


def _finite(value, where: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise SceneError(f"{where}: expected a number, got {value!r}") from None
    if not math.isfinite(number):
        raise SceneError(f"{where}: expected a finite number, got {number}")
    return number


def _shown(value) -> str:
    """A value as the user wrote it: numbers plainly (numpy's repr says np.int64(40)), anything else quoted."""
    return str(value) if isinstance(value, (int, float, np.number)) else repr(value)


def _index(index) -> tuple[int, ...]:
    return tuple(int(i) for i in index)


def _import_extra(module: str, extra: str, purpose: str, where: str):
    """An optional dependency, imported only when a scene needs it; one line naming the
    extra that installs it when it is missing."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise SceneError(f"{where}: {purpose} needs the `{extra}` extra: pip install 'clrays[{extra}]'") from None
