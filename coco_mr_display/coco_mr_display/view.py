"""What one eye sees in one render pass: the contract between GLManager, its camera and its peers.

GLManager asks its camera peer for one :class:`RenderView` per eye (one in 2D and 3D mono, two in
side-by-side stereo) and hands each to every drawing peer in order. Matrices follow OpenGL's
conventions so that they go to shaders unchanged: column vectors, the camera looks down its -Z axis,
clip space is [-1, 1]^3. They are float64 here; peers convert to float32 (``.astype('f4').T``,
transposed because GLSL reads column-major) when they upload them.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np


class Eye(enum.Enum):
    """Which eye a pass renders: MONO for 2D and 3D mono, LEFT/RIGHT for stereo."""

    MONO = "mono"
    LEFT = "left"
    RIGHT = "right"


@dataclass(frozen=True)
class RenderView:
    """Matrices and target rectangle of one pass.

    ``view`` maps coordinates of the transformation-graph frame ``frame`` (the scene's world frame,
    GLManager's ``world`` attribute) to the eye; peers that take poses from the graph look them up in
    ``frame`` so that everything lands in one space.
    """

    view: np.ndarray
    """4x4 world (``frame``) -> eye."""
    projection: np.ndarray
    """4x4 eye -> clip."""
    viewport: tuple[int, int, int, int]
    """x, y, width, height in pixels of the framebuffer being drawn (y from the bottom, as GL)."""
    eye: Eye = Eye.MONO
    frame: str = "world"
    background: tuple[float, float, float, float] | None = None
    """The clear colour (r g b a) while nothing has been drawn into this view in this frame: a peer
    given it may replace the view's pixels outright (a copy instead of a depth-tested pass, see
    :mod:`.layer_cache`); None once a peer has drawn (or when the drawer does not say)."""

    @property
    def view_projection(self) -> np.ndarray:
        """4x4 world -> clip, the product shaders usually want."""
        return self.projection @ self.view

    @property
    def camera_position(self) -> np.ndarray:
        """Position of the eye in world coordinates (for lighting and billboards)."""
        return np.linalg.inv(self.view)[:3, 3]

    @property
    def aspect(self) -> float:
        """Width over height of the viewport."""
        return self.viewport[2] / self.viewport[3]
