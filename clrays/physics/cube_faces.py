"""Which cube-map faces of a point light the frame can sample (raster, docs/design.md §7).

A point light's shadow map is six perspective faces (+x, -x, +y, -y, +z, -z, the order
of `light_view_index` in cl/lighting.h). Every lookup of the frame is along a visible
camera ray, at most `far` from the eye: rectify and traverse read the light ray to a
point of such a ray (or of its neighbour slice, at most one slice step away; or
half a γ texel past its far end), shade reads
visible surface points, raymarch its samples. So a face whose cone from the light misses
the camera's view pyramid (apex at the eye, base 10 % past `far`, widened by one slice step) is
never read and need not be rasterized; its texels stay empty, and it takes a token
MIN_SHADOW_MAP² of them (clrays.inputs.frame_inputs).

The test is exact for the two convex bodies: the view pyramid and the face's cone
truncated beyond the pyramid's farthest point are disjoint exactly when some axis
separates their vertices; the candidate axes are the cross products of every pair of
their edge directions (which include both bodies' face normals). A face is culled only
when an axis separates them by a margin, so rounding never culls a face in use.
"""
from __future__ import annotations

import math

import numpy as np

from ..physics.radiometry import effective_far
from ..scene.camera import camera_basis, half_extents

#: The six faces' axes, in view order: (axis index, sign).
_FACE_AXES = ((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0), (2, 1.0), (2, -1.0))
#: Separation needed to cull, relative to the bodies' size.
_SEPARATION_MARGIN = 1e-6


def view_pyramid(scene, light_position, margin_rad: float) -> np.ndarray | None:
    """(5, 3) vertices, relative to the light, of the camera's view pyramid out to depth
    the effective `far`, each side turned out by `margin_rad`; None when the widened view reaches 90°
    off the view direction (then it is not a pyramid and nothing is culled)."""
    camera, image = scene.camera, scene.image
    right, up, forward = camera_basis(camera)
    tan_x, tan_y = half_extents(camera, image)
    half_x, half_y = math.atan(tan_x) + margin_rad, math.atan(tan_y) + margin_rad
    if max(half_x, half_y) >= math.pi / 2 - 1e-3:
        return None
    tan_x, tan_y = math.tan(half_x), math.tan(half_y)
    eye = np.asarray(camera.position, float) - np.asarray(light_position, float)
    # 10 % past far (where the rays that hit nothing end: radiometry.effective_far): a γ
    # texel's centre may lie half a texel beyond a ray's far end.
    far = effective_far(scene)
    corners = [eye + 1.1 * far * (forward + sx * tan_x * right + sy * tan_y * up)
               for sx in (-1, 1) for sy in (-1, 1)]
    return np.array([eye] + corners)


def _edges(vertices: np.ndarray) -> np.ndarray:
    """(..., 8, 3) edge directions of pyramids (..., 5, 3): apex (vertex 0) to each base
    corner, and the base rectangle's sides (corners ordered (-,-), (-,+), (+,-), (+,+))."""
    apex, base = vertices[..., :1, :], vertices[..., 1:, :]
    sides = base[..., [1, 2, 3, 3], :] - base[..., [0, 0, 1, 2], :]
    return np.concatenate([base - apex, sides], axis=-2)


def _face_cones(reach: float) -> np.ndarray:
    """(6, 5, 3) vertices of the faces' cones from the origin, out to `reach` along each
    axis: every point of a cone within distance `reach` of the light lies inside its body."""
    cones = np.zeros((6, 5, 3))
    for face, (axis, sign) in enumerate(_FACE_AXES):
        others = [k for k in range(3) if k != axis]
        for corner, (a, b) in enumerate(((-1, -1), (-1, 1), (1, -1), (1, 1)), start=1):
            cones[face, corner, axis], cones[face, corner, others[0]], cones[face, corner, others[1]] = (
                sign * reach, a * reach, b * reach)
    return cones


#: Every pair of the 16 edge directions of two pyramids (computed once: host work per frame).
_EDGE_PAIRS = np.triu_indices(16, 1)


def _separated(pyramid: np.ndarray, cones: np.ndarray) -> np.ndarray:
    """(6,) bool: whether an axis separates the pyramid from each cone by the margin."""
    edges = np.concatenate([np.broadcast_to(_edges(pyramid), (len(cones), 8, 3)), _edges(cones)], axis=1)
    i, j = _EDGE_PAIRS
    axes = np.cross(edges[:, i], edges[:, j])  # (6, 120, 3)
    lengths = np.linalg.norm(axes, axis=-1, keepdims=True)
    usable = lengths > 1e-12 * lengths.max()
    axes = np.where(usable, axes / np.where(usable, lengths, 1.0), 0.0)  # degenerate axes separate nothing
    pa = np.einsum("vk,fak->fav", pyramid, axes)  # (6, 120, 5)
    pb = np.einsum("fvk,fak->fav", cones, axes)
    margin = _SEPARATION_MARGIN * max(np.abs(pyramid).max(), np.abs(cones).max())
    apart = (pa.max(-1) < pb.min(-1) - margin) | (pb.max(-1) < pa.min(-1) - margin)
    return apart.any(axis=1)


def sampled_cube_faces(scene, light_position, slices: int) -> tuple[bool, ...]:
    """For each of the six faces of a cube map at `light_position` (world space): whether
    a frame with `slices` epipolar slices can read it. One slice step (at most 2π/slices)
    widens the view, for the neighbour slice that traverse interpolates."""
    pyramid = view_pyramid(scene, light_position, 2 * math.pi / slices)
    if pyramid is None:
        return (True,) * 6
    reach = float(np.linalg.norm(pyramid, axis=1).max()) * 1.01
    return tuple(bool(not apart) for apart in _separated(pyramid, _face_cones(reach)))
