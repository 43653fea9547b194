"""Which cube-map faces of a point light the frame can sample (raster, docs/design.md §7).

A point light's shadow map is six perspective faces (+x, -x, +y, -y, +z, -z, the order
of `light_view_index` in cl/lighting.h). Every lookup of the frame is along a visible
camera ray, at most `far` from the eye: rectify and traverse read the light ray to a
point of such a ray (or of its neighbour slice, at most one slice step away; or
half a γ texel past its far end), shade reads
visible surface points, raymarch its samples. So a face whose cone from the light misses
the camera's view pyramid (apex at the eye, base 10 % past `far`, widened by one slice step) is
never read and need not be rasterized; its texels stay empty.

The test is exact for the two convex bodies: the view pyramid and the face's cone
truncated beyond the pyramid's farthest point are disjoint exactly when some axis
separates their vertices; the candidate axes are the cross products of every pair of
their edge directions (which include both bodies' face normals). A face is culled only
when an axis separates them by a margin, so rounding never culls a face in use.
"""
from __future__ import annotations

import math

import numpy as np

from ..scene.camera import camera_basis

#: The six faces' axes, in view order: (axis index, sign).
_FACE_AXES = ((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0), (2, 1.0), (2, -1.0))
#: Separation needed to cull, relative to the bodies' size.
_SEPARATION_MARGIN = 1e-6


def view_pyramid(scene, light_position, margin_rad: float) -> np.ndarray | None:
    """(5, 3) vertices, relative to the light, of the camera's view pyramid out to depth
    `far`, each side turned out by `margin_rad`; None when the widened view reaches 90°
    off the view direction (then it is not a pyramid and nothing is culled)."""
    camera, image = scene.camera, scene.image
    right, up, forward = camera_basis(camera)
    tan_y = math.tan(math.radians(camera.fov_deg) / 2)
    tan_x = tan_y * image.width / image.height
    half_x, half_y = math.atan(tan_x) + margin_rad, math.atan(tan_y) + margin_rad
    if max(half_x, half_y) >= math.pi / 2 - 1e-3:
        return None
    tan_x, tan_y = math.tan(half_x), math.tan(half_y)
    eye = np.asarray(camera.position, float) - np.asarray(light_position, float)
    # 10 % past far: a γ texel's centre may lie half a texel beyond a ray's far end.
    corners = [eye + 1.1 * camera.far * (forward + sx * tan_x * right + sy * tan_y * up)
               for sx in (-1, 1) for sy in (-1, 1)]
    return np.array([eye] + corners)


def _edges(vertices: np.ndarray) -> np.ndarray:
    """Edge directions of a pyramid: apex (vertex 0) to each base corner, and the base
    rectangle's sides (corners ordered (-,-), (-,+), (+,-), (+,+))."""
    apex, base = vertices[0], vertices[1:]
    sides = [base[1] - base[0], base[2] - base[0], base[3] - base[1], base[3] - base[2]]
    return np.array([corner - apex for corner in base] + sides)


def _face_cone(axis: int, sign: float, reach: float) -> np.ndarray:
    """(5, 3) vertices of a face's cone from the origin, out to `reach` along its axis:
    every point of the cone within distance `reach` of the light lies inside."""
    others = [k for k in range(3) if k != axis]
    vertices = [np.zeros(3)]
    for a in (-1, 1):
        for b in (-1, 1):
            v = np.zeros(3)
            v[axis], v[others[0]], v[others[1]] = sign * reach, a * reach, b * reach
            vertices.append(v)
    return np.array(vertices)


def _separated(a: np.ndarray, b: np.ndarray) -> bool:
    edges = np.concatenate([_edges(a), _edges(b)])
    i, j = np.triu_indices(len(edges), 1)
    axes = np.cross(edges[i], edges[j])
    lengths = np.linalg.norm(axes, axis=1)
    axes = axes[lengths > 1e-12 * lengths.max()] / lengths[lengths > 1e-12 * lengths.max(), None]
    pa, pb = a @ axes.T, b @ axes.T
    margin = _SEPARATION_MARGIN * max(np.abs(a).max(), np.abs(b).max())
    return bool(np.any((pa.max(axis=0) < pb.min(axis=0) - margin) | (pb.max(axis=0) < pa.min(axis=0) - margin)))


def sampled_cube_faces(scene, light_position, slices: int) -> tuple[bool, ...]:
    """For each of the six faces of a cube map at `light_position` (world space): whether
    a frame with `slices` epipolar slices can read it. One slice step (at most 2π/slices)
    widens the view, for the neighbour slice that traverse interpolates."""
    pyramid = view_pyramid(scene, light_position, 2 * math.pi / slices)
    if pyramid is None:
        return (True,) * 6
    reach = float(np.linalg.norm(pyramid, axis=1).max()) * 1.01
    return tuple(not _separated(pyramid, _face_cone(axis, sign, reach)) for axis, sign in _FACE_AXES)
