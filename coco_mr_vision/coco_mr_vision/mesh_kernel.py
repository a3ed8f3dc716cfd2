"""The mesh of one depth grid in compiled passes: vertices, normals, colours and triangles.

Whole-array numpy made MeshReconstructor 8x slower than Open3D's bare RGB-D -> point cloud: each
step (back-projection, grid differences for the normals, the cross product, the triangle tests)
wrote and read full-size temporaries, about forty of them per frame. Here one compiled pass per
output walks the grid once and writes straight into the pooled slot's arrays; what the passes
compute is what the numpy version computed (same vertex order, same triangle order, same rules),
checked against it in the tests.

Rules, per grid point with depth ``z`` and ray ``(x/z, y/z)``: the vertex is the ray times ``z``;
the normal is the cross product of the grid differences along columns and rows (central where both
neighbours are known, else one-sided), unit length, turned towards the camera, and the direction
back to the camera where no neighbour is known along an axis; each 2x2 cell gives the triangles
``(a, c, b)`` and ``(b, c, d)`` (counter-clockwise as the camera sees them) when their three depths
are known and differ by at most ``discontinuity`` times the nearest.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# error_model="numpy": a division by zero gives inf/NaN (handled where it can happen) instead of a
# Python exception, whose check on every division kept the loops 5x slower.


@njit(cache=True, nogil=True, error_model="numpy")
def _difference(x: np.ndarray, y: np.ndarray, z: np.ndarray, known: np.ndarray, r: int, c: int,
                dr: int, dc: int) -> tuple[float, float, float, bool]:
    """The grid difference at (r, c) along (dr, dc): central, forward or backward; False when no
    neighbour along that axis is known."""
    rows, cols = known.shape
    ra, ca, rb, cb = r + dr, c + dc, r - dr, c - dc
    ahead = ra < rows and ca < cols and known[ra, ca]
    behind = rb >= 0 and cb >= 0 and known[rb, cb]
    if ahead and behind:
        return 0.5 * (x[ra, ca] - x[rb, cb]), 0.5 * (y[ra, ca] - y[rb, cb]), 0.5 * (z[ra, ca] - z[rb, cb]), True
    if ahead:
        return x[ra, ca] - x[r, c], y[ra, ca] - y[r, c], z[ra, ca] - z[r, c], True
    if behind:
        return x[r, c] - x[rb, cb], y[r, c] - y[rb, cb], z[r, c] - z[rb, cb], True
    return 0.0, 0.0, 0.0, False


@njit(cache=True, nogil=True, error_model="numpy")
def mesh_points(depth: np.ndarray, ray_x: np.ndarray, ray_y: np.ndarray, rgb: np.ndarray, index: np.ndarray,
                x: np.ndarray, y: np.ndarray, vertices: np.ndarray, normals: np.ndarray, colors: np.ndarray) -> int:
    """Vertices (row-major over the known depths), their normals and colours; fills ``index`` (the
    vertex of each grid point, -1 where unknown) and the ``x``, ``y`` planes. Returns the count."""
    rows, cols = depth.shape
    known = np.empty((rows, cols), np.bool_)
    count = 0
    for r in range(rows):
        for c in range(cols):
            z = depth[r, c]
            ok = math.isfinite(z)
            known[r, c] = ok
            x[r, c] = ray_x[r, c] * z
            y[r, c] = ray_y[r, c] * z
            if ok:
                index[r, c] = count
                count += 1
            else:
                index[r, c] = -1
    for r in range(rows):
        for c in range(cols):
            i = index[r, c]
            if i < 0:
                continue
            px, py, pz = x[r, c], y[r, c], depth[r, c]
            vertices[i, 0], vertices[i, 1], vertices[i, 2] = px, py, pz
            colors[i, 0], colors[i, 1], colors[i, 2] = rgb[r, c, 0], rgb[r, c, 1], rgb[r, c, 2]
            if 0 < r < rows - 1 and 0 < c < cols - 1 and \
                    (index[r, c - 1] | index[r, c + 1] | index[r - 1, c] | index[r + 1, c]) >= 0:
                # inside a surface (all four neighbours known: no index is -1), the common case: central
                ux, uy, uz = 0.5 * (x[r, c + 1] - x[r, c - 1]), 0.5 * (y[r, c + 1] - y[r, c - 1]), \
                    0.5 * (depth[r, c + 1] - depth[r, c - 1])
                vx, vy, vz = 0.5 * (x[r + 1, c] - x[r - 1, c]), 0.5 * (y[r + 1, c] - y[r - 1, c]), \
                    0.5 * (depth[r + 1, c] - depth[r - 1, c])
                along_columns = along_rows = True
            else:
                ux, uy, uz, along_columns = _difference(x, y, depth, known, r, c, 0, 1)
                vx, vy, vz, along_rows = _difference(x, y, depth, known, r, c, 1, 0)
            nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
            length = math.sqrt(nx * nx + ny * ny + nz * nz)
            if along_columns and along_rows and length > 0.0:  # False for NaN too
                scale = (-1.0 if nx * px + ny * py + nz * pz > 0.0 else 1.0) / length
                normals[i, 0], normals[i, 1], normals[i, 2] = nx * scale, ny * scale, nz * scale
            else:  # no surface around it: the direction back to the camera
                distance = math.sqrt(px * px + py * py + pz * pz)
                normals[i, 0], normals[i, 1], normals[i, 2] = -px / distance, -py / distance, -pz / distance
    return count


@njit(cache=True, nogil=True, error_model="numpy")
def _kept(za: float, zb: float, zc: float, limit: float) -> bool:
    near = min(za, zb, zc)
    return max(za, zb, zc) - near <= limit * near


@njit(cache=True, nogil=True, error_model="numpy")
def mesh_triangles(depth: np.ndarray, index: np.ndarray, discontinuity: float, triangles: np.ndarray) -> int:
    """The triangles of every cell: all ``(a, c, b)`` first, then all ``(b, c, d)``, each row-major.
    Returns the count."""
    rows, cols = index.shape
    count = 0
    for second in (False, True):
        for r in range(rows - 1):
            for c in range(cols - 1):
                a, b, cc, d = index[r, c], index[r, c + 1], index[r + 1, c], index[r + 1, c + 1]
                if second:
                    if b >= 0 and cc >= 0 and d >= 0 and _kept(depth[r, c + 1], depth[r + 1, c],
                                                               depth[r + 1, c + 1], discontinuity):
                        triangles[count, 0], triangles[count, 1], triangles[count, 2] = b, cc, d
                        count += 1
                elif a >= 0 and b >= 0 and cc >= 0 and _kept(depth[r, c], depth[r + 1, c], depth[r, c + 1],
                                                              discontinuity):
                    triangles[count, 0], triangles[count, 1], triangles[count, 2] = a, cc, b
                    count += 1
    return count
