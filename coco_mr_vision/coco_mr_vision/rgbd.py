"""RGBDFrame: a colour image and the depth image registered to it, travelling as one port value.

An RGB-D camera delivers both halves of a frame at once; sending them as one value keeps them
paired through buffered connections (two ports could be read one frame apart). The frame also
carries what is needed to turn depth into geometry: the depth camera's intrinsics and the depth
scale of 16-bit depth. ``depth_scale`` is in units per metre, as in Open3D: 1000 for the millimetres
that :attr:`ImageFormat.DEPTH16` normally holds, 5000 for the TUM RGB-D data sets. DEPTH32F is
metres already and ignores it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from coco_core.errors import ImageError, ResourceNotFoundError

from .image import CameraIntrinsics, Image, ImageFormat
from coco_core.wire import value_type


@value_type
@dataclass(frozen=True, eq=False)
class RGBDFrame:
    """``color`` (any non-depth format) and ``depth`` (DEPTH16 or DEPTH32F) of the same size.

    ``intrinsics`` defaults to the depth image's own. Stamp and frame are the depth image's: the
    geometry is where the depth camera was.
    """

    color: Image
    depth: Image
    intrinsics: CameraIntrinsics | None = None
    depth_scale: float = 1000.0

    def __post_init__(self) -> None:
        if not self.depth.format.is_depth:
            raise ImageError(f"the depth image of an RGBDFrame must be DEPTH16 or DEPTH32F, "
                             f"got {self.depth.format.name}")
        if self.color.format.is_depth:
            raise ImageError(f"the color image of an RGBDFrame must not be depth, got {self.color.format.name}")
        if self.color.size != self.depth.size:
            raise ImageError(f"color ({self.color.width}x{self.color.height}) and depth "
                             f"({self.depth.width}x{self.depth.height}) must be registered: same size")
        if not self.depth_scale > 0:
            raise ImageError(f"depth_scale is depth units per metre and must be > 0, got {self.depth_scale}")
        object.__setattr__(self, "depth_scale", float(self.depth_scale))
        if self.intrinsics is None:
            object.__setattr__(self, "intrinsics", self.depth.intrinsics)
        intrinsics = self.intrinsics
        if intrinsics is not None and intrinsics.width and (intrinsics.width, intrinsics.height) != self.depth.size:
            raise ImageError(f"intrinsics are for {intrinsics.width}x{intrinsics.height} images, "
                             f"the frame is {self.depth.width}x{self.depth.height}")

    @property
    def stamp(self) -> float | None:
        return self.depth.stamp

    @property
    def frame_id(self) -> str:
        return self.depth.frame_id

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels."""
        return self.depth.size

    def depth_metres(self) -> np.ndarray:
        """Depth as float32 metres with NaN where unknown, using ``depth_scale`` for DEPTH16."""
        if self.depth.format is ImageFormat.DEPTH32F:
            return self.depth.data
        metres = self.depth.data.astype(np.float32) * np.float32(1.0 / self.depth_scale)
        metres[self.depth.data == 0] = np.nan
        return metres

    @classmethod
    def load(cls, color: str | Path, depth: str | Path, intrinsics: CameraIntrinsics | None = None,
             depth_scale: float = 1000.0, stamp: float | None = None, frame_id: str = "") -> RGBDFrame:
        """Read a colour file (JPEG, PNG ...) and a 16-bit depth PNG, as RGB-D data sets store them."""
        import cv2  # file reading only

        bgr = cv2.imread(str(color), cv2.IMREAD_COLOR)
        if bgr is None:
            raise ResourceNotFoundError(f"cannot read a colour image from {color}")
        raw = cv2.imread(str(depth), cv2.IMREAD_UNCHANGED)
        if raw is None:
            raise ResourceNotFoundError(f"cannot read a depth image from {depth}")
        if raw.dtype != np.uint16 or raw.ndim != 2:
            raise ImageError(f"{depth}: expected a single-channel 16-bit depth image, got {raw.dtype} {raw.shape}")
        return cls(Image(bgr, ImageFormat.BGR8, stamp, frame_id, intrinsics),
                   Image(raw, ImageFormat.DEPTH16, stamp, frame_id, intrinsics), intrinsics, depth_scale)
