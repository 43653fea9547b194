"""Which triangles each raster view draws: the blocks of triangles that may reach a texel
of the view.

Without a list, a raster pass launches one work-item per triangle of the frame for every
view, and a triangle outside a view still costs its work-item and its projection. Here the
host tests the geometry's triangles in blocks of CULL_BLOCK consecutive ones (a mesh is in
spatial order, clrays.scene.geometry.spatial_order, so a block is a small part of it),
each block's box against the view's planes (perspective: the four sides and the eye's
plane; orthographic: the four sides and the plane the rays start from), and lists the
blocks not wholly outside one of them; the raster passes launch over the listed blocks'
triangles (cl/raster.cl, RASTER_ARGS's `drawn`). The test costs the host a millisecond or
two a view for a million triangles (15 k blocks), where one per triangle cost hundreds of
milliseconds of numpy; the listed triangles that still miss the view leave pass 1 early on
the device.

A dropped block reaches no texel, so the maps keep their bits: every sample ray of a view
lies inside its planes (sample positions inside the view's pixels), and a ray's hit lies
in its triangle grown by EDGE_SLACK (a relative 1e-5 of the triangle, cl/common.h) and
moved by the float32 rounding of the vertices and the ray test. A block is dropped only
where its box lies beyond a plane by CULL_SLACK of twice its largest coordinate from the
view's origin: far above both. The order of a list does not matter: every raster update
is a min or a max.
"""
from __future__ import annotations

import numpy as np

from .. import structs

#: Consecutive triangles whose box is tested as one (15 k blocks for a million triangles).
CULL_BLOCK = 64
#: How far beyond a plane a block's box must lie to be dropped, relative to twice its
#: largest coordinate from the view's origin.
CULL_SLACK = 1e-3
#: Lists a geometry keeps (light poses, camera poses and views it was asked for).
CULLED_KEPT = 16


def view_planes(view: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(5, 3) inward normals, in the view's frame (x right, y up, z forward), and (5,)
    offsets of the planes that bound every sample ray of `view` (a view_t): a point p of a
    ray has normal · p + offset ≥ 0 for each. Perspective: |x| ≤ scale_x·z, |y| ≤
    scale_y·z and z ≥ 0; orthographic: |x| ≤ scale_x, |y| ≤ scale_y and z ≥ 0 (t > 0
    from the plane the rays start on)."""
    sx, sy = float(view["scale_x"]), float(view["scale_y"])
    if view["projection"] == structs.PROJECTION_PERSPECTIVE:
        normals = [[-1.0, 0.0, sx], [1.0, 0.0, sx], [0.0, -1.0, sy], [0.0, 1.0, sy], [0.0, 0.0, 1.0]]
        return np.array(normals), np.zeros(5)
    normals = [[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    return np.array(normals), np.array([sx, sx, sy, sy, 0.0])


def block_boxes(triangles: np.ndarray, block: int) -> tuple[np.ndarray, np.ndarray]:
    """(B, 3) lo and hi of each block of `block` consecutive triangles ((T, 3, 3)); the
    last block holds the rest."""
    count = len(triangles)
    whole = count // block * block
    corners = triangles[:whole]
    # each triangle's box first, elementwise: twice as fast as reducing over 3·block points
    lo = np.minimum(np.minimum(corners[:, 0], corners[:, 1]), corners[:, 2]).reshape(-1, block, 3)
    hi = np.maximum(np.maximum(corners[:, 0], corners[:, 1]), corners[:, 2]).reshape(-1, block, 3)
    lo, hi = [lo.min(axis=1)], [hi.max(axis=1)]
    if whole < count:
        rest = triangles[whole:].reshape(-1, 3)
        lo.append(rest.min(axis=0, keepdims=True))
        hi.append(rest.max(axis=0, keepdims=True))
    return np.concatenate(lo), np.concatenate(hi)


def culled_blocks(boxes: tuple[np.ndarray, np.ndarray], origin: np.ndarray, view: np.ndarray) -> np.ndarray:
    """int32 indices, ascending, of the blocks (`block_boxes`, in any frame: `origin` is the
    view's origin in it) whose box is not wholly beyond one plane of `view` (`view_planes`)
    by CULL_SLACK."""
    lo, hi = boxes
    normals, offsets = view_planes(view)
    basis = np.stack([view["right"][:3], view["up"][:3], view["forward"][:3]]).astype(np.float64).T
    # each plane's normal in the boxes' frame: normal · (basisᵀ (p - origin)) = (basis normal) · (p - origin)
    world_normals = normals @ basis.T  # (5, 3)
    centre, half = 0.5 * (lo + hi) - np.asarray(origin, np.float64), 0.5 * (hi - lo)
    # (B, 5): each plane's value at the box's corner deepest inside it
    farthest = centre @ world_normals.T + half @ np.abs(world_normals).T + offsets
    slack = CULL_SLACK * 2 * (np.abs(centre) + half).max(axis=1)
    return np.flatnonzero(~(farthest < -slack[:, None]).any(axis=1)).astype(np.int32)


def geometry_boxes(geometry, count: int) -> tuple[np.ndarray, np.ndarray]:
    """`block_boxes` of the geometry's first `count` triangles by CULL_BLOCK, world space,
    kept on the geometry."""
    return geometry.kept(("cull boxes", count, CULL_BLOCK), lambda: block_boxes(geometry.triangles[:count], CULL_BLOCK))


def view_blocks(geometry, count: int, anchor_ws: np.ndarray, view: np.ndarray) -> np.ndarray:
    """`culled_blocks` of the geometry's first `count` triangles for `view`, whose frame is
    anchored at `anchor_ws` (world space: the eye for the camera, the light's anchor for
    its map), kept on the geometry for the anchor and view: a static light's lists, or a
    still camera's, are computed once."""
    origin = np.asarray(anchor_ws, np.float64) + view["origin"][:3].astype(np.float64)
    key = ("culled", count, CULL_BLOCK, origin.tobytes(), view.tobytes())
    return geometry.kept(key, lambda: culled_blocks(geometry_boxes(geometry, count), origin, view),
                         most=CULLED_KEPT)
