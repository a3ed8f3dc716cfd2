"""Render as a real camera sees: the view and projection of a pinhole camera of known intrinsics.

An augmented camera image only lines up with the virtual objects drawn over it when the virtual
camera has the real one's pose and intrinsics; the same pair renders an RGB-D frame back onto its
own colour image (the check of GLRGBDImage). Pixel ``(u, v)`` of the camera (top-left origin, pixel
centres at integers, as OpenCV and ``sensor_msgs/CameraInfo``) lands on the centre of framebuffer
pixel ``(u, H - 1 - v)``.
"""

from __future__ import annotations

import numpy as np

from coco_core.transforms import se3

from .camera import OPTICAL_TO_GL
from .projection import frustum


def pinhole_projection(fx: float, fy: float, cx: float, cy: float, width: int, height: int,
                       near: float, far: float) -> np.ndarray:
    """``glFrustum`` of a ``width`` x ``height`` pinhole camera (lens distortion is not modelled).

    The frustum's edges are the image's outer pixel edges, ``-0.5`` and ``width - 0.5`` in OpenCV's
    pixel coordinates, scaled to the near plane.
    """
    left, right = -(cx + 0.5) * near / fx, (width - cx - 0.5) * near / fx
    top, bottom = (cy + 0.5) * near / fy, -(height - cy - 0.5) * near / fy
    return frustum(left, right, bottom, top, near, far)


def optical_view(camera_pose: np.ndarray) -> np.ndarray:
    """The view matrix of a camera whose optical frame (z forward, y down) has pose ``camera_pose``
    (4x4, optical frame -> world)."""
    return se3.inverse(np.asarray(camera_pose, dtype=float) @ OPTICAL_TO_GL)
