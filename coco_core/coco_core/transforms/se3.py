"""Rigid transforms as 4x4 homogeneous numpy matrices, and the few operations the graph needs.

Convention: a transform ``T_a_b`` maps coordinates in frame ``b`` to frame ``a`` (it is the pose of
``b`` in ``a``), as a URDF joint origin maps child to parent and tf2's ``lookupTransform(a, b)``.
Quaternions are ``(x, y, z, w)`` as in ROS messages.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ..errors import GeometryError

IDENTITY = np.eye(4)
IDENTITY.flags.writeable = False


def frozen(matrix: np.ndarray) -> np.ndarray:
    """Mark ``matrix`` read-only: cached values are shared with every caller and must not change."""
    matrix.flags.writeable = False
    return matrix


def make(rotation: np.ndarray | None = None, translation: Sequence[float] | np.ndarray | None = None) -> np.ndarray:
    """A 4x4 transform from a 3x3 rotation and a translation (either may be omitted)."""
    transform = np.eye(4)
    if rotation is not None:
        transform[:3, :3] = rotation
    if translation is not None:
        transform[:3, 3] = translation
    return transform


def inverse(transform: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform (transpose the rotation; no general matrix inversion)."""
    result = np.eye(4)
    rotation_t = transform[:3, :3].T
    result[:3, :3] = rotation_t
    result[:3, 3] = -rotation_t @ transform[:3, 3]
    return result


def quaternion_to_matrix(q: Sequence[float] | np.ndarray) -> np.ndarray:
    """3x3 rotation of a quaternion ``(x, y, z, w)``; normalised first (on Python floats: every
    received pose goes through here, and four numbers are cheaper outside numpy)."""
    return np.array(_rotation_rows(q))


def _rotation_rows(q: Sequence[float] | np.ndarray) -> list[list[float]]:
    x, y, z, w = (float(c) for c in q)
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if not 0.0 < norm < math.inf:  # NaN or infinite components leave no direction either
        raise GeometryError(f"quaternion {(x, y, z, w)} has no direction (norm {norm}): not a rotation")
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]


def matrix_to_quaternion(rotation: np.ndarray) -> np.ndarray:
    """Quaternion ``(x, y, z, w)`` with ``w >= 0`` of a 3x3 rotation (Shepperd's method, stable for
    every angle), on Python floats: every published pose goes through here, and nine numbers read
    once with ``tolist`` cost a fifth of indexing the array element by element."""
    (a, b, c), (d, e, f), (g, h, i) = rotation.tolist()
    trace = a + e + i
    if trace > 0:
        s = 2.0 * math.sqrt(1.0 + trace)
        x, y, z, w = (h - f) / s, (c - g) / s, (d - b) / s, 0.25 * s
    elif a > e and a > i:
        s = 2.0 * math.sqrt(1.0 + a - e - i)
        x, y, z, w = 0.25 * s, (b + d) / s, (c + g) / s, (h - f) / s
    elif e > i:
        s = 2.0 * math.sqrt(1.0 + e - a - i)
        x, y, z, w = (b + d) / s, 0.25 * s, (f + h) / s, (c - g) / s
    else:
        s = 2.0 * math.sqrt(1.0 + i - a - e)
        x, y, z, w = (c + g) / s, (f + h) / s, 0.25 * s, (d - b) / s
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if w < 0:
        norm = -norm
    return np.array((x / norm, y / norm, z / norm, w / norm))


def from_pose(translation: Sequence[float], quaternion: Sequence[float]) -> np.ndarray:
    """4x4 transform of a translation and a quaternion ``(x, y, z, w)`` (a ROS Pose), built as one
    array from Python floats. A translation with a NaN or an infinity is refused as tf2 refuses it
    (a tracker that lost its target may send one): one such pose in a graph or a device target
    would make every pose composed with it NaN."""
    (a, b, c), (d, e, f), (g, h, i) = _rotation_rows(quaternion)
    x, y, z = (float(t) for t in translation)
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        raise GeometryError(f"translation {(x, y, z)} is not finite: not a pose")
    return np.array([[a, b, c, x], [d, e, f, y], [g, h, i, z], [0.0, 0.0, 0.0, 1.0]])


def to_pose(transform: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(translation, quaternion ``(x, y, z, w)``) of a 4x4 transform."""
    return transform[:3, 3].copy(), matrix_to_quaternion(transform[:3, :3])


def rpy_to_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """3x3 rotation of URDF's fixed-axis roll, pitch, yaw: ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def axis_angle(axis: Sequence[float] | np.ndarray, angle: float) -> np.ndarray:
    """3x3 rotation of ``angle`` radians about the unit ``axis`` (Rodrigues)."""
    x, y, z = axis
    c, s = math.cos(angle), math.sin(angle)
    t = 1.0 - c
    return np.array([
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ])


def slerp(q0: np.ndarray, q1: np.ndarray, fraction: float) -> np.ndarray:
    """Spherical linear interpolation between unit quaternions, along the shorter arc."""
    dot = float(np.dot(q0, q1))
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > 0.9995:  # nearly parallel: linear interpolation is exact enough and stable
        result = q0 + fraction * (q1 - q0)
        return result / np.linalg.norm(result)
    theta = math.acos(dot)
    sin_theta = math.sin(theta)
    return (math.sin((1.0 - fraction) * theta) * q0 + math.sin(fraction * theta) * q1) / sin_theta


def interpolate(a: np.ndarray, b: np.ndarray, fraction: float) -> np.ndarray:
    """Transform ``fraction`` of the way from ``a`` to ``b``: linear translation, slerp rotation."""
    translation = a[:3, 3] + fraction * (b[:3, 3] - a[:3, 3])
    rotation = quaternion_to_matrix(slerp(matrix_to_quaternion(a[:3, :3]), matrix_to_quaternion(b[:3, :3]),
                                          fraction))
    return make(rotation, translation)


def denavit_hartenberg(d: float, theta: float, r: float, alpha: float) -> np.ndarray:
    """Transform of classic Denavit-Hartenberg parameters: ``Rz(theta) Tz(d) Tx(r) Rx(alpha)``."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array([
        [ct, -st * ca, st * sa, r * ct],
        [st, ct * ca, -ct * sa, r * st],
        [0.0, sa, ca, d],
        [0.0, 0.0, 0.0, 1.0],
    ])


def as_transform(value: np.ndarray | Sequence[Sequence[float]]) -> np.ndarray:
    """Check and copy a 4x4 rigid transform given by a caller; a clear error otherwise.

    On the write path of every edge update, so the checks run on the 16 values as Python floats
    (one ``tolist``): six row dot products, a determinant and a sum, about 4x cheaper than the same
    checks as numpy calls on a 4x4 (each call costs more than its arithmetic). Every comparison is
    written so that a NaN fails it (NaN compares false), and a NaN or an infinity in the rotation
    makes the dot products NaN, so non-finite entries are refused with the rest.
    """
    matrix = np.array(value, dtype=float)
    if matrix.shape != (4, 4):
        raise GeometryError(f"expected a 4x4 homogeneous transform, got shape {matrix.shape}")
    (a, b, c, x), (d, e, f, y), (g, h, i, z), bottom = matrix.tolist()
    if not (math.isfinite(x + y + z) and math.isfinite(sum(bottom))):
        raise GeometryError("the transform has NaN or infinite entries")
    b0, b1, b2, b3 = bottom
    if abs(b0) + abs(b1) + abs(b2) + abs(b3 - 1.0) > 1e-9:
        raise GeometryError(f"the last row of a homogeneous transform must be 0 0 0 1, got {matrix[3]}")
    tolerance = 1e-6
    if not (abs(a * a + b * b + c * c - 1.0) <= tolerance and abs(d * d + e * e + f * f - 1.0) <= tolerance
            and abs(g * g + h * h + i * i - 1.0) <= tolerance and abs(a * d + b * e + c * f) <= tolerance
            and abs(a * g + b * h + c * i) <= tolerance and abs(d * g + e * h + f * i) <= tolerance):
        if not math.isfinite(a + b + c + d + e + f + g + h + i):
            raise GeometryError("the transform has NaN or infinite entries")
        raise GeometryError("the rotation part of the transform is not orthonormal")
    if a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) < 0.0:
        raise GeometryError("the rotation part of the transform is a reflection (determinant -1)")
    return matrix
