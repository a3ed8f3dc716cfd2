"""A printable fiducial marker as a textured 3D square, for a display to draw where a robot holds it.

A simulated camera can only register a robot if the marker is in the rendered scene exactly as the
tracker expects it: the dictionary's bit pattern, the black square of side ``length`` and a white
quiet zone around it. The mesh is a two-triangle square in its xy plane, centred on its origin, with
the marker image as texture and +z its face, which is MarkerTracker's marker frame (OpenCV's: x
right, y up, z out of the marker); GLB keeps the texture in the one file.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from coco_core.errors import UnknownNameError, did_you_mean

from .marker_tracker import DICTIONARIES

PIXELS = 240
"""Texture pixels across the black square (a multiple of the bit count of every 4x4 .. 7x7 dictionary
plus its border)."""


def write_marker_mesh(path: Path, dictionary: str, marker_id: int, length: float, quiet_zone: float = 0.25) -> Path:
    """Write marker ``marker_id`` of ``dictionary`` (a ``cv2.aruco`` name) as a textured square whose
    black square is ``length`` metres wide, with a white margin of ``quiet_zone`` times that on each side."""
    import trimesh
    from PIL import Image as PILImage

    if dictionary not in DICTIONARIES:
        raise UnknownNameError(f"unknown marker dictionary {dictionary!r}; {did_you_mean(dictionary, DICTIONARIES)}")
    marker = cv2.aruco.generateImageMarker(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)),
                                           marker_id, PIXELS)
    border = round(PIXELS * quiet_zone)
    texture = np.full((PIXELS + 2 * border, PIXELS + 2 * border), 255, np.uint8)
    texture[border:border + PIXELS, border:border + PIXELS] = marker
    half = length * texture.shape[0] / PIXELS / 2
    corners = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]])
    visual = trimesh.visual.TextureVisuals(uv=[[0, 0], [1, 0], [1, 1], [0, 1]],
                                           image=PILImage.fromarray(texture).convert("RGB"))
    path.parent.mkdir(parents=True, exist_ok=True)
    trimesh.Trimesh(corners, [[0, 1, 2], [0, 2, 3]], visual=visual, process=False).export(path)
    return path
