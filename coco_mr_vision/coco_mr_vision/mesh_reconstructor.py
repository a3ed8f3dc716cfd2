"""MeshReconstructor: colour + depth -> an organised triangle mesh, through a pooled port.

For each frame (every ``stride``-th pixel in both directions):

1. small holes in the depth (connected regions of missing depth whose bounding box fits in
   ``hole_size`` x ``hole_size`` pixels) are filled by normalised convolution (the mean of the valid
   depth around them, OpenCV box filters); larger unknown regions stay unknown;
2. each pixel with depth becomes a vertex, back-projected with the frame's intrinsics (rays cached
   per image size);
3. each 2x2 cell gives two triangles, unless a vertex is missing or the depths in the triangle differ
   by more than ``discontinuity`` times the nearest one (the "rubber sheet" between a foreground
   object and the background is cut there);
4. normals come from the grid (cross product of the central differences), facing the camera;
   colours are the RGB of the pixel.

All of it is whole-array numpy and OpenCV work, written straight into the slot's buffer. The
vertices feed the haptic module's point-cloud structures; ``export_ply`` saves the latest mesh.
"""

from __future__ import annotations

import logging
from pathlib import Path

import cv2
import numpy as np

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import ImageError, PoolError
from coco_core.operations import operation
from coco_core.pool import Slot
from coco_core.ports import InputPort, PooledOutputPort
from coco_core.stamps import Stamped, unstamped

from .image import ImageFormat
from .mesh import MeshInfo, MeshLayout, TriangleMesh, write_ply
from .rgbd import RGBDFrame

log = logging.getLogger("coco.vision")


def fill_small_holes(depth: np.ndarray, hole_size: int) -> np.ndarray:
    """``depth`` (float32 metres, NaN unknown) with holes up to ``hole_size`` px across filled."""
    missing = ~np.isfinite(depth)
    if hole_size <= 0 or not missing.any():
        return depth
    count, labels, stats, _ = cv2.connectedComponentsWithStats(missing.astype(np.uint8), connectivity=8)
    small = (stats[:, cv2.CC_STAT_WIDTH] <= hole_size) & (stats[:, cv2.CC_STAT_HEIGHT] <= hole_size)
    small[0] = False  # label 0 is the valid depth
    fill = small[labels]
    if not fill.any():
        return depth
    known = np.where(missing, 0.0, depth).astype(np.float32)
    weight = (~missing).astype(np.float32)
    window = (2 * hole_size + 1, 2 * hole_size + 1)
    total = cv2.boxFilter(known, -1, window, normalize=False)
    weights = cv2.boxFilter(weight, -1, window, normalize=False)
    filled = depth.copy()
    with np.errstate(invalid="ignore", divide="ignore"):
        filled[fill] = total[fill] / weights[fill]
    return filled


def _grid_differences(planes: tuple[np.ndarray, ...], known: np.ndarray, axis: int) -> list[np.ndarray]:
    """Differences of neighbouring grid points along ``axis`` for each coordinate plane: central where
    both neighbours are known, else forward, else backward (NaN when neither is)."""
    ahead = np.zeros_like(known)
    behind = np.zeros_like(known)
    inner = (slice(None), slice(1, -1)) if axis == 1 else (slice(1, -1), slice(None))
    after = (slice(None), slice(2, None)) if axis == 1 else (slice(2, None), slice(None))
    before = (slice(None), slice(None, -2)) if axis == 1 else (slice(None, -2), slice(None))
    head = (slice(None), slice(0, 1)) if axis == 1 else (slice(0, 1), slice(None))
    head_next = (slice(None), slice(1, 2)) if axis == 1 else (slice(1, 2), slice(None))
    tail = (slice(None), slice(-1, None)) if axis == 1 else (slice(-1, None), slice(None))
    tail_prev = (slice(None), slice(-2, -1)) if axis == 1 else (slice(-2, -1), slice(None))
    ahead[inner], ahead[head] = known[after], known[head_next]
    behind[inner], behind[tail] = known[before], known[tail_prev]
    both, only_ahead = ahead & behind, ahead & ~behind
    out = []
    for plane in planes:
        step = np.diff(plane, axis=axis)  # step[i] = p[i+1] - p[i]
        pad = np.zeros_like(np.take(plane, [0], axis=axis))
        forward = np.concatenate([step, pad], axis=axis)
        backward = np.concatenate([pad, step], axis=axis)
        out.append(np.where(both, 0.5 * (forward + backward), np.where(only_ahead, forward, backward)))
    return out


class MeshReconstructor(Component):
    """Turns each RGB-D frame into an organised, coloured triangle mesh with normals."""

    stride = Attribute(int, 1, "use every stride-th pixel in both directions (2: a quarter of the vertices)", min=1)
    hole_size = Attribute(int, 4, "fill missing depth in holes up to this many pixels across (0: never)", min=0)
    discontinuity = Attribute(float, 0.05, "cut a triangle whose depths differ by more than this fraction "
                              "of its nearest depth", min=0.0)
    min_depth = Attribute(float, 0.1, "ignore depth nearer than this, m", min=0.0)
    max_depth = Attribute(float, 10.0, "ignore depth farther than this, m", min=0.0)

    rgbd = InputPort(RGBDFrame | Stamped, event=True, doc="registered colour + depth frames with intrinsics")
    mesh = PooledOutputPort(slots=3, doc="slots holding a TriangleMesh (read with TriangleMesh.from_slot)")

    def init(self) -> None:
        self.frames = 0
        self.skipped = 0
        """Frames not meshed because a newer one was already waiting."""
        self.stalls = 0
        """Frames skipped because every slot of the pool was held by readers."""
        self._rays: tuple[tuple, np.ndarray, np.ndarray] | None = None
        self._newest: Slot | None = None
        """The slot published last: only this component writes slots, in its own thread, and an
        operation runs in that thread too, so the slot is intact when ``export_ply`` reads it."""

    def on_update(self) -> None:
        waiting = self.rgbd.read_all()
        if not waiting:
            return
        self.skipped += len(waiting) - 1  # a mesh is only worth making for the newest frame
        frame, stamp = unstamped(waiting[-1])
        if frame.intrinsics is None:
            raise ImageError(f"{self.name}: the RGB-D frame carries no intrinsics, so its depth cannot be "
                             "back-projected")
        layout = MeshLayout(*frame.depth_metres()[::self.stride, ::self.stride].shape)
        slot = self.mesh.acquire((layout.offsets[-1],), np.uint8)
        if slot is None:
            self.stalls += 1
            return
        counts = self.reconstruct(frame, slot.array, layout)
        slot.stamp = MeshInfo(layout, counts[0], counts[1], stamp, frame.stamp, frame.frame_id)
        self.mesh.write(slot)
        self._newest = slot
        self.frames += 1

    def _ray_grid(self, frame: RGBDFrame, rows: int, cols: int) -> tuple[np.ndarray, np.ndarray]:
        k = frame.intrinsics
        assert k is not None  # on_update refuses frames without
        key = (k.fx, k.fy, k.cx, k.cy, k.skew, rows, cols, self.stride)
        if self._rays is None or self._rays[0] != key:
            v, u = np.mgrid[0:rows, 0:cols].astype(np.float32) * self.stride
            y = (v - k.cy) / k.fy
            x = (u - k.cx - k.skew * y) / k.fx
            self._rays = (key, x.astype(np.float32), y.astype(np.float32))
        return self._rays[1], self._rays[2]

    def reconstruct(self, frame: RGBDFrame, buffer: np.ndarray, layout: MeshLayout) -> tuple[int, int]:
        """Write the mesh of ``frame`` into ``buffer``; returns (vertex count, triangle count)."""
        s = self.stride
        depth = frame.depth_metres()[::s, ::s]
        depth = np.where((depth >= self.min_depth) & (depth <= self.max_depth), depth, np.nan).astype(np.float32)
        depth = fill_small_holes(depth, max(self.hole_size // s, 0) if s > 1 else self.hole_size)
        rows, cols = depth.shape
        ray_x, ray_y = self._ray_grid(frame, rows, cols)
        x, y = ray_x * depth, ray_y * depth
        valid = np.isfinite(depth)
        index = np.cumsum(valid.ravel(), dtype=np.int32).reshape(rows, cols) - 1
        vertices, normals, colors, triangles = TriangleMesh.writable(buffer, layout)
        count = int(index[-1, -1] + 1) if valid.size else 0
        for column, plane in enumerate((x, y, depth)):
            vertices[:count, column] = plane[valid]
        for column, plane in enumerate(self._normals(x, y, depth, valid)):
            normals[:count, column] = plane[valid]
        rgb = frame.color.to(ImageFormat.RGB8).data[::s, ::s]
        colors[:count] = rgb[valid]
        faces = self._triangles(depth, valid, index)
        triangles[:len(faces)] = faces
        return count, len(faces)

    @staticmethod
    def _normals(x: np.ndarray, y: np.ndarray, z: np.ndarray, known: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit normal planes from grid differences (central where both neighbours exist, else
        one-sided), turned towards the camera; with no neighbour at all, the direction back to it.
        Works plane by plane in float32: a third of the memory traffic of Nx3 rows."""
        dx = _grid_differences((x, y, z), known, axis=1)
        dy = _grid_differences((x, y, z), known, axis=0)
        nx = dx[1] * dy[2] - dx[2] * dy[1]
        ny = dx[2] * dy[0] - dx[0] * dy[2]
        nz = dx[0] * dy[1] - dx[1] * dy[0]
        length = np.sqrt(nx * nx + ny * ny + nz * nz)
        with np.errstate(invalid="ignore", divide="ignore"):
            # Facing the camera: the normal and the point (the ray from the camera) point opposite ways.
            sign = np.where(nx * x + ny * y + nz * z > 0, -1.0, 1.0).astype(np.float32) / length
            bad = ~np.isfinite(sign)
            distance = np.sqrt(x * x + y * y + z * z)
            nx, ny, nz = nx * sign, ny * sign, nz * sign
            for normal, coordinate in ((nx, x), (ny, y), (nz, z)):
                normal[bad] = -coordinate[bad] / distance[bad]
        return nx, ny, nz

    def _triangles(self, depth: np.ndarray, valid: np.ndarray, index: np.ndarray) -> np.ndarray:
        a, b = index[:-1, :-1], index[:-1, 1:]
        c, d = index[1:, :-1], index[1:, 1:]
        za, zb, zc, zd = depth[:-1, :-1], depth[:-1, 1:], depth[1:, :-1], depth[1:, 1:]
        va, vb, vc, vd = valid[:-1, :-1], valid[:-1, 1:], valid[1:, :-1], valid[1:, 1:]
        limit = self.discontinuity
        with np.errstate(invalid="ignore"):
            near1 = np.fmin(np.fmin(za, zc), zb)
            far1 = np.fmax(np.fmax(za, zc), zb)
            near2 = np.fmin(np.fmin(zb, zc), zd)
            far2 = np.fmax(np.fmax(zb, zc), zd)
            keep1 = va & vb & vc & (far1 - near1 <= limit * near1)
            keep2 = vb & vc & vd & (far2 - near2 <= limit * near2)
        # Image rows grow downwards and the camera looks along +z: (a, c, b) is counter-clockwise as
        # the camera sees it, so the triangles face the camera.
        first = np.stack([a[keep1], c[keep1], b[keep1]], axis=-1)
        second = np.stack([b[keep2], c[keep2], d[keep2]], axis=-1)
        return np.concatenate([first, second]).astype(np.int32)

    @operation
    def export_ply(self, path: str) -> str:
        """Save the latest mesh as a binary PLY; returns the path written."""
        if self._newest is None:
            raise PoolError(f"{self.name}: no mesh has been made yet")
        mesh = TriangleMesh.from_slot(self._newest)
        return str(write_ply(Path(path), mesh.vertices, mesh.triangles, mesh.normals, mesh.colors))
