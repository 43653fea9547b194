"""Writes the OpenVDB files that tests/scene/test_density_sources.py reads, with libopenvdb's
own writer (the `openvdb` Python module that Blender 4.5 bundles, libopenvdb 12.0), so that
clrays' reader is tested on files it did not write. Not run by the tests; to regenerate:

    BPY=/path/to/site-packages/bpy
    LD_LIBRARY_PATH=$BPY/lib PYTHONPATH=$BPY/4.5/python/lib/python3.11/site-packages \
        python3.11 make_vdb_files.py

density.vdb: a float fog volume named `density`, values (k + 1) / 8 for k = 0..59 in
[z, y, x] order over 5 × 4 × 3 voxels (x, y, z) from index (2, -1, 3), voxel size 0.5,
beside a float grid `temperature` of 2.0 at 4 voxels; density_expected.npy holds the
density grid as clrays should read it. tiles.vdb: a fog volume whose 8³ active voxels
are one tile. level_set.vdb: a level-set sphere of radius 2 (voxel size 0.5).
"""
import numpy as np
import openvdb as vdb

SHAPE_ZYX = (3, 4, 5)
expected = ((np.arange(np.prod(SHAPE_ZYX), dtype=np.float32) + 1) / 8).reshape(SHAPE_ZYX)

density = vdb.FloatGrid()
# copyFromArray reads the array as [x][y][z]
density.copyFromArray(np.ascontiguousarray(expected.transpose(2, 1, 0)), ijk=(2, -1, 3), tolerance=0)
density.name = "density"
density.gridClass = vdb.GridClass.FOG_VOLUME
density.transform = vdb.createLinearTransform(voxelSize=0.5)
temperature = vdb.FloatGrid()
temperature.copyFromArray(np.full((2, 2, 1), 2.0, dtype=np.float32), ijk=(0, 0, 0), tolerance=0)
temperature.name = "temperature"
vdb.write("density.vdb", grids=[temperature, density])
np.save("density_expected.npy", expected)

tiles = vdb.FloatGrid()
tiles.fill((8, 0, 0), (15, 7, 7), 2.0, True)
tiles.name = "density"
tiles.gridClass = vdb.GridClass.FOG_VOLUME
vdb.write("tiles.vdb", grids=[tiles])

sphere = vdb.createLevelSetSphere(radius=2.0, center=(0, 0, 0), voxelSize=0.5, halfWidth=2.0)
sphere.name = "surface"
vdb.write("level_set.vdb", grids=[sphere])
