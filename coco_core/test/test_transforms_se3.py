"""SE(3) helpers of the transformation graph, checked against pytransform3d and hand-built matrices.

Conventions under test (coco_core.transforms.se3): quaternions are ``(x, y, z, w)`` like ROS, while
pytransform3d uses ``(w, x, y, z)``; ``rpy`` is URDF's fixed-axis ``Rz(yaw) Ry(pitch) Rx(roll)``;
classic Denavit-Hartenberg is ``Rz(theta) Tz(d) Tx(r) Rx(alpha)``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from coco_core.transforms import se3
from geometry import rot_x, rot_y, rot_z, homogeneous

pr = pytest.importorskip("pytransform3d.rotations")

TOL = 1e-12


# --- independent constructions ----------------------------------------------------------------------


def skew(v) -> np.ndarray:
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def rodrigues(axis, angle) -> np.ndarray:
    """``I + sin(a) K + (1 - cos(a)) K^2``, written independently of se3.axis_angle."""
    k = skew(np.asarray(axis, dtype=float) / np.linalg.norm(axis))
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def to_wxyz(q_xyzw) -> np.ndarray:
    x, y, z, w = q_xyzw
    return np.array([w, x, y, z])


def to_xyzw(q_wxyz) -> np.ndarray:
    w, x, y, z = q_wxyz
    return np.array([x, y, z, w])


def same_rotation_quaternion(q1, q2, tol=1e-9) -> bool:
    """q and -q are the same rotation."""
    q1, q2 = np.asarray(q1, dtype=float), np.asarray(q2, dtype=float)
    return bool(np.allclose(q1, q2, atol=tol) or np.allclose(q1, -q2, atol=tol))


def random_unit_quaternions(rng: np.random.Generator, count: int) -> np.ndarray:
    q = rng.normal(size=(count, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def random_transform(rng: np.random.Generator) -> np.ndarray:
    q = random_unit_quaternions(rng, 1)[0]
    return homogeneous(pr.matrix_from_quaternion(to_wxyz(q)), rng.uniform(-3.0, 3.0, size=3))


def angle_between(r1: np.ndarray, r2: np.ndarray) -> float:
    """Geodesic distance between two rotations."""
    cos = (np.trace(r1.T @ r2) - 1.0) / 2.0
    return math.acos(max(-1.0, min(1.0, cos)))


# --- quaternions ------------------------------------------------------------------------------------

def test_quaternion_to_matrix_matches_pytransform3d_on_random_quaternions():
    rng = np.random.default_rng(1)
    for q in random_unit_quaternions(rng, 200):
        expected = pr.matrix_from_quaternion(to_wxyz(q))
        np.testing.assert_allclose(se3.quaternion_to_matrix(q), expected, atol=TOL)


def test_quaternion_to_matrix_normalises_its_input():
    q = np.array([0.1, -0.4, 0.3, 0.8])
    unit = q / np.linalg.norm(q)
    np.testing.assert_allclose(se3.quaternion_to_matrix(q * 7.5), se3.quaternion_to_matrix(unit), atol=TOL)
    rotation = se3.quaternion_to_matrix([0.0, 0.0, 0.0, 3.0])
    np.testing.assert_allclose(rotation, np.eye(3), atol=TOL)


def test_quaternion_matrix_quaternion_round_trip_random():
    rng = np.random.default_rng(2)
    for q in random_unit_quaternions(rng, 300):
        back = se3.matrix_to_quaternion(se3.quaternion_to_matrix(q))
        assert back[3] >= 0.0, "the returned quaternion has w >= 0"
        assert abs(np.linalg.norm(back) - 1.0) < 1e-12
        expected = q if q[3] >= 0 else -q
        np.testing.assert_allclose(back, expected, atol=1e-12)


def test_matrix_quaternion_matrix_round_trip_random():
    rng = np.random.default_rng(3)
    for _ in range(300):
        rotation = pr.random_matrix(rng)
        back = se3.quaternion_to_matrix(se3.matrix_to_quaternion(rotation))
        np.testing.assert_allclose(back, rotation, atol=1e-12)
        # and against pytransform3d's own conversion (up to the sign of q)
        reference = to_xyzw(pr.quaternion_from_matrix(rotation))
        assert same_rotation_quaternion(se3.matrix_to_quaternion(rotation), reference)


@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (0, 1, 1), (1, 0, 1),
                                  (1, -2, 3), (-0.3, 0.1, -0.9)])
@pytest.mark.parametrize("angle", [math.pi, math.pi - 1e-9, math.pi - 1e-6, -math.pi + 1e-7, math.pi - 0.01])
def test_near_half_turn_rotations_round_trip(axis, angle):
    """Rotations near 180 degrees have w ~ 0 and a trace near -1: the branches of Shepperd's method
    that do not divide by w must be used, and the matrix must come back exactly."""
    unit = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    rotation = rodrigues(unit, angle)
    q = se3.matrix_to_quaternion(rotation)
    assert np.all(np.isfinite(q))
    assert q[3] >= 0.0
    assert abs(np.linalg.norm(q) - 1.0) < 1e-12
    np.testing.assert_allclose(se3.quaternion_to_matrix(q), rotation, atol=1e-12)
    # the vector part points along the rotation axis, |v| = sin(|angle| / 2)
    expected = np.concatenate([unit * math.sin(angle / 2.0), [math.cos(angle / 2.0)]])
    assert same_rotation_quaternion(q, expected, tol=1e-9)


@pytest.mark.parametrize("q", [(1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0),
                               (0.6, 0.8, 0.0, 0.0), (0.0, 0.6, -0.8, 0.0), (0.48, 0.6, 0.64, 0.0),
                               (0.48, 0.6, 0.64, 1e-12), (0.48, 0.6, 0.64, -1e-12)])
def test_w_zero_quaternions_round_trip(q):
    q = np.asarray(q)
    q = q / np.linalg.norm(q)
    rotation = se3.quaternion_to_matrix(q)
    np.testing.assert_allclose(rotation, pr.matrix_from_quaternion(to_wxyz(q)), atol=TOL)
    back = se3.matrix_to_quaternion(rotation)
    assert same_rotation_quaternion(back, q, tol=1e-9)
    np.testing.assert_allclose(se3.quaternion_to_matrix(back), rotation, atol=1e-12)


def test_pose_round_trip():
    rng = np.random.default_rng(4)
    for _ in range(50):
        transform = random_transform(rng)
        translation, quaternion = se3.to_pose(transform)
        np.testing.assert_allclose(se3.from_pose(translation, quaternion), transform, atol=1e-12)
        translation[0] += 100.0  # to_pose hands out a copy
        assert transform[0, 3] != translation[0]


# --- roll, pitch, yaw and axis-angle -----------------------------------------------------------------

def test_rpy_matches_pytransform3d_and_hand_composition():
    rng = np.random.default_rng(5)
    for roll, pitch, yaw in rng.uniform(-math.pi, math.pi, size=(100, 3)):
        got = se3.rpy_to_matrix(roll, pitch, yaw)
        np.testing.assert_allclose(got, rot_z(yaw) @ rot_y(pitch) @ rot_x(roll), atol=TOL)
        # extrinsic (fixed-axis) rotations about x, then y, then z
        np.testing.assert_allclose(got, pr.matrix_from_euler([roll, pitch, yaw], 0, 1, 2, True), atol=TOL)


def test_rpy_single_axes():
    np.testing.assert_allclose(se3.rpy_to_matrix(0.3, 0, 0), rot_x(0.3), atol=TOL)
    np.testing.assert_allclose(se3.rpy_to_matrix(0, 0.3, 0), rot_y(0.3), atol=TOL)
    np.testing.assert_allclose(se3.rpy_to_matrix(0, 0, 0.3), rot_z(0.3), atol=TOL)
    # a quarter turn of yaw takes x to y
    np.testing.assert_allclose(se3.rpy_to_matrix(0, 0, math.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=TOL)


def test_axis_angle_against_rodrigues_by_hand():
    rng = np.random.default_rng(6)
    for _ in range(100):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = rng.uniform(-2 * math.pi, 2 * math.pi)
        got = se3.axis_angle(axis, angle)
        np.testing.assert_allclose(got, rodrigues(axis, angle), atol=TOL)
        np.testing.assert_allclose(got, pr.matrix_from_axis_angle(np.r_[axis, angle]), atol=TOL)
        np.testing.assert_allclose(got @ axis, axis, atol=1e-12)  # the axis is fixed
        assert abs(angle_between(np.eye(3), got) - abs(math.remainder(angle, 2 * math.pi))) < 1e-9


def test_axis_angle_elementary_rotations():
    for angle in (0.0, 0.4, -1.2, math.pi):
        np.testing.assert_allclose(se3.axis_angle((1, 0, 0), angle), rot_x(angle), atol=TOL)
        np.testing.assert_allclose(se3.axis_angle((0, 1, 0), angle), rot_y(angle), atol=TOL)
        np.testing.assert_allclose(se3.axis_angle((0, 0, 1), angle), rot_z(angle), atol=TOL)


# --- inverse ----------------------------------------------------------------------------------------

def test_inverse_of_random_transforms():
    rng = np.random.default_rng(7)
    for _ in range(100):
        transform = random_transform(rng)
        before = transform.copy()
        inverse = se3.inverse(transform)
        np.testing.assert_allclose(inverse, np.linalg.inv(transform), atol=1e-12)
        np.testing.assert_allclose(transform @ inverse, np.eye(4), atol=1e-12)
        np.testing.assert_allclose(inverse @ transform, np.eye(4), atol=1e-12)
        np.testing.assert_array_equal(transform, before)  # the argument is not modified
        np.testing.assert_array_equal(inverse[3], [0, 0, 0, 1])


def test_inverse_of_read_only_input_is_writable_new_array():
    frozen = se3.frozen(homogeneous(rot_z(0.5), (1, 2, 3)))
    inverse = se3.inverse(frozen)
    assert inverse is not frozen
    np.testing.assert_allclose(inverse[:3, 3], -(rot_z(0.5).T @ [1, 2, 3]), atol=TOL)


# --- slerp and interpolate --------------------------------------------------------------------------

def test_slerp_endpoints_and_midpoint():
    rng = np.random.default_rng(8)
    for q0, q1 in zip(random_unit_quaternions(rng, 100), random_unit_quaternions(rng, 100)):
        assert same_rotation_quaternion(se3.slerp(q0, q1, 0.0), q0)
        assert same_rotation_quaternion(se3.slerp(q0, q1, 1.0), q1)
        middle = se3.slerp(q0, q1, 0.5)
        assert abs(np.linalg.norm(middle) - 1.0) < 1e-12
        r0, r1, rm = (se3.quaternion_to_matrix(q) for q in (q0, q1, middle))
        total = angle_between(r0, r1)
        # the midpoint is half way along the shorter geodesic
        assert abs(angle_between(r0, rm) - total / 2) < 1e-9
        assert abs(angle_between(rm, r1) - total / 2) < 1e-9
        reference = to_xyzw(pr.quaternion_slerp(to_wxyz(q0), to_wxyz(q1), 0.5, shortest_path=True))
        assert same_rotation_quaternion(middle, reference)


@pytest.mark.parametrize("fraction", [0.1, 0.25, 0.5, 0.9])
def test_slerp_is_constant_speed_about_one_axis(fraction):
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    q0 = np.r_[axis * math.sin(0.1), math.cos(0.1)]  # 0.2 rad
    q1 = np.r_[axis * math.sin(1.1), math.cos(1.1)]  # 2.2 rad
    expected_angle = 0.2 + fraction * 2.0
    expected = np.r_[axis * math.sin(expected_angle / 2), math.cos(expected_angle / 2)]
    assert same_rotation_quaternion(se3.slerp(q0, q1, fraction), expected, tol=1e-12)


def test_slerp_takes_the_shorter_arc():
    q0 = np.array([0.0, 0.0, 0.0, 1.0])
    q1 = -np.array([0.0, 0.0, math.sin(0.3), math.cos(0.3)])  # 0.6 rad about z, with w < 0
    middle = se3.slerp(q0, q1, 0.5)
    np.testing.assert_allclose(se3.quaternion_to_matrix(middle), rot_z(0.3), atol=1e-12)


def test_slerp_of_nearly_equal_quaternions_stays_unit():
    q0 = np.array([0.0, 0.0, math.sin(0.5), math.cos(0.5)])
    q1 = np.array([0.0, 0.0, math.sin(0.5 + 1e-7), math.cos(0.5 + 1e-7)])
    for fraction in (0.0, 0.3, 1.0):
        q = se3.slerp(q0, q1, fraction)
        assert abs(np.linalg.norm(q) - 1.0) < 1e-12
        np.testing.assert_allclose(se3.quaternion_to_matrix(q), rot_z(1.0 + 2e-7 * fraction), atol=1e-9)


def test_interpolate_translation_linear_rotation_slerp():
    a = homogeneous(rot_x(0.2), (1.0, -2.0, 0.5))
    b = homogeneous(rot_x(1.4), (3.0, 2.0, -1.5))
    np.testing.assert_allclose(se3.interpolate(a, b, 0.0), a, atol=1e-12)
    np.testing.assert_allclose(se3.interpolate(a, b, 1.0), b, atol=1e-12)
    for fraction in (0.25, 0.5, 0.8):
        got = se3.interpolate(a, b, fraction)
        np.testing.assert_allclose(got[:3, 3], (1 - fraction) * a[:3, 3] + fraction * b[:3, 3], atol=1e-12)
        np.testing.assert_allclose(got[:3, :3], rot_x(0.2 + fraction * 1.2), atol=1e-12)
        np.testing.assert_array_equal(got[3], [0, 0, 0, 1])


def test_interpolate_random_against_pytransform3d_slerp():
    rng = np.random.default_rng(9)
    for _ in range(50):
        a, b = random_transform(rng), random_transform(rng)
        fraction = rng.uniform()
        got = se3.interpolate(a, b, fraction)
        qa, qb = pr.quaternion_from_matrix(a[:3, :3]), pr.quaternion_from_matrix(b[:3, :3])
        expected = pr.matrix_from_quaternion(pr.quaternion_slerp(qa, qb, fraction, shortest_path=True))
        np.testing.assert_allclose(got[:3, :3], expected, atol=1e-9)
        np.testing.assert_allclose(got[:3, 3], a[:3, 3] + fraction * (b[:3, 3] - a[:3, 3]), atol=1e-12)


# --- Denavit-Hartenberg -------------------------------------------------------------------------------

def textbook_dh(d, theta, r, alpha) -> np.ndarray:
    """The classic DH matrix as printed in textbooks (Spong, Craig's 'standard' form)."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array([
        [ct, -st * ca, st * sa, r * ct],
        [st, ct * ca, -ct * sa, r * st],
        [0, sa, ca, d],
        [0, 0, 0, 1],
    ])


def test_denavit_hartenberg_against_textbook_and_elementary_product():
    rng = np.random.default_rng(10)
    for d, theta, r, alpha in rng.uniform(-3, 3, size=(100, 4)):
        got = se3.denavit_hartenberg(d, theta, r, alpha)
        np.testing.assert_allclose(got, textbook_dh(d, theta, r, alpha), atol=TOL)
        product = (homogeneous(rot_z(theta)) @ homogeneous(None, (0, 0, d)) @ homogeneous(None, (r, 0, 0))
                   @ homogeneous(rot_x(alpha)))
        np.testing.assert_allclose(got, product, atol=TOL)


def test_denavit_hartenberg_known_values():
    # a planar link of length 2 turned by 90 degrees: the end is at (0, 2, d)
    np.testing.assert_allclose(se3.denavit_hartenberg(0.5, math.pi / 2, 2.0, 0.0) @ [0, 0, 0, 1],
                               [0, 2, 0.5, 1], atol=TOL)
    # alpha twists z into -y
    np.testing.assert_allclose(se3.denavit_hartenberg(0, 0, 0, math.pi / 2)[:3, 2], [0, -1, 0], atol=TOL)


# --- make / frozen / as_transform ------------------------------------------------------------------

def test_make_and_identity():
    transform = se3.make(rot_y(0.3), (1, 2, 3))
    np.testing.assert_allclose(transform, homogeneous(rot_y(0.3), (1, 2, 3)))
    np.testing.assert_array_equal(se3.make(), np.eye(4))
    assert not se3.IDENTITY.flags.writeable
    with pytest.raises(ValueError):
        se3.IDENTITY[0, 3] = 1.0


def test_frozen_marks_read_only():
    matrix = np.eye(4)
    assert se3.frozen(matrix) is matrix
    with pytest.raises(ValueError):
        matrix[0, 0] = 2.0


def test_as_transform_accepts_and_copies():
    source = [[1, 0, 0, 1], [0, 1, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]]
    matrix = se3.as_transform(source)
    assert matrix.dtype == float and matrix.shape == (4, 4)
    original = homogeneous(rot_z(0.7), (1, 2, 3))
    checked = se3.as_transform(original)
    assert checked is not original
    original[0, 3] = 99.0
    assert checked[0, 3] == 1.0, "the checked value is a copy"
    # a small numeric error in the rotation (as from a float32 message) is accepted
    noisy = homogeneous(rot_z(0.7))
    noisy[:3, :3] += 1e-8
    se3.as_transform(noisy)


@pytest.mark.parametrize("value", [np.eye(3), np.eye(4)[:3], np.zeros((4, 4, 1)), np.arange(16.0), [1, 2, 3]])
def test_as_transform_rejects_wrong_shapes(value):
    with pytest.raises(ValueError, match=r"4x4 .*shape"):
        se3.as_transform(value)


@pytest.mark.parametrize("row", [(0, 0, 0, 2), (0, 0.1, 0, 1), (1, 0, 0, 1), (0, 0, 0, 0)])
def test_as_transform_rejects_wrong_last_row(row):
    matrix = np.eye(4)
    matrix[3] = row
    with pytest.raises(ValueError, match="last row"):
        se3.as_transform(matrix)


@pytest.mark.parametrize("rotation", [2 * np.eye(3), np.array([[1, 0.1, 0], [0, 1, 0], [0, 0, 1]]),
                                      np.zeros((3, 3)), np.ones((3, 3))])
def test_as_transform_rejects_non_orthonormal_rotations(rotation):
    with pytest.raises(ValueError, match="orthonormal"):
        se3.as_transform(homogeneous(rotation))


def test_as_transform_rejects_non_finite_values():
    """A NaN makes every ``> tolerance`` comparison False, so it must be checked for explicitly:
    a NaN or infinite transform would poison every lookup through its edge."""
    accepted = []
    for where, index in {"rotation": (0, 0), "translation": (1, 3), "last row": (3, 0)}.items():
        for bad in (math.nan, math.inf):
            matrix = homogeneous(rot_z(0.2), (1, 2, 3))
            matrix[index] = bad
            try:
                with np.errstate(invalid="ignore"):
                    se3.as_transform(matrix)
            except ValueError:
                continue
            accepted.append(f"{bad} in the {where}")
    assert not accepted, f"as_transform accepted {', '.join(accepted)}"


def test_as_transform_rejects_reflections():
    """An orthonormal matrix with determinant -1 is a mirror, not a rotation: no rigid transform
    (and no quaternion) describes it."""
    mirror = homogeneous(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError):
        se3.as_transform(mirror)
