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

The hole filling is OpenCV's; steps 2-4 are compiled passes over the grid (:mod:`.mesh_kernel`)
that write straight into the slot's buffer. The vertices feed the haptic module's point-cloud
structures; ``export_ply`` saves the latest mesh.
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
from .mesh_kernel import mesh_points, mesh_triangles
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
        self._scratch: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        """Per-grid-point vertex index and x, y planes, kept between frames of one size."""
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
        if self._scratch is None or self._scratch[0].shape != (rows, cols):
            self._scratch = (np.empty((rows, cols), np.int32), np.empty((rows, cols), np.float32),
                             np.empty((rows, cols), np.float32))
        index, x, y = self._scratch
        vertices, normals, colors, triangles = TriangleMesh.writable(buffer, layout)
        rgb = frame.color.to(ImageFormat.RGB8).data[::s, ::s]
        count = mesh_points(depth, ray_x, ray_y, rgb, index, x, y, vertices, normals, colors)
        return count, mesh_triangles(depth, index, self.discontinuity, triangles)

    @operation
    def export_ply(self, path: str) -> str:
        """Save the latest mesh as a binary PLY; returns the path written."""
        if self._newest is None:
            raise PoolError(f"{self.name}: no mesh has been made yet")
        mesh = TriangleMesh.from_slot(self._newest)
        return str(write_ply(Path(path), mesh.vertices, mesh.triangles, mesh.normals, mesh.colors))
