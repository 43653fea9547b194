"""Density grids from files and noise (clrays/scene/density_sources.py): each loader on real
files, the header checks that refuse a grid before allocating it, bad values, and the
optional extras' one-line errors when they are missing.

The .vdb files in tests/scene/data were written by libopenvdb 12.0 (tests/scene/data/
make_vdb_files.py says how), so the reader is tested on files it did not write.
"""
from __future__ import annotations

import io
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from clrays.errors import SceneError
from clrays.scene.density_sources import (GRID_VOXELS_MAX, NOISE_CONTRAST, bake_noise, check_grid,
                                          load_grid_file)
from clrays.scene.model import Box

DATA = Path(__file__).parent / "data"
WHERE = "scenes/smoke.yaml: medium.density.file"
NOISE_WHERE = "scenes/smoke.yaml: medium.density"


def refused(call, match: str) -> str:
    """The one line SceneError says for `call()`, which must match `match` and name the field."""
    with pytest.raises(SceneError, match=match) as info:
        call()
    message = str(info.value)
    assert "\n" not in message, message
    assert message.startswith("scenes/smoke.yaml: medium.density"), message
    return message


def save_npy(path: Path, array) -> Path:
    np.save(path, array, allow_pickle=False)
    return path


def npy_claiming(path: Path, shape, dtype="<f4") -> Path:
    """A .npy file whose header claims `shape` but holds 16 bytes of data."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": dtype, "fortran_order": False, "shape": tuple(shape)})
    path.write_bytes(header.getvalue() + bytes(16))  # the header writer writes the magic too
    return path


#: What a refusal "before allocating" may allocate: the file's 1 MiB read buffer and change,
#: where the grids refused here would take terabytes.
SMALL_BYTES = 8 << 20


def peak_allocation(call) -> int:
    """Bytes allocated at the peak while `call()` raises SceneError."""
    tracemalloc.start()
    try:
        with pytest.raises(SceneError):
            call()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


# --------------------------------------------------------------------------- .npy


def test_a_float32_npy_reads_as_the_same_bits(tmp_path):
    values = np.random.default_rng(1).random((3, 4, 5), dtype=np.float32)
    grid = load_grid_file(save_npy(tmp_path / "g.npy", values), WHERE)
    assert grid.dtype == np.float32 and grid.flags.c_contiguous and grid.flags.writeable
    assert grid.tobytes() == values.tobytes()


@pytest.mark.parametrize("dtype", ["<f2", ">f4", "<f8", "<i2", "<u1", "|b1"])
def test_other_number_types_become_float32(tmp_path, dtype):
    values = (np.arange(24).reshape(2, 3, 4) % 7).astype(dtype)
    grid = load_grid_file(save_npy(tmp_path / "g.npy", values), WHERE)
    assert grid.dtype == np.float32 and grid.shape == (2, 3, 4)
    np.testing.assert_array_equal(grid, values.astype(np.float64))


def test_a_fortran_ordered_npy_keeps_its_indexing(tmp_path):
    values = np.asfortranarray(np.arange(60, dtype=np.float32).reshape(3, 4, 5))
    grid = load_grid_file(save_npy(tmp_path / "g.npy", values), WHERE)
    assert grid.flags.c_contiguous
    np.testing.assert_array_equal(grid, values)


def test_a_header_claiming_a_trillion_voxels_is_refused_before_allocating(tmp_path):
    path = npy_claiming(tmp_path / "huge.npy", (10_000, 10_000, 10_000))
    message = refused(lambda: load_grid_file(path, WHERE),
                      f"expected at most {GRID_VOXELS_MAX} voxels, got 1000000000000")
    assert "10000 × 10000 × 10000" in message
    assert peak_allocation(lambda: load_grid_file(path, WHERE)) < SMALL_BYTES


def test_one_voxel_over_the_cap_is_refused(tmp_path):
    refused(lambda: load_grid_file(npy_claiming(tmp_path / "g.npy", (256, 256, 257)), WHERE),
            r"expected at most 16777216 voxels, got 16842752 \(256 × 256 × 257\)")


def test_a_header_claiming_more_data_than_the_file_holds_is_refused(tmp_path):
    refused(lambda: load_grid_file(npy_claiming(tmp_path / "g.npy", (8, 8, 8)), WHERE),
            "claims 8 × 8 × 8 of float32 .* but the file holds 16 bytes")


@pytest.mark.parametrize("shape, match", [((4, 4), r"expected a 3D grid \(axes z, y, x\), got shape \(4, 4\)"),
                                          ((2, 2, 2, 2), r"expected a 3D grid .*, got shape \(2, 2, 2, 2\)"),
                                          ((3, 0, 2), r"expected at least one voxel along each axis, got shape \(3, 0, 2\)")])
def test_an_npy_that_is_no_grid_is_refused(tmp_path, shape, match):
    refused(lambda: load_grid_file(save_npy(tmp_path / "g.npy", np.zeros(shape, np.float32)), WHERE), match)


def test_objects_and_complex_numbers_are_refused(tmp_path):
    pickled = tmp_path / "objects.npy"
    np.save(pickled, np.array([[[{"a": 1}]]], dtype=object), allow_pickle=True)
    refused(lambda: load_grid_file(pickled, WHERE), "expected an array of numbers, got dtype object")
    refused(lambda: load_grid_file(save_npy(tmp_path / "c.npy", np.zeros((2, 2, 2), np.complex64)), WHERE),
            "expected an array of numbers, got dtype complex64")


def test_a_file_that_is_not_an_npy_is_refused(tmp_path):
    path = tmp_path / "g.npy"
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(100))
    refused(lambda: load_grid_file(path, WHERE), r"expected a \.npy array, got a file that is not one")


def test_a_missing_file_and_an_unknown_extension_are_one_line(tmp_path):
    message = refused(lambda: load_grid_file(tmp_path / "nowhere.npy", WHERE), "No such file")
    assert "nowhere.npy" in message
    refused(lambda: load_grid_file(tmp_path / "g.raw", WHERE), r"expected a \.npy or \.vdb file, got a \.raw file")


def test_nanovdb_is_refused_with_what_to_do(tmp_path):
    refused(lambda: load_grid_file(tmp_path / "g.nvdb", WHERE), r"got a NanoVDB \(\.nvdb\) file, which clrays does not read: convert")


# --------------------------------------------------------------------------- bad values


def test_nan_and_infinity_give_their_count_and_first_index(tmp_path):
    values = np.ones((3, 4, 5), np.float32)
    values[1, 2, 3] = np.nan
    values[2, 0, 0] = np.inf
    refused(lambda: load_grid_file(save_npy(tmp_path / "g.npy", values), WHERE),
            r"expected finite densities, got 2 NaN or infinite, the first nan at \[z, y, x\] = \[1, 2, 3\]")


def test_negative_density_is_refused(tmp_path):
    values = np.ones((3, 4, 5))
    values[0, 3, 1] = -0.25
    refused(lambda: load_grid_file(save_npy(tmp_path / "g.npy", values), WHERE),
            r"expected densities ≥ 0, got -0.25 at \[z, y, x\] = \[0, 3, 1\] \(1 negative in all\)")


def test_a_float64_value_beyond_float32_is_refused():
    refused(lambda: check_grid(np.full((1, 1, 2), 1e39), WHERE),
            r"expected densities within float32 \(≤ 3.4e\+38\), got 1e\+39")


def test_check_grid_refuses_a_grid_over_the_cap_before_converting_it():
    # A broadcast view: 256 × 256 × 257 voxels that take 8 bytes of memory.
    view = np.broadcast_to(np.float64(1.0), (256, 256, 257))
    assert peak_allocation(lambda: check_grid(view, WHERE)) < SMALL_BYTES


def test_check_grid_returns_float32_c_contiguous():
    values = np.arange(24, dtype=np.float64).reshape(2, 3, 4)[:, ::-1, :]
    grid = check_grid(values, WHERE)
    assert grid.dtype == np.float32 and grid.flags.c_contiguous
    np.testing.assert_array_equal(grid, values)


# --------------------------------------------------------------------------- .vdb


def test_an_openvdb_density_grid_is_densified_over_its_active_voxels():
    pytest.importorskip("tinyvdb")
    grid = load_grid_file(DATA / "density.vdb", WHERE)  # beside a `temperature` grid: the one named density
    expected = np.load(DATA / "density_expected.npy")
    assert grid.dtype == np.float32 and grid.shape == (3, 4, 5)
    assert grid.tobytes() == expected.tobytes()


#: The index coordinates of density.vdb's voxels, [x, y, z] in x-major order (as its values
#: transposed to [x, y, z] and flattened).
DENSITY_XYZ = np.stack(np.meshgrid(np.arange(2, 7), np.arange(-1, 3), np.arange(3, 6), indexing="ij"), -1).reshape(-1, 3)


def rewritten_vdb(tmp_path, name: str, coords_xyz, values, grid_name="density") -> Path:
    """density.vdb with its density grid replaced by these voxels (and renamed `grid_name`),
    by tinyvdb's own writer."""
    tinyvdb = pytest.importorskip("tinyvdb")
    vdb_file = tinyvdb.open(str(DATA / "density.vdb"))
    vdb_file.read_grids()
    index = [vdb_file.grid_name(i) for i in range(vdb_file.grid_count)].index("density")
    vdb_file.replace_grid_from_sparse(index, np.asarray(coords_xyz, np.int32).tobytes(),
                                      np.asarray(values, np.float32).tobytes(), grid_name)
    path = tmp_path / name
    path.write_bytes(vdb_file.to_bytes())
    vdb_file.close()
    return path


def test_a_vdb_over_the_cap_is_refused_from_its_statistics_before_it_is_read(monkeypatch):
    tinyvdb = pytest.importorskip("tinyvdb")
    from clrays.scene import density_sources

    monkeypatch.setattr(density_sources, "GRID_VOXELS_MAX", 59)  # the density grid's box of 60 voxels, one too many
    monkeypatch.setattr(tinyvdb, "from_bytes", lambda data: pytest.fail("the file was read"))
    refused(lambda: load_grid_file(DATA / "density.vdb", WHERE), r"expected at most 59 voxels, got 60 \(3 × 4 × 5\)")


def test_a_vdb_of_too_many_active_voxels_in_all_its_grids_is_refused_before_it_is_read(monkeypatch):
    tinyvdb = pytest.importorskip("tinyvdb")
    from clrays.scene import density_sources

    monkeypatch.setattr(density_sources, "VDB_ACTIVE_VOXELS_MAX", 63)  # density's 60 and temperature's 4
    monkeypatch.setattr(tinyvdb, "from_bytes", lambda data: pytest.fail("the file was read"))
    refused(lambda: load_grid_file(DATA / "density.vdb", WHERE),
            r"expected at most 63 active voxels in all the file's grids, got 64 in 2 grids")


def test_a_vdb_without_statistics_over_the_cap_is_refused_from_what_was_read(tmp_path, monkeypatch):
    """tinyvdb's writer leaves out OpenVDB's statistics: the counts come from the grid read."""
    from clrays.scene import density_sources

    path = rewritten_vdb(tmp_path, "plain.vdb", DENSITY_XYZ, np.ones(len(DENSITY_XYZ)))
    assert load_grid_file(path, WHERE).shape == (3, 4, 5)
    monkeypatch.setattr(density_sources, "GRID_VOXELS_MAX", 59)
    refused(lambda: load_grid_file(path, WHERE), "expected at most 59 voxels, got 60 active voxels")


def test_two_vdb_voxels_far_apart_are_refused_before_densifying(tmp_path):
    path = rewritten_vdb(tmp_path, "far.vdb", [[0, 0, 0], [1000, 1000, 1000]], [1.0, 1.0])
    message = refused(lambda: load_grid_file(path, WHERE), r"expected at most \d+ voxels, got 1003003001 \(1001 × 1001 × 1001\)")
    assert peak_allocation(lambda: load_grid_file(path, WHERE)) < SMALL_BYTES, message


def test_a_vdb_with_nan_is_refused(tmp_path):
    values = np.load(DATA / "density_expected.npy").transpose(2, 1, 0).ravel()  # [x, y, z] order, as the coordinates
    values[7] = np.nan
    path = rewritten_vdb(tmp_path, "nan.vdb", DENSITY_XYZ, values)
    refused(lambda: load_grid_file(path, WHERE), r"expected finite densities, got 1 NaN or infinite, the first nan")


def test_a_vdb_of_two_float_grids_none_named_density_is_refused(tmp_path):
    path = rewritten_vdb(tmp_path, "smoke.vdb", [[0, 0, 0]], [1.0], grid_name="smoke")
    refused(lambda: load_grid_file(path, WHERE), r"expected a float grid named `density` or a single float grid, "
                                                 r"got temperature \(Tree_float_5_4_3\), smoke \(Tree_float_5_4_3\)")


def test_vdb_tiles_and_level_sets_are_refused():
    pytest.importorskip("tinyvdb")
    refused(lambda: load_grid_file(DATA / "tiles.vdb", WHERE), "got 512 active voxels, 512 of them in tiles")
    refused(lambda: load_grid_file(DATA / "level_set.vdb", WHERE), "expected a fog volume of densities, got grid `surface`, a level set")


def test_a_broken_vdb_is_one_line(tmp_path):
    pytest.importorskip("tinyvdb")
    path = tmp_path / "g.vdb"
    path.write_bytes((DATA / "density.vdb").read_bytes()[:200])
    refused(lambda: load_grid_file(path, WHERE), "expected an OpenVDB file, got one that cannot be read")
    path.write_bytes(b"not a vdb at all")
    refused(lambda: load_grid_file(path, WHERE), "expected an OpenVDB file, got one that cannot be read")


def test_a_vdb_without_the_extra_names_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "tinyvdb", None)  # as if not installed: importing it raises ImportError
    refused(lambda: load_grid_file(DATA / "density.vdb", WHERE),
            r"reading \.vdb files needs the `vdb` extra: pip install 'clrays\[vdb\]'")


# --------------------------------------------------------------------------- noise

BOX = Box(np.array([0.0, 0.0, 0.0]), np.array([8.0, 4.0, 2.0]))


def noise(**changes):
    arguments = dict(frequency=0.7, octaves=4, seed=11, offset=(0.0, 0.0, 0.0), bounds=BOX,
                     resolution=(16, 8, 4), where=NOISE_WHERE)
    arguments.update(changes)
    return bake_noise(**arguments)


def test_noise_is_a_float32_grid_of_resolution_x_y_z():
    pytest.importorskip("pyfastnoiselite")
    grid = noise()
    assert grid.dtype == np.float32 and grid.shape == (4, 8, 16) and grid.flags.c_contiguous
    assert grid.min() >= 0.0 and np.isfinite(grid).all()
    assert grid.std() > 0.1  # a pattern, not a constant
    assert grid.max() <= 1.0 + NOISE_CONTRAST


def test_the_same_seed_gives_the_same_bits_and_another_seed_another_pattern():
    pytest.importorskip("pyfastnoiselite")
    assert noise().tobytes() == noise().tobytes()
    assert not np.array_equal(noise(), noise(seed=12))


def test_an_offset_moves_the_pattern_by_as_much():
    pytest.importorskip("pyfastnoiselite")
    # Voxels of 0.5 units along x: an offset of one voxel moves the pattern one voxel along +x.
    still, moved = noise(), noise(offset=(0.5, 0.0, 0.0))
    assert moved[:, :, 1:].tobytes() == still[:, :, :-1].tobytes()
    assert not np.array_equal(moved, still)
    up = noise(offset=(0.0, 0.5, 0.0))  # 8 voxels over 4 units along y
    assert up[:, 1:, :].tobytes() == still[:, :-1, :].tobytes()


def test_noise_in_slabs_is_the_same_as_in_one_piece(monkeypatch):
    pytest.importorskip("pyfastnoiselite")
    from clrays.scene import density_sources

    whole = noise()
    monkeypatch.setattr(density_sources, "_NOISE_CHUNK_VOXELS", 16 * 8)  # one z slice a slab
    assert noise().tobytes() == whole.tobytes()


@pytest.mark.parametrize("changes, match", [
    (dict(frequency=0.0), r"medium.density.frequency: expected a number > 0, got 0"),
    (dict(frequency=float("nan")), r"medium.density.frequency: expected a finite number"),
    (dict(octaves=0), r"medium.density.octaves: expected an integer in \[1, 16\], got 0"),
    (dict(octaves=2.5), r"medium.density.octaves: expected an integer"),
    (dict(seed=2**31), r"medium.density.seed: expected an integer in"),
    (dict(offset=(0, 1)), r"medium.density.offset: expected three values"),
    (dict(offset=(0, float("inf"), 0)), r"medium.density.offset: expected a finite number"),
    (dict(resolution=(16, 0, 4)), r"medium.density.resolution: expected integers ≥ 1, got \[16, 0, 4\]"),
    (dict(bounds=Box(np.zeros(3), np.array([1.0, -1.0, 1.0]))), r"medium.density.bounds: expected max ≥ min on every axis, got y: min 0, max -1"),
    (dict(bounds=Box(np.zeros(3), np.array([1.0, np.nan, 1.0]))), r"medium.density.bounds: expected a finite number"),
    (dict(resolution=(16, 8.5, 4)), r"medium.density.resolution: expected three integers"),
])
def test_bad_noise_settings_are_one_line(changes, match):
    refused(lambda: noise(**changes), match)


def test_a_noise_resolution_over_the_cap_is_refused_before_allocating():
    call = lambda: noise(resolution=(100_000, 200_000, 300_000))  # (x, y, z), as written
    refused(call, r"resolution: expected at most \d+ voxels, got 6000000000000000 \(100000 × 200000 × 300000\)")
    assert peak_allocation(call) < SMALL_BYTES


def test_noise_without_the_extra_names_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyfastnoiselite.pyfastnoiselite", None)
    refused(noise, r"noise needs the `noise` extra: pip install 'clrays\[noise\]'")
