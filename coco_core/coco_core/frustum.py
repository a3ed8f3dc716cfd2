"""A receiver's view frustum, for a ``Cull`` that routes by what each viewer sees (FlowVR Render).

FlowVR Render sends each primitive only to the renderers whose view frustum its bounding box meets.
A frustum is given as what the display has at hand: its camera (``coco_mr_display``'s
``GLCameraManager``: ``position``, ``look_at``, ``up``, ``fov_y``, ``near``, ``far``, and the
window's ``aspect``), or the 4x4 view-projection matrix it draws with (any projection: an off-axis
screen's, one eye of a stereo pair). Either way it is that matrix, in OpenGL's clip convention: a
world point ``p`` is seen when ``-w <= x, y, z <= w`` for ``(x, y, z, w) = M p``.

The six planes are the matrix's rows combined (Gribb and Hartmann: ``row3 + row0`` is the left
plane, ``row3 - row0`` the right, and so on), each oriented inwards. A box is **outside** when it
lies wholly on the outer side of one plane: its corner farthest along that plane's normal (the
"positive vertex") is outside it. Otherwise it is kept. The test is conservative: a box beside a
corner or an edge of the frustum, outside it but not wholly behind any one plane, is kept (it costs
the receiver one message its renderer then clips); a box that meets the frustum is never culled.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from .errors import GeometryError

Plane = tuple[float, float, float, float]
"""``(a, b, c, d)``: the points with ``a x + b y + c z + d >= 0`` are on its inner side."""


class Frustum:
    """The view volume of a view-projection ``matrix`` (16 numbers, row by row), as six planes;
    ``given`` says how it was given, for ``--check``, the profile and the graph."""

    __slots__ = ("matrix", "planes", "given")

    def __init__(self, matrix: Sequence[float], given: str = "view_projection") -> None:
        values = tuple(float(value) for value in matrix)
        if len(values) != 16 or not all(math.isfinite(value) for value in values):
            raise GeometryError(f"a view-projection matrix is 16 finite numbers (row by row), got {len(values)}: "
                                f"{' '.join(f'{value:g}' for value in values)}")
        rows = [values[4 * row:4 * row + 4] for row in range(4)]
        planes: list[Plane] = []
        for axis, (low, high) in enumerate((("left", "right"), ("bottom", "top"), ("near", "far"))):
            for sign, side in ((1.0, low), (-1.0, high)):
                a, b, c, d = (rows[3][k] + sign * rows[axis][k] for k in range(4))
                length = math.sqrt(a * a + b * b + c * c)
                if length < 1e-12:
                    raise GeometryError(f"the view-projection matrix has no {side} plane (its rows 4 and "
                                        f"{axis + 1} give a zero normal): it is not a projection")
                planes.append((a / length, b / length, c / length, d / length))
        self.matrix = values
        self.planes = tuple(planes)
        """Left, right, bottom, top, near, far; each normal of unit length, pointing inwards."""
        self.given = given

    @classmethod
    def of_camera(cls, position: Sequence[float], look_at: Sequence[float], up: Sequence[float], fov_y: float,
                  aspect: float, near: float, far: float) -> Frustum:
        """The frustum of a perspective camera at ``position`` looking at ``look_at`` (``up`` shown
        upwards), ``fov_y`` degrees high, ``aspect`` (width / height) wide, from ``near`` to ``far``:
        what ``GLCameraManager`` draws with these attributes, in a window of that aspect."""
        if not 0.0 < fov_y < 180.0:
            raise GeometryError(f"fov_y={fov_y:g}: expected a vertical field of view in degrees, between 0 and 180")
        if not (math.isfinite(aspect) and aspect > 0.0):
            raise GeometryError(f"aspect={aspect:g}: expected the window's width / height, > 0")
        if not (0.0 < near < far < math.inf):
            raise GeometryError(f"near={near:g} far={far:g}: expected 0 < near < far")
        forward = np.asarray(look_at, float) - np.asarray(position, float)
        if not np.any(forward):
            raise GeometryError(f"the camera's position {_words(position)} is its look_at point: it looks nowhere")
        if np.linalg.norm(np.cross(forward / np.linalg.norm(forward), np.asarray(up, float))) < 1e-9:
            raise GeometryError(f"up={_words(up)} is parallel to the viewing direction (from {_words(position)} "
                                f"to {_words(look_at)}): give another up")
        from .transforms import opengl, se3  # here: the model imports this module, not the graph's package

        view = se3.inverse(opengl.look_at(position, look_at, up))  # world -> camera (-z forward)
        projection = opengl.perspective(fov_y, aspect, near, far)
        given = (f"frustum from {_words(position)} to {_words(look_at)}, fov_y {fov_y:g}, aspect {aspect:g}, "
                 f"near {near:g}, far {far:g}")
        return cls((projection @ view).ravel().tolist(), given)

    def meets(self, low: Sequence[float], high: Sequence[float]) -> bool:
        """Whether the box from ``low`` to ``high`` (3 numbers each) may meet the frustum: False
        only when it is wholly outside one of the planes (see the module's docstring)."""
        x0, y0, z0 = low
        x1, y1, z1 = high
        for a, b, c, d in self.planes:
            if a * (x1 if a >= 0 else x0) + b * (y1 if b >= 0 else y0) + c * (z1 if c >= 0 else z0) + d < 0:
                return False
        return True

    def __repr__(self) -> str:
        return f"Frustum({self.given})"


def _words(vector: Sequence[float]) -> str:
    return " ".join(f"{float(value):g}" for value in vector)
