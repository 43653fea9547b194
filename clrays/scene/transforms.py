"""Rotations, quaternions and affine transforms of points and normals, float64 numpy:
what the loader (object transforms), the animation (SLERP, camera orientation) and the
shading normals need.

Conventions:

* Right-handed coordinates; column vectors, so a matrix acts as ``m @ v`` and
  ``a @ b`` applies ``b`` first. Rotations are active (they move points, not axes)
  and positive angles turn counter-clockwise looking down the axis at the origin.
* Angles are in radians.
* Quaternions are arrays ``[w, x, y, z]`` (scalar first); rotation quaternions are unit.
* Homogeneous matrices are 4x4 with the translation in the last column.
"""
from __future__ import annotations

import numpy as np

# Below this sin(angle) two unit quaternions are treated as parallel in slerp.
_SLERP_PARALLEL_EPS = 1e-6


def _unit(v, what: str) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v)
    if n == 0.0 or not np.isfinite(n):
        raise ValueError(f"{what} must be a non-zero finite vector, got {v}")
    return v / n


def rotation_x(angle_rad: float) -> np.ndarray:
    """3x3 rotation by angle_rad (radians) about +x; maps +y towards +z."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rotation_y(angle_rad: float) -> np.ndarray:
    """3x3 rotation by angle_rad (radians) about +y; maps +z towards +x."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotation_z(angle_rad: float) -> np.ndarray:
    """3x3 rotation by angle_rad (radians) about +z; maps +x towards +y."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_axis_angle(axis, angle_rad: float) -> np.ndarray:
    """3x3 rotation by angle_rad (radians) about axis (any non-zero length), by Rodrigues:
    R = I + sin(a) K + (1 - cos(a)) K^2 with K the cross-product matrix of the unit axis."""
    x, y, z = _unit(axis, "rotation axis")
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + np.sin(angle_rad) * k + (1.0 - np.cos(angle_rad)) * (k @ k)


_AXIS_ROTATIONS = {"x": rotation_x, "y": rotation_y, "z": rotation_z}


def rotation_euler(angles_rad, order: str) -> np.ndarray:
    """3x3 rotation from three Euler angles (radians).

    ``order`` is three letters over 'xyz' with no two adjacent letters equal ("xyz",
    "zyx", "zxz", ...). The rotations are intrinsic, applied in the given order: first
    about order[0], then about the *rotated* order[1], then the twice-rotated order[2].
    As a matrix that is R = R_{order[0]}(a0) @ R_{order[1]}(a1) @ R_{order[2]}(a2),
    which equals the extrinsic (fixed-axis) sequence in the reverse order.
    """
    if (not isinstance(order, str) or len(order) != 3 or set(order) - set("xyz")
            or order[0] == order[1] or order[1] == order[2]):
        raise ValueError(f"Euler order must be 3 letters over 'xyz' with no adjacent repeats, got {order!r}")
    a = np.asarray(angles_rad, dtype=np.float64)
    if a.shape != (3,):
        raise ValueError(f"expected 3 Euler angles, got shape {a.shape}")
    r0, r1, r2 = (_AXIS_ROTATIONS[c](t) for c, t in zip(order, a))
    return r0 @ r1 @ r2


def quat_multiply(a, b) -> np.ndarray:
    """Hamilton product a·b of quaternions [w, x, y, z]; as rotations, b is applied first."""
    aw, ax, ay, az = np.asarray(a, dtype=np.float64)
    bw, bx, by, bz = np.asarray(b, dtype=np.float64)
    return np.array([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ])


def quat_conjugate(q) -> np.ndarray:
    """[w, -x, -y, -z]."""
    q = np.asarray(q, dtype=np.float64)
    return np.array([q[0], -q[1], -q[2], -q[3]])


def quat_inverse(q) -> np.ndarray:
    """Multiplicative inverse conj(q) / |q|^2; raises ValueError for the zero quaternion."""
    q = np.asarray(q, dtype=np.float64)
    n2 = float(q @ q)
    if n2 == 0.0:
        raise ValueError("the zero quaternion has no inverse")
    return quat_conjugate(q) / n2


def quat_normalize(q) -> np.ndarray:
    """q / |q|; raises ValueError for the zero quaternion."""
    return _unit(q, "quaternion")


def quat_rotate(q, v) -> np.ndarray:
    """Rotate the 3-vector v by q, computed literally as the vector part of q·(0, v)·q⁻¹."""
    p = np.concatenate([[0.0], np.asarray(v, dtype=np.float64)])
    return quat_multiply(quat_multiply(q, p), quat_inverse(q))[1:]


def quat_to_matrix(q) -> np.ndarray:
    """3x3 rotation matrix of q (normalised first, so any non-zero q is accepted)."""
    w, x, y, z = quat_normalize(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def matrix_to_quat(m) -> np.ndarray:
    """Unit quaternion (w >= 0) of a 3x3 rotation matrix, by Shepperd's method.

    The largest of 4w², 4x², 4y², 4z² is computed from the diagonal and used as the
    divisor, so the square root never sees a small, cancellation-prone argument.
    """
    m = np.asarray(m, dtype=np.float64)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0.0:
        s = 2.0 * np.sqrt(1.0 + tr)  # s = 4w
        q = [s / 4, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] >= m[1, 1] and m[0, 0] >= m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])  # s = 4x
        q = [(m[2, 1] - m[1, 2]) / s, s / 4, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] >= m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])  # s = 4y
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, s / 4, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])  # s = 4z
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, s / 4]
    q = quat_normalize(q)
    # q and -q are the same rotation; pick the w >= 0 representative.
    return -q if q[0] < 0 else q


def slerp(q0, q1, t) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions along the shorter arc.

    t is a scalar (result shape (4,)) or an array (result shape t.shape + (4,));
    t = 0 gives q0, t = 1 gives q1 or -q1 (the same rotation). The angular speed is
    constant in t.
    """
    q0, q1 = quat_normalize(q0), quat_normalize(q1)
    d = float(q0 @ q1)
    if d < 0.0:  # q1 and -q1 are the same rotation; -q1 is nearer along the sphere.
        q1, d = -q1, -d
    t = np.asarray(t, dtype=np.float64)[..., None]
    theta = np.arccos(min(d, 1.0))
    if np.sin(theta) < _SLERP_PARALLEL_EPS:
        # sin(theta) -> 0 makes the weights 0/0; lerp differs by O(theta^2) there.
        q = (1.0 - t) * q0 + t * q1
        return q / np.linalg.norm(q, axis=-1, keepdims=True)
    return (np.sin((1.0 - t) * theta) * q0 + np.sin(t * theta) * q1) / np.sin(theta)


def normal_matrix(m) -> np.ndarray:
    """Inverse transpose of the upper-left 3x3 of a 3x3 or 4x4 matrix: it maps normals so
    they stay perpendicular to tangents mapped by m, even under non-uniform scale."""
    return np.linalg.inv(np.asarray(m, dtype=np.float64)[:3, :3]).T


def affine(translate=(0.0, 0.0, 0.0), rotate=np.eye(3), scale=1.0) -> np.ndarray:
    """4x4 T @ R @ S: scale (scalar or per-axis 3-vector) first, then the 3x3 rotation,
    then translate (world units)."""
    m = np.eye(4)
    m[:3, :3] = np.asarray(rotate, dtype=np.float64) @ np.diag(np.broadcast_to(
        np.asarray(scale, dtype=np.float64), (3,)))
    m[:3, 3] = translate
    return m


def transform_points(m4, pts) -> np.ndarray:
    """Apply the 4x4 m4 to points of shape (..., 3), with w = 1 and the perspective divide."""
    m4 = np.asarray(m4, dtype=np.float64)
    p = np.asarray(pts, dtype=np.float64) @ m4[:3, :3].T + m4[:3, 3]
    w = np.asarray(pts, dtype=np.float64) @ m4[3, :3] + m4[3, 3]
    return p / w[..., None]


def transform_normals(m4, normals) -> np.ndarray:
    """Map normals of shape (..., 3) by the inverse transpose of m4's 3x3 and re-normalise
    (zero normals stay zero)."""
    n = np.asarray(normals, dtype=np.float64) @ normal_matrix(m4).T
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)
