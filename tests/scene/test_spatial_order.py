"""Mesh triangles in spatial order (clrays.scene.geometry.spatial_order): a permutation
that puts neighbouring triangles next to each other, applied to the triangles and their
vertex normals together."""
import numpy as np
import trimesh

from clrays.scene.geometry import load_mesh, spatial_order
from tests.scene.test_normals import write_obj


def _grid_triangles(side: int) -> np.ndarray:
    """Two triangles per cell of a side × side grid in the plane z = 0."""
    x, y = np.meshgrid(np.arange(side, dtype=float), np.arange(side, dtype=float))
    corner = np.stack([x.ravel(), y.ravel(), np.zeros(side * side)], axis=1)
    step = np.eye(3)
    return np.concatenate([np.stack([corner, corner + step[0], corner + step[1]], axis=1),
                           np.stack([corner + step[0], corner + step[0] + step[1], corner + step[1]], axis=1)])


def test_the_order_is_a_permutation_that_keeps_neighbours_together():
    shuffled = _grid_triangles(32)[np.random.default_rng(7).permutation(2 * 32 * 32)]
    order = spatial_order(shuffled)
    assert sorted(order.tolist()) == list(range(len(shuffled)))

    def mean_step(triangles):  # distance between consecutive triangles' centroids
        return np.linalg.norm(np.diff(triangles.mean(axis=1), axis=0), axis=1).mean()

    # measured: 1.01 cells between neighbours in Morton order, 16.5 shuffled (0.06 of it); a
    # row-by-row order would give about 1, a random one about a third of the grid's side
    assert mean_step(shuffled[order]) < 0.15 * mean_step(shuffled)


def test_a_flat_or_single_triangle_list_keeps_its_order():
    line = np.zeros((4, 3, 3))  # every centroid the same: ties keep the file's order
    np.testing.assert_array_equal(spatial_order(line), np.arange(4))
    np.testing.assert_array_equal(spatial_order(_grid_triangles(1)[:1]), [0])


def test_a_loaded_mesh_keeps_each_triangle_with_its_normals(tmp_path):
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    write_obj(tmp_path / "ico_vn.obj", mesh.vertices, mesh.faces, normals=mesh.vertices)
    triangles, normals, _ = load_mesh(tmp_path / "ico_vn.obj")
    file_order = mesh.vertices[mesh.faces]
    assert not np.array_equal(triangles, file_order)  # reordered ...
    np.testing.assert_array_equal(triangles, file_order[spatial_order(file_order)])  # ... by spatial_order
    # the file's normals are the sphere's, each vertex's own position: still beside their vertex
    np.testing.assert_allclose(normals, triangles / np.linalg.norm(triangles, axis=2, keepdims=True), atol=1e-6)
