"""The triangles of an RGB-D grid worth drawing, chosen on the CPU once per depth frame and stride.

GLRGBDImage's grid has two triangles per square of neighbouring depth pixels. Those with a vertex of
unknown depth, and the rubber sheets (a triangle with an edge longer than ``max_edge`` spans a depth
jump between a foreground and a background), must not be drawn. The test used to run in a geometry
shader, for every triangle of every view of every frame; on Mesa's llvmpipe, which runs vertex and
geometry shaders on the drawing thread, that made the draw call about twice as long as drawing the
same grid without it (palpation view, stride 2-3: 38 -> 16 and 18 -> 8 ms of draw call). The lengths
do not depend on the view (a rigid motion keeps them), so the test runs here once for each new depth
frame and stride, in numpy on whole rows of the grid at once (a few milliseconds at stride 3), and the
index buffer drawn holds only the triangles kept: the shaders draw, nothing else.
"""

from __future__ import annotations

import numpy as np


def grid_indices(width: int, height: int) -> np.ndarray:
    """Triangle indices of a ``width`` x ``height`` vertex grid, counter-clockwise as the camera sees
    them: two triangles per square, ``(i, i+W, i+1)`` and ``(i+1, i+W, i+W+1)``."""
    top_left = (np.arange(height - 1, dtype=np.uint32)[:, None] * width
                + np.arange(width - 1, dtype=np.uint32)[None, :]).ravel()
    below, right = top_left + width, top_left + 1
    return np.stack([top_left, below, right, right, below, below + 1], axis=1).ravel()


def kept_triangles(z: np.ndarray, stride: int, intrinsics: tuple[float, float, float, float],
                   max_edge: float) -> np.ndarray:
    """Indices (uint32, three per triangle, in :func:`grid_indices`' order) of the triangles of the
    grid of depths ``z`` (metres, rows x columns: the depth pixels every ``stride`` pixels; 0 or NaN
    unknown) whose three vertices have a depth and, when ``max_edge`` > 0, whose edges are all at
    most ``max_edge`` metres long."""
    rows, columns = z.shape
    if rows < 2 or columns < 2:
        return np.zeros(0, np.uint32)
    fx, fy, cx, cy = intrinsics
    known = z > 0.0  # False for NaN
    z = np.where(known, z, 0.0).astype(np.float32)
    u = np.arange(columns, dtype=np.float32) * stride
    v = np.arange(rows, dtype=np.float32)[:, None] * stride
    points = np.stack([(u - cx) / fx * z, (v - cy) / fy * z, z], axis=-1)
    # The corners of each square: top-left, top-right, bottom-left, bottom-right.
    ok_tl, ok_tr, ok_bl, ok_br = known[:-1, :-1], known[:-1, 1:], known[1:, :-1], known[1:, 1:]
    first = ok_tl & ok_bl & ok_tr  # (i, i+W, i+1)
    second = ok_tr & ok_bl & ok_br  # (i+1, i+W, i+W+1)
    if max_edge > 0.0:
        limit = np.float32(max_edge * max_edge)

        def short(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            step = a - b
            return np.einsum("...k,...k->...", step, step) <= limit

        across = short(points[:, 1:], points[:, :-1])  # (rows, columns-1): each pixel to its right
        down = short(points[1:], points[:-1])  # (rows-1, columns): each pixel to the one below
        diagonal = short(points[:-1, 1:], points[1:, :-1])  # top-right to bottom-left of each square
        first &= down[:, :-1] & diagonal & across[:-1]
        second &= diagonal & across[1:] & down[:, 1:]
    keep = np.stack([first, second], axis=-1).ravel()
    return grid_indices(columns, rows).reshape(-1, 3)[keep].ravel()
