"""MeshReconstructor: colour + depth -> an organised triangle mesh, through a pooled port.

For each frame (every ``stride``-th pixel in both directions):

1. depth outside [``min_depth``, ``max_depth``] is missing; small holes in the depth (connected
   regions of missing depth whose bounding box fits in ``hole_size`` x ``hole_size`` pixels) are
   filled with the mean of the known depth around each pixel; larger unknown regions stay unknown;
2. each pixel with depth becomes a vertex, back-projected with the frame's intrinsics (rays cached
   per image size);
3. each 2x2 cell gives two triangles, unless a vertex is missing or the depths in the triangle differ
   by more than ``discontinuity`` times the nearest one (the "rubber sheet" between a foreground
   object and the background is cut there);
4. normals come from the grid (cross product of the central differences), facing the camera;
   colours are the RGB of the pixel (BGR8 frames are read as they are, other formats converted).

All four steps are compiled passes over the grid (:mod:`.mesh_kernel`, which says why) that write
straight into the slot's buffer. Steps 2-4 run as ``threads`` bands of rows at once, on the
activity's thread and helper threads of this component (the passes release the GIL), like
OpenCV's own parallel loops: the component still never knows which activity runs it. The vertices
feed the haptic module's point-cloud structures; ``export_ply`` saves the latest mesh.
"""

from __future__ import annotations

import logging
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import numpy as np

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import ImageError, PoolError
from coco_core.operations import operation
from coco_core.pool import Slot
from coco_core.policy import NEW_DATA
from coco_core.ports import InputPort, PooledOutputPort
from coco_core.stamps import Stamped, unstamped

from .image import CameraIntrinsics, Image, ImageFormat
from .mesh import MeshInfo, MeshLayout, TriangleMesh, write_ply
from .mesh_kernel import depth_grid, fill_small_holes, mesh_rows, number_known
from .rgbd import RGBDFrame

log = logging.getLogger("coco.vision")

WARM_UP_SIDE = 8
"""Grid points a side of the frame meshed in ``on_config`` to compile the passes."""


_BANDS_FROM_POINTS = 40_000
"""Grids with fewer points are meshed in one band."""


def _sampled(image: np.ndarray, stride: int) -> np.ndarray:
    """Every ``stride``-th pixel of ``image``; the array itself at stride 1, which the compiled passes
    read as contiguous (a ``[::1, ::1]`` view would compile to their slower strided version)."""
    return image if stride == 1 else image[::stride, ::stride]


class MeshReconstructor(Component):
    """Turns each RGB-D frame into an organised, coloured triangle mesh with normals."""

    stride = Attribute(int, 1, "use every stride-th pixel in both directions (2: a quarter of the vertices)", min=1)
    hole_size = Attribute(int, 4, "fill missing depth in holes up to this many pixels across (0: never)", min=0)
    discontinuity = Attribute(float, 0.05, "cut a triangle whose depths differ by more than this fraction "
                              "of its nearest depth", min=0.0)
    min_depth = Attribute(float, 0.1, "ignore depth nearer than this, m", min=0.0)
    max_depth = Attribute(float, 10.0, "ignore depth farther than this, m", min=0.0)
    threads = Attribute(int, 2, "mesh each frame as this many bands of rows at once: the activity's thread "
                        "and threads - 1 helpers of this component (1: the activity's thread only)", min=1)

    rgbd = InputPort(RGBDFrame | Stamped, event=True, doc="registered colour + depth frames with intrinsics")
    mesh = PooledOutputPort(slots=3, doc="slots holding a TriangleMesh (read with TriangleMesh.from_slot)")

    def init(self) -> None:
        self.frames = 0
        self.stalls = 0
        """Frames skipped because every slot of the pool was held by readers."""
        self._rays: tuple[tuple, np.ndarray, np.ndarray] | None = None
        self._scratch: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        """The depth grid, the per-grid-point labels (then vertex index) and the hole filling's runs
        and their parents, kept between frames of one size."""
        self._helpers: tuple[int, ThreadPoolExecutor] | None = None
        """How many threads mesh the bands after the first, and their pool, made at the first frame
        large enough."""
        self._newest: Slot | None = None
        """The slot published last: only this component writes slots, in its own thread, and an
        operation runs in that thread too, so the slot is intact when ``export_ply`` reads it."""

    def on_config(self) -> None:
        """Compile (or load from numba's cache) the meshing passes now, at this stride, for both depth
        encodings and both colour orders: on a fresh install the first compilation takes seconds,
        and made at the first frame it held the first meshes back that long (the palpation app's
        first presses found no surface in a fresh clone's run). Configured here, it is done before
        the application's start gate opens."""
        side = WARM_UP_SIDE * self.stride
        layout = MeshLayout(WARM_UP_SIDE, WARM_UP_SIDE)
        intrinsics = CameraIntrinsics(side, side, float(side), float(side), side / 2, side / 2)
        for depth, depth_format, color_format in ((np.full((side, side), 1000, np.uint16), ImageFormat.DEPTH16,
                                                   ImageFormat.BGR8),
                                                  (np.full((side, side), 1.0, np.float32), ImageFormat.DEPTH32F,
                                                   ImageFormat.RGB8)):
            frame = RGBDFrame(Image(np.zeros((side, side, 3), np.uint8), color_format, 0.0, ""),
                              Image(depth, depth_format, 0.0, ""), intrinsics)
            self.reconstruct(frame, np.empty(layout.offsets[-1], np.uint8), layout)
        self._scratch = self._rays = None

    def on_update(self) -> None:
        # A mesh is only worth making for the newest frame: the older ones waiting count as dropped
        # on the connection, where the profile shows them.
        status, value = self.rgbd.read_newest()
        if status is not NEW_DATA:
            return
        frame, stamp = unstamped(value)
        if frame.intrinsics is None:
            raise ImageError(f"{self.name}: the RGB-D frame carries no intrinsics, so its depth cannot be "
                             "back-projected")
        height, width = frame.depth.data.shape[:2]
        layout = MeshLayout(-(-height // self.stride), -(-width // self.stride))
        slot = self.mesh.acquire((layout.offsets[-1],), np.uint8)
        if slot is None:
            self.stalls += 1
            return
        counts = self.reconstruct(frame, slot.array, layout)
        slot.stamp = MeshInfo(layout, counts[0], counts[1], stamp.step("meshed") if stamp is not None else None,
                              frame.stamp, frame.frame_id)
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
        rows, cols, s = layout.rows, layout.cols, self.stride
        if self._scratch is None or self._scratch[0].shape != (rows, cols):
            most_runs = rows * ((cols + 1) // 2)
            self._scratch = (np.empty((rows, cols), np.float32), np.empty((rows, cols), np.int32),
                             np.empty((most_runs, 3), np.int32), np.empty(most_runs, np.int32))
        depth, labels, runs, parent = self._scratch
        scale = np.float32(1.0 if frame.depth.format is ImageFormat.DEPTH32F else 1.0 / frame.depth_scale)
        near, far = np.float32(self.min_depth), np.float32(self.max_depth)
        if depth_grid(_sampled(frame.depth.data, s), scale, near, far, depth, labels):
            fill_small_holes(depth, labels, self.hole_size // s, runs, parent)
        ray_x, ray_y = self._ray_grid(frame, rows, cols)
        color = frame.color if frame.color.format is ImageFormat.BGR8 else frame.color.to(ImageFormat.RGB8)
        red, blue = (2, 0) if color.format is ImageFormat.BGR8 else (0, 2)
        vertices, normals, colors, triangles = TriangleMesh.writable(buffer, layout)
        count = number_known(depth, labels)
        grid = (depth, ray_x, ray_y, _sampled(color.data, s), red, blue, self.discontinuity, labels)
        outputs = (vertices, normals, colors, triangles)
        (first, end, start), *others = self._bands(rows, cols)
        helpers: list[Future[int]] = []
        if others:
            pool = self._helper_pool(len(others))
            helpers = [pool.submit(mesh_rows, *grid, top, bottom, *outputs, face) for top, bottom, face in others]
        try:
            faces = mesh_rows(*grid, first, end, *outputs, start)
        finally:  # the helpers write into the slot: never hand it on before they are done
            done: list[int] = [helper.result() for helper in helpers]
        for (_, _, face), written in zip(others, done):  # each band's triangles behind the previous ones
            triangles[faces:faces + written] = triangles[face:face + written]
            faces += written
        return count, faces

    def _bands(self, rows: int, cols: int) -> list[tuple[int, int, int]]:
        """Row ranges to mesh at once, each with the triangle its triangles are written from (where the
        most triangles the rows above could give end): ``threads`` of them for grids worth the
        hand-off to a helper thread (about 50 us, a tenth of a 160x120 grid's mesh), else one."""
        bands = min(self.threads, rows) if rows * cols >= _BANDS_FROM_POINTS else 1
        edges = [rows * band // bands for band in range(bands + 1)]
        return [(first, end, 2 * (cols - 1) * first) for first, end in zip(edges[:-1], edges[1:])]

    def _helper_pool(self, size: int) -> ThreadPoolExecutor:
        if self._helpers is None or self._helpers[0] != size:
            self._close_helpers()
            self._helpers = (size, ThreadPoolExecutor(size, thread_name_prefix=f"coco:{self.name} (mesh band)"))
        return self._helpers[1]

    def _close_helpers(self) -> None:
        if self._helpers is not None:
            self._helpers[1].shutdown()
            self._helpers = None

    def on_stop(self) -> None:
        self._close_helpers()

    @operation
    def export_ply(self, path: str) -> str:
        """Save the latest mesh as a binary PLY; returns the path written."""
        if self._newest is None:
            raise PoolError(f"{self.name}: no mesh has been made yet")
        mesh = TriangleMesh.from_slot(self._newest)
        return str(write_ply(Path(path), mesh.vertices, mesh.triangles, mesh.normals, mesh.colors))
