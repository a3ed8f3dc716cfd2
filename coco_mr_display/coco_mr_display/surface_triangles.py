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

import functools

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
    most ``max_edge`` metres long.

    Written for numpy's speed on a full 640x480 grid (every temporary is a float32 plane of the grid,
    no N x 3 arrays): about 2 ms at stride 3, 15 ms at stride 1 on one core."""
    rows, columns = z.shape
    if rows < 2 or columns < 2:
        return np.zeros(0, np.uint32)
    fx, fy, cx, cy = intrinsics
    known = z > 0.0  # False for NaN
    z = np.where(known, z, np.float32(0.0)).astype(np.float32, copy=False)
    x = (np.arange(columns, dtype=np.float32) * np.float32(stride / fx) - np.float32(cx / fx)) * z
    y = (np.arange(rows, dtype=np.float32)[:, None] * np.float32(stride / fy) - np.float32(cy / fy)) * z
    # The corners of each square: top-left, top-right, bottom-left, bottom-right.
    first = known[:-1, :-1] & known[1:, :-1] & known[:-1, 1:]  # (i, i+W, i+1)
    second = known[:-1, 1:] & known[1:, :-1] & known[1:, 1:]  # (i+1, i+W, i+W+1)
    if max_edge > 0.0:
        limit = np.float32(max_edge * max_edge)

        def short(a: tuple[slice, slice], b: tuple[slice, slice]) -> np.ndarray:
            """Whether the points at ``a`` are within max_edge of those at ``b`` (same shapes)."""
            total = np.zeros(z[a].shape, np.float32)
            for plane in (x, y, z):
                step = plane[a] - plane[b]
                step *= step
                total += step
            return total <= limit

        every, head, tail = slice(None), slice(None, -1), slice(1, None)
        across = short((every, tail), (every, head))  # (rows, columns-1): each point to its right
        down = short((tail, every), (head, every))  # (rows-1, columns): each point to the one below
        diagonal = short((head, tail), (tail, head))  # top-right to bottom-left of each square
        first &= down[:, :-1]
        first &= diagonal
        first &= across[:-1]
        second &= diagonal
        second &= across[1:]
        second &= down[:, 1:]
    keep = np.stack([first, second], axis=-1).ravel()  # per triangle, in grid_indices' order
    return _grid_triangles(columns, rows)[keep].ravel()


@functools.lru_cache(maxsize=8)
def _grid_triangles(width: int, height: int) -> np.ndarray:
    """:func:`grid_indices` as triangles (n x 3), read-only and kept: a new depth frame at a stride
    drawn before needs it again (7 ms at 640x480)."""
    triangles = grid_indices(width, height).reshape(-1, 3)
    triangles.flags.writeable = False
    return triangles
