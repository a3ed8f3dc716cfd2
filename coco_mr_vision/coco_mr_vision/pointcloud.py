"""Point clouds as they flow on CoCo ports: an Nx3 float32 array, optional colours, time and frame.

Like :class:`coco_mr_vision.image.Image`, a cloud is a frozen dataclass around numpy arrays, checked
by shape and dtype only, never point by point. ``stamp`` is float seconds on the graph's time base
(ROS time for clouds from ROS), ``None`` when unknown.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from coco_core.errors import ImageError

from .image import CameraIntrinsics, Image, ImageFormat, _optional_seconds
from coco_core.wire import value_type


@value_type
@dataclass(frozen=True, eq=False)
class PointCloud:
    """``points`` (Nx3 float32, metres, in ``frame_id``) and optionally ``colors`` (Nx3 uint8 RGB).

    Points may be NaN where a sensor saw nothing. An *organized* cloud keeps the sensor's grid:
    ``organized`` is its (height, width) and the points are stored row by row, so that point
    ``(row, column)`` is ``points[row * width + column]``. Clouds compare by identity (``eq=False``).
    """

    points: np.ndarray
    colors: np.ndarray | None = None
    stamp: float | None = None
    frame_id: str = ""
    organized: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        points, colors = self.points, self.colors
        if not isinstance(points, np.ndarray) or points.ndim != 2 or points.shape[1] != 3:
            shape = points.shape if isinstance(points, np.ndarray) else type(points).__name__
            raise ImageError(f"point cloud points must be an Nx3 numpy array, got {shape}")
        if points.dtype != np.float32:
            raise ImageError(f"point cloud points must be float32, got {points.dtype} "
                             "(convert with points.astype(np.float32))")
        if colors is not None:
            if not isinstance(colors, np.ndarray) or colors.shape != points.shape:
                shape = colors.shape if isinstance(colors, np.ndarray) else type(colors).__name__
                raise ImageError(f"point cloud colors must be an Nx3 array like the points {points.shape}, "
                                 f"got {shape}")
            if colors.dtype != np.uint8:
                raise ImageError(f"point cloud colors must be uint8 RGB, got {colors.dtype}")
        if self.organized is not None:
            height, width = (int(n) for n in self.organized)
            if height * width != len(points):
                raise ImageError(f"an organized {height}x{width} cloud needs {height * width} points, "
                                 f"got {len(points)}")
            object.__setattr__(self, "organized", (height, width))
        object.__setattr__(self, "stamp", _optional_seconds(self.stamp))

    def __len__(self) -> int:
        return len(self.points)

    @property
    def is_dense(self) -> bool:
        """True when every point is finite (as ``PointCloud2.is_dense``); a vectorised check."""
        return bool(np.isfinite(self.points).all())

    def finite(self) -> PointCloud:
        """The cloud without its non-finite points (no longer organized); ``self`` when all are finite."""
        keep = np.isfinite(self.points).all(axis=1)
        if keep.all():
            return self
        return PointCloud(self.points[keep], None if self.colors is None else self.colors[keep],
                          self.stamp, self.frame_id)

    @classmethod
    def from_depth(cls, depth: Image, intrinsics: CameraIntrinsics, color: Image | None = None,
                   organized: bool = False) -> PointCloud:
        """Back-project a depth image through a pinhole camera (lens distortion is ignored).

        Pixels of unknown depth (0 or NaN) are dropped, or kept as NaN points when ``organized``.
        ``color`` must be registered to the depth image (same size); any format ``to_rgb`` takes.
        The cloud has the depth image's frame and stamp.
        """
        if intrinsics.width and (intrinsics.width, intrinsics.height) != depth.size:
            raise ImageError(f"intrinsics are for {intrinsics.width}x{intrinsics.height} images, "
                             f"the depth image is {depth.width}x{depth.height}")
        z = depth.depth_metres()
        height, width = z.shape
        u = np.arange(width, dtype=np.float32)
        v = np.arange(height, dtype=np.float32)
        x = (u[None, :] - np.float32(intrinsics.cx)) * (z / np.float32(intrinsics.fx))
        y = (v[:, None] - np.float32(intrinsics.cy)) * (z / np.float32(intrinsics.fy))
        points = np.stack([x, y, z], axis=-1).reshape(-1, 3).astype(np.float32, copy=False)
        colors = None
        if color is not None:
            if color.size != depth.size:
                raise ImageError(f"the color image is {color.width}x{color.height}, "
                                 f"the depth image {depth.width}x{depth.height}")
            colors = np.ascontiguousarray(color.to_rgb()).reshape(-1, 3)
        if organized:
            if depth.format is ImageFormat.DEPTH32F:
                points[~(z > 0).reshape(-1)] = np.nan
            return cls(points, colors, depth.stamp, depth.frame_id, (height, width))
        keep = (np.isfinite(z) & (z > 0)).reshape(-1)
        return cls(points[keep], None if colors is None else colors[keep], depth.stamp, depth.frame_id)
