"""KDTreeBuilder and HapticCloud: haptic rendering of a live point cloud.

The paper's front/back buffer, through a port: KDTreeBuilder builds the search structure of each new
cloud in its own activity (at camera rate) and writes the finished, immutable structure on its
output; HapticCloud, in the 1 kHz haptic activity, takes the newest one at the start of a cycle and
keeps rendering on the previous one until then. Nothing is built inside the haptic loop.

The structure is chosen by measurement (bench/bench_haptics.py, docs/benchmarks.md): an organised
cloud from a depth camera is searched *projectively* (its pixel grid is the structure: nothing to
build, a few microseconds per query), and an RGB-D frame is its own structure the same way (its
depth image, searched projectively with the frame's intrinsics: a copy of the depth to build, a
depth image's bytes to pass to the haptic process); a cloud without a pixel grid gets a compiled *uniform grid*
(a counting sort by cell, ~15 ms for 307,200 points; cells found by binary search inside the fit).
SciPy's cKDTree (unbalanced) stays available: it builds 3x slower, and a query from Python costs tens
of microseconds, too many to refit at every haptic cycle; pykdtree builds faster than cKDTree but its
one-point queries wake OpenMP threads, whose p99 is milliseconds on a busy machine.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import SetupError, StructureError
from coco_core.policy import NEW_DATA
from coco_core.pool import Slot
from coco_core.ports import InputPort, OutputPort
from coco_core.stamps import Stamp, Stamped, unstamped
from coco_mr_vision.image import ImageFormat
from coco_mr_vision.mesh import MeshInfo, TriangleMesh
from coco_mr_vision.pointcloud import PointCloud
from coco_mr_vision.rgbd import RGBDFrame

from . import kernel
from .implicit import Plane
from .local_surface import bounds, fit_depth, fit_grid, fit_points, fit_projective, kept_points, sort_into_cells, warm_up
from .proxy import GodObject
from .renderer import FrameLink, SurfaceRenderer
from .scene import Scene

log = logging.getLogger("coco")

STRUCTURES = ("auto", "projective", "grid", "kdtree")
KDTREE_NEIGHBOURS = 32
"""Candidates a kd-tree query returns for one local fit."""


@dataclass(frozen=True, eq=False)
class UniformGrid:
    """The cells of a uniform 3-D grid that hold points (the points themselves are sorted by cell):
    ``keys`` the occupied cells' linear indices in increasing order, ``starts``/``ends`` their points."""

    keys: np.ndarray
    starts: np.ndarray
    ends: np.ndarray
    origin: np.ndarray
    cell: float
    dims: np.ndarray

    @classmethod
    def of(cls, points: np.ndarray, cell: float) -> tuple[UniformGrid, np.ndarray]:
        """The grid of ``points`` (N x 3, float64) and the points in cell order (a compiled counting
        sort: O(N + cells)).

        ``cell`` is the size asked for; a cloud whose extent would need more than
        ``max(8 N, 1e6)`` cells of it (a real depth frame: 1-3 m deep and wide, 10 mm cells, 7e6
        cells for 270k points) gets the smallest larger cell that stays within that, so that any
        cloud gets a grid of a bounded size; the fits read the cell from the grid."""
        if len(points) == 0:
            raise StructureError("no point of the cloud passed the filters: nothing to build a grid of")
        origin, upper = bounds(points)
        limit = max(8.0 * len(points), 1e6)
        extent = upper - origin
        while True:
            dims = (np.floor(extent / cell) + 1).astype(np.int64)
            cells = float(dims[0]) * float(dims[1]) * float(dims[2])
            if cells <= limit:
                break
            cell *= max(1.01, (cells / limit) ** (1.0 / 3.0))
        ordered, keys, starts, ends = sort_into_cells(points, origin, float(cell), dims)
        return cls(keys, starts, ends, origin, float(cell), dims), ordered


@dataclass(frozen=True, eq=False)
class CloudStructure:
    """A finished search structure over one cloud, in the cloud's frame; never changed once written.

    ``kind`` is ``projective`` (``grid`` is the H x W x 3 organised cloud, ``intrinsics`` fx fy cx cy),
    ``depth`` (an RGB-D frame's: ``depth`` is its H x W depth image, metres = value x ``depth_scale``,
    0 or NaN where unknown, ``intrinsics`` fx fy cx cy and ``skew``; no ``points``: the fit
    back-projects the pixels it reads), ``grid`` (``points`` N x 3 sorted by cell, ``cells``) or
    ``kdtree`` (``points`` N x 3 and ``tree``)."""

    kind: str
    points: np.ndarray
    frame_id: str = ""
    stamp: float | None = None
    grid: np.ndarray | None = None
    intrinsics: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    tree: Any = None
    cells: UniformGrid | None = None
    depth: np.ndarray | None = None
    depth_scale: float = 1.0
    skew: float = 0.0
    build_seconds: float = 0.0
    valid: int = 0
    """Points that survived the filters."""
    origin: Stamp | None = None
    """The acquisition stamp of the frame a mesh's cloud came from, with its way so far and the step
    ``built`` (when the structure was finished): the sensor-to-touchable latency, step by step."""

    def fit(self, qx: float, qy: float, qz: float, support: float, viewpoint: tuple[float, float, float],
            out: np.ndarray, moments: np.ndarray) -> int:
        """The MLS plane at ``q`` into ``out`` (nx ny nz offset cx cy cz); the neighbours used (0: none)."""
        vx, vy, vz = viewpoint
        if self.kind == "projective":
            fx, fy, cx, cy = self.intrinsics
            return fit_projective(self.grid, fx, fy, cx, cy, qx, qy, qz, support, vx, vy, vz, moments, out)
        if self.kind == "depth":
            fx, fy, cx, cy = self.intrinsics
            return fit_depth(self.depth, self.depth_scale, fx, fy, cx, cy, self.skew, qx, qy, qz, support,
                             vx, vy, vz, moments, out)
        if self.kind == "grid":
            g = self.cells
            assert g is not None  # built with the structure of kind "grid"
            return fit_grid(self.points, g.keys, g.starts, g.ends, g.origin, g.cell, g.dims, qx, qy, qz, support,
                            vx, vy, vz, moments, out)
        distances, index = self.tree.query((qx, qy, qz), k=KDTREE_NEIGHBOURS, distance_upper_bound=support)
        found = index[index < len(self.points)]
        if len(found) == 0:
            return 0
        return fit_points(self.points[found], qx, qy, qz, support, vx, vy, vz, moments, out)


def estimate_intrinsics(grid: np.ndarray, samples: int = 4000) -> tuple[float, float, float, float] | None:
    """The pinhole (fx, fy, cx, cy) an organised cloud was back-projected with, by least squares on
    u = fx x/z + cx and v = fy y/z + cy over a sample of its valid pixels; None when the cloud is not
    a pinhole back-projection (residuals above a tenth of a pixel)."""
    height, width = grid.shape[:2]
    z = grid[:, :, 2]
    rows, cols = np.nonzero(z > 0)
    if len(rows) < 10:
        return None
    pick = np.linspace(0, len(rows) - 1, min(samples, len(rows))).astype(int)
    rows, cols = rows[pick], cols[pick]
    points = grid[rows, cols].astype(np.float64)
    result = []
    for pixel, ratio in ((cols, points[:, 0] / points[:, 2]), (rows, points[:, 1] / points[:, 2])):
        design = np.stack([ratio, np.ones_like(ratio)], axis=1)
        (focal, centre), *_ = np.linalg.lstsq(design, pixel.astype(np.float64), rcond=None)
        if np.abs(design @ (focal, centre) - pixel).max() > 0.1:
            return None
        result += [float(focal), float(centre)]
    fx, cx, fy, cy = result
    return fx, fy, cx, cy


def _fits(grid: np.ndarray, intrinsics: tuple[float, float, float, float], samples: int = 64) -> bool:
    """Whether ``samples`` pixels spread over ``grid`` project back to themselves within 0.1 pixel."""
    height, width = grid.shape[:2]
    fx, fy, cx, cy = intrinsics
    flat = np.linspace(0, height * width - 1, samples * 8).astype(int)
    rows, cols = np.divmod(flat, width)
    points = grid[rows, cols].astype(np.float64)
    valid = points[:, 2] > 0
    if valid.sum() < samples // 4:
        return False
    points, rows, cols = points[valid], rows[valid], cols[valid]
    u = fx * points[:, 0] / points[:, 2] + cx
    v = fy * points[:, 1] / points[:, 2] + cy
    return bool(np.abs(u - cols).max() < 0.1 and np.abs(v - rows).max() < 0.1)


def mesh_cloud(slot: Slot) -> PointCloud:
    """The vertices of the mesh a MeshReconstructor published in ``slot``, as a cloud in the camera's
    frame with the image's stamp; the slot is released. The vertices are copied: a structure outlives
    the slot, which the reconstructor refills with a later frame."""
    try:
        mesh = TriangleMesh.from_slot(slot)
        return PointCloud(mesh.vertices.copy(), mesh.colors.copy(), mesh.info.image_stamp, mesh.info.frame_id)
    finally:
        slot.release()


def frame_cloud(frame: RGBDFrame) -> PointCloud:
    """The valid pixels of an RGB-D frame's depth, back-projected through its intrinsics (skew
    included), as an unorganised cloud: what a grid or a kd-tree is built from."""
    k = frame.intrinsics
    if k is None:
        raise StructureError("an RGB-D frame without intrinsics cannot be back-projected into a cloud")
    z = frame.depth_metres()
    rows, cols = np.nonzero(z > 0)
    depth = z[rows, cols]
    ray_y = (rows - np.float32(k.cy)) / np.float32(k.fy)
    ray_x = (cols - np.float32(k.cx) - np.float32(k.skew) * ray_y) / np.float32(k.fx)
    points = np.stack([ray_x * depth, ray_y * depth, depth], axis=1).astype(np.float32)
    return PointCloud(points, None, frame.stamp, frame.frame_id)


class KDTreeBuilder(Component):
    """Filters each cloud and builds its search structure in its own activity; the newest finished
    structure is on ``structure`` (the front buffer) while the next is being built."""

    structure_kind = Attribute(str, "auto", "auto (projective for organised clouds and RGB-D frames, else "
                               "grid), projective, grid or kdtree", choices=STRUCTURES)
    min_distance = Attribute(float, 0.0, "m: points nearer the camera (depth) are dropped", min=0.0)
    max_distance = Attribute(float, 0.0, "m: points farther from the camera (depth) are dropped; 0: none",
                             min=0.0)
    stride = Attribute(int, 1, "keep every stride-th row and column (organised, RGB-D) or point", min=1)
    voxel = Attribute(float, 0.0, "m: one point per voxel of this size (makes the cloud unorganised); "
                      "0: off", min=0.0)
    intrinsics: Attribute[list[float]] = Attribute(list[float], [], "fx fy cx cy of an organised cloud; empty: "
                                                   "estimated from it (an RGB-D frame carries its own)")
    cell = Attribute(float, 0.01, "m: cell of the uniform grid (about HapticCloud's support); a cloud "
                     "too large for it gets the smallest larger cell that bounds the grid", min=1e-4)

    cloud = InputPort(PointCloud | np.ndarray | Slot | RGBDFrame | Stamped, event=True,
                      doc="PointCloud, an N x 3 array, a MeshReconstructor's mesh slot (its vertices), or an "
                          "RGB-D frame, Stamped or not (its depth image's valid pixels)")
    structure = OutputPort(CloudStructure, doc="the newest finished search structure")

    def on_config(self) -> None:
        if self.intrinsics and len(self.intrinsics) != 4:
            raise SetupError(f"{self.name}: intrinsics are fx fy cx cy, got {self.intrinsics}")
        warm_up()  # the compiled grid passes now, before the start gate, not at the first cloud
        self._known: tuple[tuple[int, ...], tuple[float, float, float, float]] | None = None
        self._enlarged = False
        self.built = 0

    def on_update(self) -> None:
        # Only the newest cloud is worth a structure: the older ones waiting count as dropped on the
        # connection, where the profile shows them.
        status, cloud = self.cloud.read_newest()
        if status is not NEW_DATA:
            return
        if isinstance(cloud, Slot):
            origin = cloud.stamp.stamp if isinstance(cloud.stamp, MeshInfo) else None
            self.structure.write(self.build(mesh_cloud(cloud), origin))
        else:
            self.structure.write(self.build(*unstamped(cloud)))
        self.built += 1

    def on_stop(self) -> None:
        log.info("%s: %d structures built", self.name, self.built)

    def build(self, cloud: PointCloud | np.ndarray | RGBDFrame, origin: Stamp | None = None) -> CloudStructure:
        """The structure of one cloud after the filters; ``origin``: the acquisition stamp of the
        cloud's frame, passed on with the step ``built``."""
        import time

        start = time.perf_counter()
        if isinstance(cloud, RGBDFrame):
            frame_id, stamp = cloud.frame_id, cloud.stamp
            if self.structure_kind == "projective" or (self.structure_kind == "auto" and not self.voxel):
                structure = self._depth(cloud)
            else:
                structure = self._of_points(frame_cloud(cloud).points, None)
        elif isinstance(cloud, np.ndarray):
            if cloud.ndim != 2 or cloud.shape[1] != 3:
                raise StructureError(f"{self.name}: an array cloud must be N x 3, got {cloud.shape}")
            frame_id, stamp = "", None
            structure = self._of_points(cloud, None)
        elif isinstance(cloud, PointCloud):
            frame_id, stamp = cloud.frame_id, cloud.stamp
            structure = self._of_points(cloud.points, cloud.organized)
        else:  # a Stamped value of another type reaches here: the port cannot tell what a Stamped holds
            raise StructureError(f"{self.name}: a structure is built of a PointCloud, an N x 3 array, an RGB-D "
                                 f"frame or a mesh slot, got {type(cloud).__name__}")
        end = time.perf_counter()
        return CloudStructure(**structure, frame_id=frame_id, stamp=stamp, build_seconds=end - start,
                              origin=origin.step("built", end) if origin is not None else None)

    def _of_points(self, points: np.ndarray, organized: tuple[int, int] | None) -> dict[str, Any]:
        """The fields of the structure of ``points`` (organised: ``organized`` is the grid's shape)."""
        kind = self.structure_kind
        if kind == "auto":
            kind = "projective" if organized is not None and not self.voxel else "grid"
        if kind == "projective":
            return self._projective(points, organized)
        if kind == "kdtree":
            return self._kdtree(self._unorganised(points))
        points = self._unorganised(points)
        cells, points = UniformGrid.of(points, self.cell)
        if cells.cell != self.cell and not self._enlarged:
            self._enlarged = True
            log.info("%s: a grid of %g m cells would be too large for this cloud's extent: built with "
                     "%.3g m cells", self.name, self.cell, cells.cell)
        return {"kind": "grid", "points": points, "cells": cells, "valid": len(points)}

    def _projective(self, points: np.ndarray, organized: tuple[int, int] | None) -> dict[str, Any]:
        if organized is None:
            raise StructureError(f"{self.name}: a projective structure needs an organised cloud "
                                 "(PointCloud.from_depth(..., organized=True)); use kdtree for this one")
        self._refuse_voxel()
        grid = points.reshape(organized[0], organized[1], 3)
        if self.intrinsics:
            fx, fy, cx, cy = self.intrinsics
        else:
            fx, fy, cx, cy = self._estimated(grid)
        s = self.stride
        if s > 1:  # pixel (s*i, s*j) becomes (i, j)
            grid = grid[::s, ::s]
            fx, fy, cx, cy = fx / s, fy / s, cx / s, cy / s
        if self.min_distance or self.max_distance:  # unknown depth (NaN, 0) needs no filter: never a neighbour
            grid = np.where(self._within_distances(grid[:, :, 2])[:, :, None], grid, np.float32(np.nan))
        valid = int(np.count_nonzero(grid[:, :, 2] > 0))
        return {"kind": "projective", "points": grid.reshape(-1, 3), "grid": np.ascontiguousarray(grid),
                "intrinsics": (fx, fy, cx, cy), "valid": valid}

    def _depth(self, frame: RGBDFrame) -> dict[str, Any]:
        """The frame's depth image as the structure: copied (a structure outlives the frame and is
        never changed), every stride-th pixel both ways, the pixels outside the distances unknown (0)."""
        k = frame.intrinsics
        if k is None:
            raise StructureError(f"{self.name}: the RGB-D frame carries no intrinsics, so its depth cannot be "
                                 "searched projectively")
        self._refuse_voxel()
        s = self.stride
        depth = np.array(frame.depth.data[::s, ::s])  # pixel (s*i, s*j) becomes (i, j)
        scale = 1.0 if frame.depth.format is ImageFormat.DEPTH32F else 1.0 / frame.depth_scale
        if self.min_distance or self.max_distance:
            depth[~self._within_distances(depth * scale)] = 0
        return {"kind": "depth", "points": np.empty((0, 3), np.float32), "depth": depth, "depth_scale": scale,
                "intrinsics": (k.fx / s, k.fy / s, k.cx / s, k.cy / s), "skew": k.skew / s,
                "valid": int(np.count_nonzero(depth > 0))}

    def _refuse_voxel(self) -> None:
        """A structure searched in the image's grid (projective, depth) keeps every pixel's place."""
        if self.voxel:
            raise StructureError(f"{self.name}: voxel decimation makes a cloud unorganised; use stride "
                                 "with a projective structure")

    def _within_distances(self, z: np.ndarray) -> np.ndarray:
        """Where the depths ``z`` (m) pass min_distance and max_distance (0: no bound)."""
        keep = z > self.min_distance
        if self.max_distance:
            keep &= z <= self.max_distance
        return keep

    def _estimated(self, grid: np.ndarray) -> tuple[float, float, float, float]:
        """The intrinsics of the stream: estimated on its first cloud, then only checked on a few
        pixels of each new one (a camera does not change its calibration between frames)."""
        known = self._known
        if known is not None and known[0] == grid.shape and _fits(grid, known[1]):
            return known[1]
        estimate = estimate_intrinsics(grid)
        if estimate is None:
            raise StructureError(f"{self.name}: this organised cloud is not a pinhole back-projection; "
                                 "give its intrinsics or use kdtree")
        self._known = (grid.shape, estimate)
        return estimate

    def _unorganised(self, points: np.ndarray) -> np.ndarray:
        """The finite points that pass the filters, as float64 (what the compiled fits read)."""
        points = kept_points(np.ascontiguousarray(points), float(self.min_distance), float(self.max_distance),
                             int(self.stride))
        if self.voxel:
            keys = np.floor(points / self.voxel).astype(np.int64)
            _, first = np.unique(keys, axis=0, return_index=True)
            points = points[np.sort(first)]
        return points

    def _kdtree(self, points: np.ndarray) -> dict[str, Any]:
        from scipy.spatial import cKDTree

        tree = cKDTree(points, leafsize=16, balanced_tree=False, compact_nodes=False)
        return {"kind": "kdtree", "points": points, "tree": tree, "valid": len(points)}


class HapticCloud(SurfaceRenderer):
    """The proxy of HapticImplicitSurf over the MLS plane of the cloud near it, refitted as it moves.

    Why the support grows with depth: a depth camera quantises depth in steps that grow with the
    square of the distance; a neighbourhood smaller than a few steps sees one terrace of the staircase
    where the sensor meets an oblique surface, not the surface: the fitted plane tilts with each
    terrace (forces up to 150 degrees off the floor's normal on a real PrimeSense frame at 1.2 m, with
    a 10 mm support) and the proxy falls off the terrace's edge. ``support_steps`` steps of
    ``depth_resolution`` at the query's distance average the staircase back into the surface.

    A new structure replaces the old between two cycles; a proxy in contact is put back on the new
    local surface from where it was (the kernel projects it), so it does not jump."""

    support = Attribute(float, 0.01, "m: least radius of the neighbourhood the local surface is fitted to",
                        min=1e-5)
    depth_resolution = Attribute(float, 3.7e-3, "m: the sensor's depth step at 1 m, which grows with the "
                                 "square of the distance (PrimeSense / Kinect v1: 3.7 mm, 5.5 mm at 1.2 m); "
                                 "0: points without quantisation (the support stays fixed)", min=0.0)
    support_steps = Attribute(float, 4.0, "the support spans at least this many depth steps at the "
                              "query's distance from the viewpoint", min=0.0)
    viewpoint = Attribute(list[float], [0.0, 0.0, 0.0], "where the cloud was seen from (cloud frame): "
                          "the free side of the surface")

    refit_distance = Attribute(float, 5e-4, "m: the local surface is refitted once the query point moved "
                               "this far from where it was last fitted (0: every cycle)", min=0.0)
    blend = Attribute(int, 30, "cycles over which the local surface moves from the old structure's "
                      "fit to the new one's after a swap (0: at once)", min=0)

    structure = InputPort(CloudStructure, doc="KDTreeBuilder.structure")

    def on_config(self) -> None:
        super().on_config()
        if len(self.viewpoint) != 3:
            raise SetupError(f"{self.name}: viewpoint needs 3 numbers, got {self.viewpoint}")
        warm_up()
        self.scene = Scene(Plane((0.0, 0.0, 1.0), -1e3))
        self.proxy_object = GodObject(self.scene, self.material())
        self._material_changed = False
        self.current: CloudStructure | None = None
        self.swaps = 0
        self.neighbours = 0
        """Points the last local surface was fitted to (0: no surface near the proxy)."""
        self._fit = np.zeros(7)
        self._old_fit = np.zeros(7)
        self._moments = np.zeros(11)
        self._radius = self.support
        self._cloud_frame: FrameLink | None = None
        self._fitted_at: tuple[float, float, float] | None = None
        """Where the current fit was made (cloud frame); None: refit at the next cycle."""
        self.fits = 0
        self.blind_cycles = 0
        """Cycles rendered before the first structure arrived (no surface: no force)."""
        self.previous: CloudStructure | None = None
        """The structure being blended out after a swap (None once the blend is over)."""
        self._blended = 0

    @property
    def ready(self) -> bool:
        return self.current is not None

    def on_stop(self) -> None:
        log.info("%s: %d local fits, %d structure swaps", self.name, self.fits, self.swaps)
        if self.current is None and self.blind_cycles:
            # Not a perfect run with no contact: the device went wherever the hand went, through
            # whatever the camera saw. The launcher's exit status carries it.
            message = (f"{self.name}: no cloud structure ever arrived on {self.structure.qualified_name}: "
                       f"{self.blind_cycles} haptic cycles rendered no surface")
            log.error("%s", message)
            if self.app is not None:
                self.app.report_damage(message)

    def prepare(self) -> None:
        status, structure = self.structure.read()
        if status is NEW_DATA and structure is not self.current:
            self.use(structure)

    def use(self, structure: CloudStructure) -> None:
        """Render on ``structure`` from the next cycle (what a new one on the port does): the old one
        is blended out over ``blend`` cycles."""
        if self.current is not None:
            self.swaps += 1
            self.previous, self._blended = (self.current, 0) if self.blend else (None, 0)
        self.current = structure
        self._fitted_at = None
        frame = structure.frame_id
        if self._cloud_frame is None or self._cloud_frame.frame != frame:
            self._cloud_frame = FrameLink(self, self.render_frame, frame)

    def render(self, x: float, y: float, z: float, vx: float, vy: float, vz: float) -> bool:
        structure, god = self.current, self.proxy_object
        assert god is not None  # made in on_config, before the device's loop calls render
        if structure is None:
            self.blind_cycles += 1
            god.reset()
            return False
        frame = self._cloud_frame
        assert frame is not None  # set with the first structure
        frame.refresh()
        # The local surface is fitted where the proxy is (in contact) or where the device is.
        qx, qy, qz = god.proxy if god.contact else (x, y, z)
        tx, ty, tz = frame.t
        cx, cy, cz = frame.to_frame((qx - tx, qy - ty, qz - tz))
        fit = self._fit
        last = self._fitted_at
        if (last is not None and self.previous is None
                and (cx - last[0]) ** 2 + (cy - last[1]) ** 2 + (cz - last[2]) ** 2 < self.refit_distance ** 2):
            # The plane fitted a fraction of a millimetre away still holds (its error on a curved
            # surface is d^2 / 2R: 1 um for d = 0.5 mm, R = 0.1 m); only the proxy step runs.
            return god.step(x, y, z, vx, vy, vz)
        self._radius = self.support_at(cx, cy, cz)
        self.neighbours = structure.fit(cx, cy, cz, self._radius, self.viewpoint, fit, self._moments)
        self._fitted_at = (cx, cy, cz) if self.neighbours else None
        self.fits += 1
        if self.previous is not None:
            self._blend(cx, cy, cz)
        row = self.scene.prm[0]
        if self.neighbours == 0:
            # No surface within reach (off the cloud's edge, a hole in the depth): the proxy is let
            # go, and a plane far away lets it follow the device.
            god.reset()
            row[kernel.SHAPE:kernel.SHAPE + 4] = (0.0, 0.0, 1.0, -1e3)
        else:
            nx, ny, nz = frame.to_render((fit[0], fit[1], fit[2]), False)
            px, py, pz = frame.to_render((fit[4], fit[5], fit[6]), True)
            row[kernel.SHAPE:kernel.SHAPE + 4] = (nx, ny, nz, nx * px + ny * py + nz * pz)
        return god.step(x, y, z, vx, vy, vz)

    def support_at(self, x: float, y: float, z: float) -> float:
        """The support radius (m) at ``(x, y, z)`` in the cloud's frame: ``support``, or
        ``support_steps`` depth steps at that distance from the viewpoint when wider."""
        vx, vy, vz = self.viewpoint
        squared = (x - vx) ** 2 + (y - vy) ** 2 + (z - vz) ** 2
        return max(self.support, self.support_steps * self.depth_resolution * squared)

    def _blend(self, cx: float, cy: float, cz: float) -> None:
        """Move the fit from the old structure's towards the new one's: a new cloud may place the
        surface a millimetre elsewhere (noise, a moved camera), which held for one cycle would be a
        force step of stiffness x 1 mm; spread over ``blend`` cycles it is a ramp."""
        self._blended += 1
        old = self._old_fit
        assert self.previous is not None  # render blends only while there is one
        found = self.previous.fit(cx, cy, cz, self._radius, self.viewpoint, old, self._moments)
        if self._blended >= self.blend or not found or not self.neighbours:
            self.previous = None
            return
        s = self._blended / self.blend
        fit = self._fit
        n = (1.0 - s) * old[:3] + s * fit[:3]
        n /= np.linalg.norm(n)
        c = (1.0 - s) * old[4:7] + s * fit[4:7]
        fit[:3], fit[3], fit[4:7] = n, n @ c, c

