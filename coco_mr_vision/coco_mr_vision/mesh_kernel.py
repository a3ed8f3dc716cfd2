"""The mesh of one depth frame in compiled passes: the depth grid, its small holes, the mesh.

Whole-array numpy made MeshReconstructor 8x slower than Open3D's bare RGB-D -> point cloud: each
step wrote and read full-size temporaries, about forty per frame. A first compiled version (one
pass for the points, one for the triangles, OpenCV for the holes and numpy for the range test) was
still 1.7x slower than Open3D: the range test on NaN depths took 1.3 ms, OpenCV's connected
components 1 ms even when no hole was small enough to fill, and the normals, computed point by point
in float64, 2.3 ms. Here:

1. :func:`depth_grid` samples, scales and range-checks the raw depth in one branch-free read of
   the frame (vectorised by the compiler);
2. :func:`fill_small_holes` finds the regions of missing depth as runs along the rows, so its work
   follows the number of runs, and fills the small ones;
3. :func:`number_known` numbers the known pixels (row-major); then :func:`mesh_rows`, for a band
   of rows, computes each row's normals in one vectorised float32 loop and writes each vertex, its
   normal, its colour and the triangles of its cells straight into the pooled slot. Bands write
   disjoint parts of the slot, so a frame can be meshed by several threads (the kernels release the
   GIL); each band's triangles start where the most triangles the rows above could give would end,
   and are moved down behind the previous band's afterwards.

Rules, per grid point with depth ``z`` and ray ``(x/z, y/z)``: the vertex is the ray times ``z``;
the normal is the cross product of the grid differences along columns and rows (central where both
neighbours are known, else one-sided), unit length, turned towards the camera, and the direction
back to the camera where no neighbour is known along an axis; each 2x2 cell ``a b / c d`` gives the
triangles ``(a, c, b)`` then ``(b, c, d)`` (counter-clockwise as the camera sees them) when their
three depths are known and differ by at most ``discontinuity`` times the nearest. The tests check
these rules against a whole-array numpy version.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# error_model="numpy": a division by zero gives inf/NaN (handled where it can happen) instead of a
# Python exception, whose check on every division kept the loops 5x slower. The fast-math flags allow
# reassociation, fused multiply-adds and approximate reciprocals, not "no NaN": NaN marks missing depth.
_FAST = {"nsz", "arcp", "contract", "afn", "reassoc"}
_NAN = np.float32(np.nan)
_ONE = np.float32(1.0)

MISSING = -1
"""``labels`` value of a pixel without depth (known pixels: 0)."""


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST)
def depth_grid(raw: np.ndarray, scale: np.float32, near: np.float32, far: np.float32, depth: np.ndarray,
               labels: np.ndarray) -> int:
    """``raw`` (depth units or float32 metres, already sampled at the stride) times ``scale`` into
    ``depth`` (float32 metres), NaN where the depth is zero, not finite or outside [near, far];
    ``labels`` 0 where known, MISSING where not. Returns the number missing.

    Branch-free, so that the compiler vectorises it: a tenth of the time of the same test with
    branches."""
    rows, cols = depth.shape
    missing = 0
    for r in range(rows):
        for c in range(cols):
            z = np.float32(raw[r, c]) * scale
            known = (z > 0) & (z >= near) & (z <= far)  # False for NaN
            depth[r, c] = z if known else _NAN
            labels[r, c] = 0 if known else MISSING
            missing += not known
    return missing


@njit(cache=True, nogil=True, error_model="numpy")
def _root(parent: np.ndarray, k: int) -> int:
    """The representative of run ``k``'s region (union-find with path halving)."""
    while parent[k] != k:
        parent[k] = parent[parent[k]]
        k = parent[k]
    return k


@njit(cache=True, nogil=True, error_model="numpy")
def _window_mean(depth: np.ndarray, labels: np.ndarray, r: int, c: int, half: int) -> float:
    """The mean of the originally known depths (label 0) within ``half`` pixels of (r, c); NaN if none."""
    rows, cols = depth.shape
    total, weight = 0.0, 0
    for rr in range(max(r - half, 0), min(r + half + 1, rows)):
        for cc in range(max(c - half, 0), min(c + half + 1, cols)):
            if labels[rr, cc] == 0:
                total += depth[rr, cc]
                weight += 1
    return total / weight if weight else np.nan


@njit(cache=True, nogil=True, error_model="numpy")
def fill_small_holes(depth: np.ndarray, labels: np.ndarray, hole_size: int, runs: np.ndarray,
                     parent: np.ndarray) -> int:
    """Fill, in place, each 8-connected region of missing depth (``labels`` MISSING) whose bounding
    box is at most ``hole_size`` pixels wide and high. Returns the number of pixels filled.

    Regions are found as runs of missing pixels along each row, joined to the runs they touch in
    the row above (union-find): the work follows the number of runs, not of pixels, and a frame whose
    holes are all large costs one scan (a flood fill took 5x longer, OpenCV's connected components
    with statistics 7x). ``runs`` (row, first, end column) and ``parent`` have room for
    ``rows * ((cols + 1) // 2)`` runs, the most a grid can have."""
    rows, cols = depth.shape
    n = 0
    above_first = above_end = 0
    for r in range(rows):
        first = n
        c = 0
        while c < cols:
            if labels[r, c] != MISSING:
                c += 1
                continue
            start = c
            while c < cols and labels[r, c] == MISSING:
                c += 1
            runs[n, 0], runs[n, 1], runs[n, 2] = r, start, c
            parent[n] = n
            n += 1
        j = above_first
        for k in range(first, n):  # runs above touching columns start - 1 .. end (8-connected)
            start, end = runs[k, 1], runs[k, 2]
            while j < above_end and runs[j, 2] < start:
                j += 1
            above = j
            while above < above_end and runs[above, 1] <= end:
                a, b = _root(parent, k), _root(parent, above)
                if a != b:
                    parent[max(a, b)] = min(a, b)
                above += 1
        above_first, above_end = first, n
    box = np.empty((n, 4), np.int32)  # per region: top, bottom, left, right
    for k in range(n):  # a region's root is its first run, so its box starts there
        root = _root(parent, k)
        r, left, right = runs[k, 0], runs[k, 1], runs[k, 2] - 1
        if root == k:
            box[k, 0], box[k, 1], box[k, 2], box[k, 3] = r, r, left, right
        else:
            box[root, 1] = max(box[root, 1], r)
            box[root, 2] = min(box[root, 2], left)
            box[root, 3] = max(box[root, 3], right)
    filled = 0
    for k in range(n):
        root = _root(parent, k)
        if box[root, 1] - box[root, 0] < hole_size and box[root, 3] - box[root, 2] < hole_size:
            r = runs[k, 0]
            for c in range(runs[k, 1], runs[k, 2]):
                depth[r, c] = _window_mean(depth, labels, r, c, hole_size)
                filled += 1
    return filled


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST)
def _row_normals(depth: np.ndarray, ray_x: np.ndarray, ray_y: np.ndarray, r: int, normal: np.ndarray) -> None:
    """Unit normals of row ``r``'s inner points from central differences, facing the camera, into
    ``normal`` (3 x cols); NaN where a neighbour is missing or the cross product vanishes.

    Branch-free over a whole row, so that the compiler vectorises it: a sixth of the time of the
    same arithmetic point by point."""
    for c in range(1, depth.shape[1] - 1):
        pz = depth[r, c]
        px, py = ray_x[r, c] * pz, ray_y[r, c] * pz
        zl, zr, zu, zd = depth[r, c - 1], depth[r, c + 1], depth[r - 1, c], depth[r + 1, c]
        ux, uy, uz = ray_x[r, c + 1] * zr - ray_x[r, c - 1] * zl, ray_y[r, c + 1] * zr - ray_y[r, c - 1] * zl, zr - zl
        vx, vy, vz = ray_x[r + 1, c] * zd - ray_x[r - 1, c] * zu, ray_y[r + 1, c] * zd - ray_y[r - 1, c] * zu, zd - zu
        nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
        square = nx * nx + ny * ny + nz * nz
        scale = (-_ONE if nx * px + ny * py + nz * pz > 0.0 else _ONE) / np.sqrt(square)
        scale = scale if square > 0.0 else _NAN  # False for NaN too
        normal[0, c], normal[1, c], normal[2, c] = nx * scale, ny * scale, nz * scale


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST)
def _difference(ray_x: np.ndarray, ray_y: np.ndarray, depth: np.ndarray, r: int, c: int, dr: int, dc: int
                ) -> tuple[float, float, float, bool]:
    """The difference of the points around (r, c) along (dr, dc): central, forward or backward (its
    scale does not matter to a normal); False when no neighbour along that axis is known."""
    rows, cols = depth.shape
    ra, ca, rb, cb = r + dr, c + dc, r - dr, c - dc
    ahead = ra < rows and ca < cols and math.isfinite(depth[ra, ca])
    behind = rb >= 0 and cb >= 0 and math.isfinite(depth[rb, cb])
    if not ahead:
        ra, ca = r, c
    if not behind:
        rb, cb = r, c
    za, zb = depth[ra, ca], depth[rb, cb]
    return ray_x[ra, ca] * za - ray_x[rb, cb] * zb, ray_y[ra, ca] * za - ray_y[rb, cb] * zb, za - zb, ahead or behind


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST)
def _edge_normal(ray_x: np.ndarray, ray_y: np.ndarray, depth: np.ndarray, r: int, c: int
                 ) -> tuple[float, float, float]:
    """The normal of a point on the grid's border or beside missing depth: one-sided differences,
    or the direction back to the camera when an axis has no known neighbour."""
    pz = depth[r, c]
    px, py = ray_x[r, c] * pz, ray_y[r, c] * pz
    ux, uy, uz, along_columns = _difference(ray_x, ray_y, depth, r, c, 0, 1)
    vx, vy, vz, along_rows = _difference(ray_x, ray_y, depth, r, c, 1, 0)
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    square = nx * nx + ny * ny + nz * nz
    if along_columns and along_rows and square > 0.0:
        scale = (-_ONE if nx * px + ny * py + nz * pz > 0.0 else _ONE) / np.sqrt(square)
        return nx * scale, ny * scale, nz * scale
    scale = -_ONE / np.sqrt(px * px + py * py + pz * pz)
    return px * scale, py * scale, pz * scale


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST)
def _row_cells(depth: np.ndarray, index: np.ndarray, r: int, limit: np.float32, keep: np.ndarray) -> None:
    """Which triangles of the cells between rows ``r`` and ``r + 1`` are kept, into ``keep`` (2 x cols):
    all three vertices known and their depths within ``limit`` times the nearest. Branch-free over the
    row (vectorised), so that only the writing of the triangles branches."""
    above, below, z_above, z_below = index[r], index[r + 1], depth[r], depth[r + 1]
    for c in range(depth.shape[1] - 1):
        a, b, cc, d = above[c], above[c + 1], below[c], below[c + 1]
        za, zb, zc, zd = z_above[c], z_above[c + 1], z_below[c], z_below[c + 1]
        near, far = min(za, zb, zc), max(za, zb, zc)
        keep[0, c] = ((a | b | cc) >= 0) & (far - near <= limit * near)  # an index -1 makes the | negative
        near, far = min(zb, zc, zd), max(zb, zc, zd)
        keep[1, c] = ((b | cc | d) >= 0) & (far - near <= limit * near)


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST)
def number_known(depth: np.ndarray, index: np.ndarray) -> int:
    """Each known grid point's vertex number (row-major) into ``index``, -1 where the depth is
    unknown; returns the number of vertices."""
    count = 0
    for r in range(depth.shape[0]):
        for c in range(depth.shape[1]):
            known = math.isfinite(depth[r, c])
            index[r, c] = count if known else -1
            count += known
    return count


@njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST)
def mesh_rows(depth: np.ndarray, ray_x: np.ndarray, ray_y: np.ndarray, color: np.ndarray, red: int, blue: int,
              discontinuity: float, index: np.ndarray, first: int, end: int, vertices: np.ndarray,
              normals: np.ndarray, colors: np.ndarray, triangles: np.ndarray, first_face: int) -> int:
    """The mesh of grid rows ``first`` to ``end`` (excluded), numbered by :func:`number_known`: their
    vertices with normals and colours (channels ``red``, 1, ``blue`` of ``color``), and the triangles
    of the cells below them, cell by cell, written from ``triangles[first_face]``. Returns the
    number of triangles written. Bands of rows write disjoint parts of every output, so they can be
    meshed on several threads at once."""
    rows, cols = depth.shape
    limit = np.float32(discontinuity)
    row_normal = np.full((3, cols), _NAN, np.float32)  # the border columns stay NaN
    keep = np.empty((2, cols), np.bool_)
    faces = first_face
    for r in range(first, end):
        inner = 0 < r < rows - 1
        if inner:
            _row_normals(depth, ray_x, ray_y, r, row_normal)
        for c in range(cols):
            i = index[r, c]
            if i < 0:
                continue
            pz = depth[r, c]
            vertices[i, 0], vertices[i, 1], vertices[i, 2] = ray_x[r, c] * pz, ray_y[r, c] * pz, pz
            nx = row_normal[0, c]
            if inner and math.isfinite(nx):
                normals[i, 0], normals[i, 1], normals[i, 2] = nx, row_normal[1, c], row_normal[2, c]
            else:
                normals[i, 0], normals[i, 1], normals[i, 2] = _edge_normal(ray_x, ray_y, depth, r, c)
        if r == rows - 1:
            break
        _row_cells(depth, index, r, limit, keep)
        for c in range(cols - 1):
            b, cc = index[r, c + 1], index[r + 1, c]
            if keep[0, c]:
                triangles[faces, 0], triangles[faces, 1], triangles[faces, 2] = index[r, c], cc, b
                faces += 1
            if keep[1, c]:
                triangles[faces, 0], triangles[faces, 1], triangles[faces, 2] = b, cc, index[r + 1, c + 1]
                faces += 1
    # The colours last, in a loop of their own: byte stores among the float ones above kept the
    # compiler reloading, 0.2-0.4 ms per frame more.
    for r in range(first, end):
        for c in range(cols):
            i = index[r, c]
            if i >= 0:
                colors[i, 0], colors[i, 1], colors[i, 2] = color[r, c, red], color[r, c, 1], color[r, c, blue]
    return faces - first_face
