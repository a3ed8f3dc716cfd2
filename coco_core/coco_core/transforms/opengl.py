"""The view and perspective matrices of the fixed-function GL (``gluLookAt``, ``gluPerspective``,
``glFrustum``; OpenGL conventions, float64): what the display draws with
(``coco_mr_display.projection``) and what a ``Cull``'s view frustum is made of
(:meth:`coco_core.frustum.Frustum.of_camera`), one formula for both, so a frustum given as the
display's camera is the volume that camera shows.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ..errors import GeometryError
from . import se3


def look_at(eye: Sequence[float], target: Sequence[float], up: Sequence[float]) -> np.ndarray:
    """Pose (camera -> world) of a camera at ``eye`` looking at ``target``: -Z forward, +Y up."""
    eye_, forward = np.asarray(eye, float), np.asarray(target, float) - np.asarray(eye, float)
    distance = np.linalg.norm(forward)
    if distance == 0.0:
        raise GeometryError(f"look_at: the camera position {list(eye_)} equals the target")
    forward /= distance
    right = np.cross(forward, np.asarray(up, float))
    if np.linalg.norm(right) < 1e-9:
        raise GeometryError(f"look_at: the up vector {list(up)} is parallel to the viewing direction {list(forward)}")
    right /= np.linalg.norm(right)
    return se3.make(np.column_stack([right, np.cross(right, forward), -forward]), eye_)


def frustum(left: float, right: float, bottom: float, top: float, near: float, far: float) -> np.ndarray:
    """``glFrustum``: the perspective projection of a view volume bounded on the near plane."""
    return np.array([
        [2 * near / (right - left), 0.0, (right + left) / (right - left), 0.0],
        [0.0, 2 * near / (top - bottom), (top + bottom) / (top - bottom), 0.0],
        [0.0, 0.0, -(far + near) / (far - near), -2 * far * near / (far - near)],
        [0.0, 0.0, -1.0, 0.0],
    ])


def perspective(fov_y_degrees: float, aspect: float, near: float, far: float) -> np.ndarray:
    """``gluPerspective``: symmetric frustum of vertical field of view ``fov_y_degrees``."""
    top = near * math.tan(math.radians(fov_y_degrees) / 2)
    return frustum(-top * aspect, top * aspect, -top, top, near, far)
