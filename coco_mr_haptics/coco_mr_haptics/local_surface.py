"""The implicit surface of a point cloud near one point: a moving-least-squares plane.

HapticCloud renders a cloud with the same proxy as an implicit surface, over the surface the points
near the proxy describe. The choice is the MLS plane (Alexa et al.'s first-order moving least
squares): the neighbours within ``support`` of the query point, weighted by a Gaussian of their
distance to it (sigma = support / 2), give a weighted centroid ``c`` and covariance whose smallest
eigenvector is the normal ``n``; the surface is ``f(p) = n . (p - c)``. Why a plane and not a
higher-order MLS surface: a proxy only needs the surface over the millimetres it moves in one cycle,
refitting at every cycle makes the plane follow curvature, and a plane is the one local model whose
fit cannot fold over itself on noisy depth data. The normal is oriented towards the viewpoint (the
camera saw the surface from the free side).

Two ways to find the neighbours, measured in bench/bench_haptics.py:

- *projective*: an organised cloud from a depth camera is its own search structure. The query point
  is projected into the image and the pixels of a window around it are the candidates: nothing to
  build, a few microseconds per query. The depth image itself serves the same way (``fit_depth``):
  each candidate pixel is back-projected as it is read, so the structure is the depth image (a
  third of an organised cloud's bytes to pass between processes, nothing to compute to build it);
- *uniform grid* for clouds without a pixel grid (mesh vertices, merged clouds): the points sorted by
  the cell of a 3-D grid (cell = the support radius), the cells around the query point found by
  binary search; compiled, like the fits;
- *kd-tree* (SciPy's cKDTree), the usual answer, measured beside it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

MIN_NEIGHBOURS = 6


@njit(cache=True, nogil=True)
def _add(moments, px, py, pz, qx, qy, qz, support):
    """Add one candidate to the weighted moments (count, w, w p, w p p^T) if it lies within support."""
    d2 = (px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2
    if not d2 <= support * support:
        return
    w = math.exp(-d2 / (0.25 * support * support))
    moments[0] += 1.0
    moments[1] += w
    moments[2] += w * px
    moments[3] += w * py
    moments[4] += w * pz
    moments[5] += w * px * px
    moments[6] += w * px * py
    moments[7] += w * px * pz
    moments[8] += w * py * py
    moments[9] += w * py * pz
    moments[10] += w * pz * pz


@njit(cache=True, nogil=True)
def _plane(moments, vx, vy, vz, out):
    """Weighted centroid and smallest-eigenvector normal from the moments; the neighbour count."""
    count = int(moments[0])
    if count < MIN_NEIGHBOURS:
        return 0
    sw = moments[1]
    cx, cy, cz = moments[2] / sw, moments[3] / sw, moments[4] / sw
    cov = np.empty((3, 3))
    cov[0, 0] = moments[5] / sw - cx * cx
    cov[0, 1] = cov[1, 0] = moments[6] / sw - cx * cy
    cov[0, 2] = cov[2, 0] = moments[7] / sw - cx * cz
    cov[1, 1] = moments[8] / sw - cy * cy
    cov[1, 2] = cov[2, 1] = moments[9] / sw - cy * cz
    cov[2, 2] = moments[10] / sw - cz * cz
    values, vectors = np.linalg.eigh(cov)
    nx, ny, nz = vectors[0, 0], vectors[1, 0], vectors[2, 0]
    if nx * (vx - cx) + ny * (vy - cy) + nz * (vz - cz) < 0.0:
        nx, ny, nz = -nx, -ny, -nz
    out[0], out[1], out[2] = nx, ny, nz
    out[3] = nx * cx + ny * cy + nz * cz
    out[4], out[5], out[6] = cx, cy, cz
    return count


@njit(cache=True, nogil=True)
def _window(height, width, fx, fy, cx, cy, skew, qx, qy, qz, support):
    """The pixels (first row, end row, first column, end column) a projective fit reads around the
    projection of ``q``: every pixel whose point can lie within ``support`` of ``q``, so that it
    finds the neighbours a grid or a kd-tree finds. Why this wide: a point ``p`` within the
    support is at least ``qz - support`` deep, and its ray's slope differs from ``q``'s (``a``) by at
    most ``support (1 + |a|) / p_z``: a neighbour nearer the camera than ``q``, or off the image's
    centre, projects farther than ``support * fx / qz`` pixels (a window of that half-width, capped
    at 15 pixels, cut the support of a wall 2.3 m away on the TUM frame, 78 mm there, to 65 mm, and
    the proxy went 0.86 m from where the grid held it). The depth is taken as at least ``qz / 2``: a query
    within two supports of the camera is nearer than a depth camera sees."""
    near = max(qz - support, 0.5 * qz)
    reach_u = (fx * (1.0 + abs(qx / qz)) + abs(skew) * (1.0 + abs(qy / qz))) * support / near
    reach_v = fy * (1.0 + abs(qy / qz)) * support / near
    u = int(round((fx * qx + skew * qy) / qz + cx))
    v = int(round(fy * qy / qz + cy))
    half_u, half_v = int(min(reach_u, width)) + 1, int(min(reach_v, height)) + 1
    return max(0, v - half_v), min(height, v + half_v + 1), max(0, u - half_u), min(width, u + half_u + 1)


@njit(cache=True, nogil=True)
def fit_projective(grid, fx, fy, cx, cy, qx, qy, qz, support, vx, vy, vz, moments, out):
    """MLS plane at ``q`` from an organised cloud ``grid`` (H x W x 3, NaN or z <= 0 where unknown);
    returns the number of neighbours used (0: no surface near ``q``). ``out`` gets nx ny nz offset
    and the centroid; ``moments`` is scratch (11)."""
    moments[:] = 0.0
    if qz <= 1e-6:
        return 0
    top, bottom, left, right = _window(grid.shape[0], grid.shape[1], fx, fy, cx, cy, 0.0, qx, qy, qz, support)
    for row in range(top, bottom):
        for col in range(left, right):
            if grid[row, col, 2] > 0.0:
                _add(moments, grid[row, col, 0], grid[row, col, 1], grid[row, col, 2], qx, qy, qz, support)
    return _plane(moments, vx, vy, vz, out)


@njit(cache=True, nogil=True)
def fit_depth(depth, scale, fx, fy, cx, cy, skew, qx, qy, qz, support, vx, vy, vz, moments, out):
    """MLS plane at ``q`` from a depth image (H x W, uint16 or float; metres = value x ``scale``; 0 or
    NaN where unknown) seen through the pinhole ``fx fy cx cy skew``: fit_projective's window, each
    candidate pixel back-projected as it is read; as fit_projective."""
    moments[:] = 0.0
    if qz <= 1e-6:
        return 0
    top, bottom, left, right = _window(depth.shape[0], depth.shape[1], fx, fy, cx, cy, skew, qx, qy, qz, support)
    for row in range(top, bottom):
        ray_y = (row - cy) / fy
        for col in range(left, right):
            d = depth[row, col]
            if d > 0:
                z = d * scale
                _add(moments, ((col - cx - skew * ray_y) / fx) * z, ray_y * z, z, qx, qy, qz, support)
    return _plane(moments, vx, vy, vz, out)


@njit(cache=True, nogil=True)
def fit_points(points, qx, qy, qz, support, vx, vy, vz, moments, out):
    """MLS plane at ``q`` from candidate neighbours (K x 3, e.g. from a kd-tree); as fit_projective."""
    moments[:] = 0.0
    for i in range(points.shape[0]):
        _add(moments, points[i, 0], points[i, 1], points[i, 2], qx, qy, qz, support)
    return _plane(moments, vx, vy, vz, out)


@njit(cache=True, nogil=True)
def kept_points(points, min_depth, max_depth, stride):
    """Every ``stride``-th of the finite points whose depth (z) is above ``min_depth`` and, when
    ``max_depth`` > 0, at most ``max_depth``; as float64 (one compiled pass instead of numpy's
    masks, copies and conversion)."""
    n = points.shape[0]
    keep = np.empty(n, np.bool_)
    count = 0
    for p in range(n):
        x, y, z = points[p, 0], points[p, 1], points[p, 2]
        ok = np.isfinite(x) and np.isfinite(y) and np.isfinite(z) and z > min_depth
        if max_depth > 0.0 and z > max_depth:
            ok = False
        keep[p] = ok
        if ok:
            count += 1
    out = np.empty(((count + stride - 1) // stride, 3))
    seen = 0
    slot = 0
    for p in range(n):
        if keep[p]:
            if seen % stride == 0:
                out[slot, 0], out[slot, 1], out[slot, 2] = points[p, 0], points[p, 1], points[p, 2]
                slot += 1
            seen += 1
    return out


@njit(cache=True, nogil=True)
def bounds(points):
    """Lower and upper corner of N x 3 points (one pass; numpy's axis-0 reductions over N x 3 are
    strided and several times slower)."""
    lo = points[0].copy()
    hi = points[0].copy()
    for p in range(1, points.shape[0]):
        for a in range(3):
            v = points[p, a]
            if v < lo[a]:
                lo[a] = v
            elif v > hi[a]:
                hi[a] = v
    return lo, hi


@njit(cache=True, nogil=True)
def sort_into_cells(points, origin, cell, dims):
    """Points in the order of their cells' linear indices (a counting sort: two passes, no
    comparison), with the occupied cells' indices and the ranges of their points."""
    n = points.shape[0]
    cells = dims[0] * dims[1] * dims[2]
    key = np.empty(n, np.int64)
    for p in range(n):
        i = min(int((points[p, 0] - origin[0]) / cell), dims[0] - 1)
        j = min(int((points[p, 1] - origin[1]) / cell), dims[1] - 1)
        k = min(int((points[p, 2] - origin[2]) / cell), dims[2] - 1)
        key[p] = i + dims[0] * (j + dims[1] * k)
    count = np.zeros(cells + 1, np.int64)
    for p in range(n):
        count[key[p] + 1] += 1
    occupied = 0
    for c in range(cells):
        if count[c + 1] > 0:
            occupied += 1
        count[c + 1] += count[c]
    keys = np.empty(occupied, np.int64)
    starts = np.empty(occupied, np.int64)
    ends = np.empty(occupied, np.int64)
    slot = 0
    for c in range(cells):
        if count[c + 1] > count[c]:
            keys[slot], starts[slot], ends[slot] = c, count[c], count[c + 1]
            slot += 1
    ordered = np.empty((n, 3))
    for p in range(n):
        c = key[p]
        ordered[count[c]] = points[p]
        count[c] += 1
    return ordered, keys, starts, ends


@njit(cache=True, nogil=True)
def fit_grid(points, keys, starts, ends, origin, cell, dims, qx, qy, qz, support, vx, vy, vz, moments, out):
    """MLS plane at ``q`` from a uniform grid: ``points`` sorted by cell, ``keys`` the occupied cells'
    linear indices (sorted) with ``starts``/``ends`` of their points; as fit_projective."""
    moments[:] = 0.0
    reach = int(math.ceil(support / cell))
    ci = int(math.floor((qx - origin[0]) / cell))
    cj = int(math.floor((qy - origin[1]) / cell))
    ck = int(math.floor((qz - origin[2]) / cell))
    for k in range(max(ck - reach, 0), min(ck + reach, dims[2] - 1) + 1):
        for j in range(max(cj - reach, 0), min(cj + reach, dims[1] - 1) + 1):
            for i in range(max(ci - reach, 0), min(ci + reach, dims[0] - 1) + 1):
                key = i + dims[0] * (j + dims[1] * k)
                slot = np.searchsorted(keys, key)
                if slot < keys.shape[0] and keys[slot] == key:
                    for n in range(starts[slot], ends[slot]):
                        _add(moments, points[n, 0], points[n, 1], points[n, 2], qx, qy, qz, support)
    return _plane(moments, vx, vy, vz, out)


def warm_up() -> None:
    """Load both fits now (from numba's cache; compiled on the first run after a change), so that
    the first haptic cycle on a cloud does not pay for it. The argument types are those of
    KDTreeBuilder's structures: float32 pixel grids, 16-bit and float32 depth images, float64 kd-tree points."""
    out, moments = np.zeros(7), np.zeros(11)
    fit_projective(np.zeros((2, 2, 3), np.float32), 1.0, 1.0, 0.5, 0.5, 0.0, 0.0, 1.0, 0.01, 0.0, 0.0, 0.0,
                   moments, out)
    for depth in (np.zeros((2, 2), np.uint16), np.zeros((2, 2), np.float32)):  # DEPTH16 and DEPTH32F
        fit_depth(depth, 1.0, 1.0, 1.0, 0.5, 0.5, 0.0, 0.0, 0.0, 1.0, 0.01, 0.0, 0.0, 0.0, moments, out)
    fit_points(np.zeros((1, 3)), 0.0, 0.0, 1.0, 0.01, 0.0, 0.0, 0.0, moments, out)
    one = np.zeros(1, np.int64)
    sort_into_cells(np.zeros((1, 3)), np.zeros(3), 0.01, np.ones(3, np.int64))
    bounds(np.zeros((1, 3)))
    kept_points(np.zeros((1, 3), np.float32), 0.0, 0.0, 1)
    fit_grid(np.zeros((1, 3)), one, one, one + 1, np.zeros(3), 0.01, np.ones(3, np.int64), 0.0, 0.0, 0.0,
             0.01, 0.0, 0.0, 1.0, moments, out)
