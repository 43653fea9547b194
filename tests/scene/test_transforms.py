"""Tests for clrays.scene.transforms.

Tolerance: everything here is a handful of float64 operations on O(1) values, so errors
are a few ulps (~1e-15); ATOL = 1e-12 leaves three orders of margin and still catches
any real formula error (those are O(1) or at least O(1e-6)).
"""
import math

import numpy as np
import pytest

from clrays.scene import transforms as tf

ATOL = 1e-12
EX, EY, EZ = np.eye(3)


def random_unit_quats(n, seed):
    # Normalised 4D Gaussians are uniform on S^3, hence uniform rotations.
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def axis_angle_quat(axis, angle):
    """[cos(a/2), sin(a/2) · unit axis], written out here so the tests do not check
    transforms.py against itself."""
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis])


def same_rotation(qa, qb):
    # q and -q are the same rotation.
    return np.allclose(qa, qb, atol=ATOL) or np.allclose(qa, -qb, atol=ATOL)


def quat_angle(qa, qb):
    """Rotation angle (rad) of qa⁻¹·qb, via atan2, which stays accurate for tiny angles
    where arccos(|dot|) would lose half the digits."""
    d = tf.quat_multiply(tf.quat_conjugate(qa), qb)
    return 2.0 * math.atan2(np.linalg.norm(d[1:]), abs(d[0]))


@pytest.mark.parametrize("rot, v, expected", [
    (tf.rotation_z, EX, EY), (tf.rotation_z, EY, -EX),
    (tf.rotation_x, EY, EZ), (tf.rotation_x, EZ, -EY),
    (tf.rotation_y, EZ, EX), (tf.rotation_y, EX, -EZ),
])
def test_quarter_turns_known_values(rot, v, expected):
    np.testing.assert_allclose(rot(math.pi / 2) @ v, expected, atol=ATOL)


def test_rotations_orthonormal_det_plus_one():
    rng = np.random.default_rng(1)
    mats = []
    for a, axis, angles, q in zip(rng.uniform(-7, 7, 20), rng.normal(size=(20, 3)),
                                  rng.uniform(-7, 7, (20, 3)), random_unit_quats(20, 2)):
        mats += [tf.rotation_x(a), tf.rotation_y(a), tf.rotation_z(a),
                 tf.rotation_axis_angle(axis, a), tf.rotation_euler(angles, "zxz"),
                 tf.quat_to_matrix(q)]
    for m in mats:
        np.testing.assert_allclose(m @ m.T, np.eye(3), atol=ATOL)
        assert abs(np.linalg.det(m) - 1.0) < ATOL


def test_axis_angle_matrix_and_quaternion_agree():
    rng = np.random.default_rng(3)
    for axis, a in zip(rng.normal(size=(50, 3)) * 5, rng.uniform(-7, 7, 50)):
        m = tf.rotation_axis_angle(axis, a)
        q = axis_angle_quat(axis, a)
        np.testing.assert_allclose(tf.quat_to_matrix(q), m, atol=ATOL)
        # The axis is fixed, whatever its length.
        np.testing.assert_allclose(m @ axis, axis, atol=ATOL * 10)
    for e, rot in [(EX, tf.rotation_x), (EY, tf.rotation_y), (EZ, tf.rotation_z)]:
        np.testing.assert_allclose(tf.rotation_axis_angle(3 * e, 0.7), rot(0.7), atol=ATOL)


def test_zero_axis_rejected():
    with pytest.raises(ValueError):
        tf.rotation_axis_angle([0, 0, 0], 1.0)


def test_matrix_quat_round_trip_random():
    for q in random_unit_quats(200, 4):
        q_back = tf.matrix_to_quat(tf.quat_to_matrix(q))
        assert q_back[0] >= 0.0
        assert same_rotation(q_back, q)
        np.testing.assert_allclose(tf.quat_to_matrix(q_back), tf.quat_to_matrix(q), atol=ATOL)


def _near_half_turns():
    rng = np.random.default_rng(5)
    cases = [(e, math.pi) for e in np.eye(3)] + [(e, math.pi - 1e-3) for e in np.eye(3)]
    cases += [(axis, math.pi - d) for axis, d in zip(rng.normal(size=(30, 3)), rng.uniform(0, 0.5, 30))]
    return cases


@pytest.mark.parametrize("axis, angle", _near_half_turns())
def test_matrix_to_quat_trace_nonpositive_branches(axis, angle):
    m = tf.rotation_axis_angle(axis, angle)
    assert np.trace(m) <= 0.0  # trace = 1 + 2cos(angle) <= 0 for angle >= 120°
    q = tf.matrix_to_quat(m)
    assert q[0] >= 0.0
    assert same_rotation(q, axis_angle_quat(axis, angle))
    np.testing.assert_allclose(tf.quat_to_matrix(q), m, atol=ATOL)


def test_all_shepperd_branches_covered():
    # Which branch runs is decided by the trace and then the largest diagonal entry.
    branches = set()
    for axis, angle in _near_half_turns():
        m = tf.rotation_axis_angle(axis, angle)
        branches.add(int(np.argmax(np.diag(m))))
    assert branches == {0, 1, 2}
    assert np.trace(tf.rotation_z(0.3)) > 0.0
    np.testing.assert_allclose(tf.matrix_to_quat(np.eye(3)), [1, 0, 0, 0], atol=ATOL)


def test_quat_times_inverse_is_identity():
    rng = np.random.default_rng(6)
    for q in rng.normal(size=(50, 4)) * rng.uniform(0.1, 10, (50, 1)):  # not unit
        np.testing.assert_allclose(tf.quat_multiply(q, tf.quat_inverse(q)), [1, 0, 0, 0], atol=ATOL)
        np.testing.assert_allclose(tf.quat_multiply(tf.quat_inverse(q), q), [1, 0, 0, 0], atol=ATOL)


def test_quat_rotate_equals_matrix_multiply():
    vs = np.random.default_rng(7).normal(size=(50, 3))
    for q, v in zip(random_unit_quats(50, 8), vs):
        np.testing.assert_allclose(tf.quat_rotate(q, v), tf.quat_to_matrix(q) @ v, atol=ATOL)
        # Non-unit q rotates the same way, since q⁻¹ absorbs its length.
        np.testing.assert_allclose(tf.quat_rotate(3 * q, v), tf.quat_to_matrix(q) @ v, atol=ATOL)


def test_products_keep_unit_norm_and_compose():
    qs = random_unit_quats(100, 9)
    for a, b in zip(qs[:50], qs[50:]):
        ab = tf.quat_multiply(a, b)
        assert abs(np.linalg.norm(ab) - 1.0) < ATOL
        np.testing.assert_allclose(tf.quat_to_matrix(ab), tf.quat_to_matrix(a) @ tf.quat_to_matrix(b), atol=ATOL)


def test_slerp_endpoints():
    q0, q1 = random_unit_quats(2, 10)
    q1 = q1 if q0 @ q1 >= 0 else -q1  # so the t = 1 endpoint is q1 itself
    np.testing.assert_allclose(tf.slerp(q0, q1, 0.0), q0, atol=ATOL)
    np.testing.assert_allclose(tf.slerp(q0, q1, 1.0), q1, atol=ATOL)
    assert tf.slerp(q0, q1, np.linspace(0, 1, 7)).shape == (7, 4)


def test_slerp_takes_shorter_arc():
    for q0, q1 in random_unit_quats(40, 11).reshape(20, 2, 4):
        ts = np.linspace(0, 1, 9)
        np.testing.assert_allclose(tf.slerp(q0, q1, ts), tf.slerp(q0, -q1, ts), atol=ATOL)
        # On the shorter arc the total rotation angle is at most pi.
        total = quat_angle(q0, q1)
        assert total <= math.pi + ATOL
        assert abs(quat_angle(q0, tf.slerp(q0, q1, 0.5)) - total / 2) < ATOL


def test_slerp_constant_angular_speed():
    for q0, q1 in random_unit_quats(20, 12).reshape(10, 2, 4):
        samples = tf.slerp(q0, q1, np.linspace(0, 1, 11))
        steps = [quat_angle(a, b) for a, b in zip(samples[:-1], samples[1:])]
        np.testing.assert_allclose(steps, quat_angle(q0, q1) / 10, atol=ATOL)


def test_slerp_nearly_parallel_falls_back_to_lerp():
    q0 = axis_angle_quat([1, 2, 3], 0.4)
    q1 = axis_angle_quat([1, 2, 3], 0.4 + 1e-9)
    q = tf.slerp(q0, q1, 0.5)
    assert np.all(np.isfinite(q)) and abs(np.linalg.norm(q) - 1.0) < ATOL
    np.testing.assert_allclose(q, axis_angle_quat([1, 2, 3], 0.4 + 5e-10), atol=ATOL)


def test_euler_is_intrinsic_product_in_order():
    a = np.array([0.3, -1.1, 2.0])
    for order in ["xyz", "zyx", "zxz", "yxy", "xzx"]:
        r = [getattr(tf, f"rotation_{c}")(t) for c, t in zip(order, a)]
        np.testing.assert_allclose(tf.rotation_euler(a, order), r[0] @ r[1] @ r[2], atol=ATOL)


def test_euler_matches_scipy_intrinsic():
    rotation = pytest.importorskip("scipy.spatial.transform").Rotation
    rng = np.random.default_rng(13)
    for order in ["xyz", "zyx", "zxz", "yzy"]:
        for a in rng.uniform(-math.pi, math.pi, (10, 3)):
            # Upper-case axes mean intrinsic in scipy.
            expected = rotation.from_euler(order.upper(), a).as_matrix()
            np.testing.assert_allclose(tf.rotation_euler(a, order), expected, atol=ATOL)


@pytest.mark.parametrize("order", ["xxy", "xyy", "xy", "xyzx", "abc", "XYZ", ""])
def test_euler_bad_order_rejected(order):
    with pytest.raises(ValueError):
        tf.rotation_euler([0.1, 0.2, 0.3], order)


def test_gimbal_lock_xyz():
    # R_x(a) R_y(90°) = R_y(90°) R_z(a), so R_x(a0) R_y(90°) R_z(a2) = R_y(90°) R_z(a0 + a2):
    # only the sum a0 + a2 survives and one degree of freedom is lost.
    lock = math.pi / 2
    m1 = tf.rotation_euler([0.3, lock, 0.5], "xyz")
    m2 = tf.rotation_euler([1.1, lock, -0.3], "xyz")  # same sum 0.8
    np.testing.assert_allclose(m1, m2, atol=ATOL)
    np.testing.assert_allclose(m1, tf.rotation_y(lock) @ tf.rotation_z(0.8), atol=ATOL)
    m3 = tf.rotation_euler([1.1, lock, 0.3], "xyz")  # same difference -0.2, different sum
    assert not np.allclose(m1, m3, atol=1e-3)


def test_normal_matrix_keeps_normals_perpendicular():
    rng = np.random.default_rng(14)
    m = tf.affine([1, -2, 3], tf.rotation_axis_angle([1, 1, 0], 0.7), [3.0, 0.5, 1.7])
    n_mat = tf.normal_matrix(m)
    np.testing.assert_allclose(n_mat, tf.normal_matrix(m[:3, :3]), atol=ATOL)
    for n in rng.normal(size=(30, 3)):
        t = np.cross(n, rng.normal(size=3))  # a tangent: perpendicular to n
        # The dot product is O(|t||n|) in size, so scale the ulp-level tolerance by it.
        assert abs((m[:3, :3] @ t) @ (n_mat @ n)) < ATOL * np.linalg.norm(t) * np.linalg.norm(n)
        n_out = tf.transform_normals(m, n)
        assert abs(np.linalg.norm(n_out) - 1.0) < ATOL
        np.testing.assert_allclose(n_out, n_mat @ n / np.linalg.norm(n_mat @ n), atol=ATOL)
    # Mapping the normal like a tangent would not stay perpendicular under this scale.
    n, t = np.array([1.0, 1.0, 0.0]), np.array([1.0, -1.0, 0.0])
    assert abs((m[:3, :3] @ t) @ (m[:3, :3] @ n)) > 0.1


def test_affine_scales_then_rotates_then_translates():
    r = tf.rotation_z(math.pi / 2)
    m = tf.affine([10, 0, 0], r, [2, 3, 4])
    # (1, 0, 0) -> scale (2, 0, 0) -> rotate (0, 2, 0) -> translate (10, 2, 0)
    np.testing.assert_allclose(tf.transform_points(m, EX), [10, 2, 0], atol=ATOL)
    np.testing.assert_allclose(tf.affine(scale=2.0)[:3, :3], 2 * np.eye(3), atol=ATOL)
    np.testing.assert_allclose(tf.affine(), np.eye(4), atol=ATOL)


def test_transform_points_batched_shapes():
    pts = np.random.default_rng(15).normal(size=(2, 5, 3))
    m = tf.affine([1, 2, 3], tf.rotation_euler([0.1, 0.2, 0.3], "zyx"), 1.5)
    out = tf.transform_points(m, pts)
    assert out.shape == (2, 5, 3)
    expected = (m @ np.concatenate([pts, np.ones((2, 5, 1))], axis=-1)[..., None])[..., :3, 0]
    np.testing.assert_allclose(out, expected, atol=ATOL)
