"""View and projection matrices (OpenGL conventions, float64), including Kooima's off-axis projection.

The formulas are those of the fixed-function GL (``gluLookAt``, ``gluPerspective``, ``glFrustum``,
``glOrtho``), so a matrix here can be checked against any OpenGL text. ``look_at``, ``perspective``
and ``frustum`` are coco_core's (:mod:`coco_core.transforms.opengl`), which a ``Cull``'s view
frustum is made with too. The off-axis projection is Robert Kooima's "Generalized Perspective
Projection" (2008): for a tracked eye in front of a physical screen whose corners are known in world
coordinates, the frustum passes exactly through the screen's edges, which is what makes rendered
objects co-located with real ones (head-tracked displays).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from coco_core.errors import GeometryError
from coco_core.transforms.opengl import frustum, look_at, perspective


def orthographic(left: float, right: float, bottom: float, top: float, near: float, far: float) -> np.ndarray:
    """``glOrtho``."""
    return np.array([
        [2 / (right - left), 0.0, 0.0, -(right + left) / (right - left)],
        [0.0, 2 / (top - bottom), 0.0, -(top + bottom) / (top - bottom)],
        [0.0, 0.0, -2 / (far - near), -(far + near) / (far - near)],
        [0.0, 0.0, 0.0, 1.0],
    ])


def screen_basis(lower_left: Sequence[float], lower_right: Sequence[float],
                 upper_left: Sequence[float]) -> np.ndarray:
    """3x3 rotation whose columns are the screen's right, up and normal (towards the viewer) axes.

    Raises when the corners do not make a rectangle: Kooima's frustum assumes one.
    """
    pa, pb, pc = (np.asarray(p, float) for p in (lower_left, lower_right, upper_left))
    width, height = pb - pa, pc - pa
    if np.linalg.norm(width) < 1e-9 or np.linalg.norm(height) < 1e-9:
        raise GeometryError(f"screen corners {list(pa)}, {list(pb)}, {list(pc)} do not span a rectangle")
    vr, vu = width / np.linalg.norm(width), height / np.linalg.norm(height)
    if abs(float(vr @ vu)) > 1e-3:
        raise GeometryError(f"screen corners: lower-left -> lower-right {list(width)} and lower-left -> upper-left "
                            f"{list(height)} must be perpendicular (the screen is a rectangle)")
    return np.column_stack([vr, vu, np.cross(vr, vu)])


def off_axis(lower_left: Sequence[float], lower_right: Sequence[float], upper_left: Sequence[float],
             eye: Sequence[float] | np.ndarray, near: float, far: float) -> tuple[np.ndarray, np.ndarray]:
    """(view, projection) for ``eye`` looking through the screen with these corners (world coordinates).

    The view's axes are the screen's (so "up" is the screen's up, whatever the head does); the
    projection is an asymmetric ``glFrustum`` through the screen edges. The eye must be in front of
    the screen, on the side its normal (right x up) points to.
    """
    basis = screen_basis(lower_left, lower_right, upper_left)
    vr, vu, vn = basis.T
    pe = np.asarray(eye, float)
    va, vb, vc = (np.asarray(p, float) - pe for p in (lower_left, lower_right, upper_left))
    distance = -float(vn @ va)
    if distance <= 1e-9:
        raise GeometryError(f"eye {list(pe)} is not in front of the screen (distance {distance:.4g} m along the normal "
                            f"{list(vn)}; the normal is right x up of the corners)")
    scale = near / distance
    projection = frustum(float(vr @ va) * scale, float(vr @ vb) * scale, float(vu @ va) * scale,
                         float(vu @ vc) * scale, near, far)
    view = np.eye(4)
    view[:3, :3] = basis.T
    view[:3, 3] = -basis.T @ pe
    return view, projection


def linear_depth(ndc_z: np.ndarray, projection: np.ndarray) -> np.ndarray:
    """Distance along the view axis (metres, positive) of normalised-device depths under ``projection``.

    Works for perspective (``glFrustum``) and orthographic projections, from the matrix's third and
    fourth rows, so no separate near/far need to travel with the image.
    """
    a, b = projection[2, 2], projection[2, 3]
    if projection[3, 2] == 0.0:  # orthographic: ndc_z = a * z_eye + b
        return (b - ndc_z) / a
    return b / (a + ndc_z)  # perspective: ndc_z = (a * z_eye + b) / -z_eye
