"""Images and camera intrinsics as they flow on CoCo ports.

An :class:`Image` is a numpy array with the natural shape of its :class:`ImageFormat` (``HxW`` for
grey and depth, ``HxWx3`` for RGB, ``HxWx2`` for packed YUYV, ``(H*3/2)xW`` for planar I420), plus
the acquisition time and the frame of the camera that produced it. Pixels are never touched one by
one in Python: checks look at shape and dtype only, and conversions are numpy or OpenCV calls.

Times (``stamp``) are float seconds on the graph's time base (ROS time when the image came from
ROS), the same as :class:`coco_core.transforms.samples.TransformSample`, so that an image and the
camera pose at that instant can be matched directly. ``None`` means "unknown". The process-local
``coco_core.stamps.Stamp`` (for latency measurement) is a different clock and travels, when wanted,
in a ``Stamped`` wrapper around the image.

:class:`CameraIntrinsics` holds a calibration as in a ``sensor_msgs/CameraInfo`` (pinhole matrix,
distortion model and coefficients, rectification and projection); an image may carry the intrinsics
of the camera that produced it, so that they travel with the stream.
"""

from __future__ import annotations

import enum
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from coco_core.errors import ImageError, UnknownNameError, WrongTypeError
from coco_core.files import DATA_FILE_LIMIT, read_regular_file
from coco_core.wire import value_type


@value_type
class ImageFormat(enum.Enum):
    """Pixel layouts; each fixes the dtype and the shape of :attr:`Image.data`."""

    GRAY8 = "GRAY8"        # uint8 HxW
    GRAY16 = "GRAY16"      # uint16 HxW
    RGB8 = "RGB8"          # uint8 HxWx3, red first
    BGR8 = "BGR8"          # uint8 HxWx3, blue first (OpenCV's order)
    RGBA8 = "RGBA8"        # uint8 HxWx4
    BGRA8 = "BGRA8"        # uint8 HxWx4
    YUYV = "YUYV"          # uint8 HxWx2, packed 4:2:2: Y0 U0 Y1 V0 for each pair of pixels (W even)
    I420 = "I420"          # uint8 (H*3/2)xW, planar 4:2:0: Y plane, then U, then V (H and W even)
    DEPTH32F = "DEPTH32F"  # float32 HxW, metres; NaN (or 0) where unknown
    DEPTH16 = "DEPTH16"    # uint16 HxW, millimetres; 0 where unknown

    @property
    def dtype(self) -> np.dtype:
        """The (native byte order) dtype of the data."""
        return _LAYOUTS[self][0]

    @property
    def channels(self) -> int:
        """Size of the last axis of the data, 1 for 2-D layouts (grey, depth, I420)."""
        return _LAYOUTS[self][1]

    @property
    def is_depth(self) -> bool:
        return self in (ImageFormat.DEPTH32F, ImageFormat.DEPTH16)

    @property
    def bytes_per_pixel(self) -> float:
        """Average bytes per pixel (1.5 for I420)."""
        if self is ImageFormat.I420:
            return 1.5
        return self.dtype.itemsize * self.channels

    def shape(self, width: int, height: int) -> tuple[int, ...]:
        """Shape of the data of a ``width`` x ``height`` image in this format."""
        if self is ImageFormat.I420:
            return (height * 3 // 2, width)
        if self.channels == 1:
            return (height, width)
        return (height, width, self.channels)


_LAYOUTS: dict[ImageFormat, tuple[np.dtype, int]] = {
    ImageFormat.GRAY8: (np.dtype(np.uint8), 1),
    ImageFormat.GRAY16: (np.dtype(np.uint16), 1),
    ImageFormat.RGB8: (np.dtype(np.uint8), 3),
    ImageFormat.BGR8: (np.dtype(np.uint8), 3),
    ImageFormat.RGBA8: (np.dtype(np.uint8), 4),
    ImageFormat.BGRA8: (np.dtype(np.uint8), 4),
    ImageFormat.YUYV: (np.dtype(np.uint8), 2),
    ImageFormat.I420: (np.dtype(np.uint8), 1),
    ImageFormat.DEPTH32F: (np.dtype(np.float32), 1),
    ImageFormat.DEPTH16: (np.dtype(np.uint16), 1),
}


def _as_format(value: ImageFormat | str) -> ImageFormat:
    if isinstance(value, ImageFormat):
        return value
    try:
        return ImageFormat[str(value).upper()]
    except KeyError:
        names = ", ".join(f.name for f in ImageFormat)
        raise ImageError(f"unknown image format {value!r}; expected one of {names}") from None


def _optional_seconds(stamp: Any) -> float | None:
    if stamp is None or isinstance(stamp, float):
        return stamp
    if isinstance(stamp, (int, np.floating, np.integer)) and not isinstance(stamp, bool):
        return float(stamp)
    raise WrongTypeError(f"stamp must be float seconds or None, got {type(stamp).__name__}")


@value_type
@dataclass(frozen=True, eq=False)
class CameraIntrinsics:
    """A camera calibration, as in ``sensor_msgs/CameraInfo``.

    ``distortion`` holds the coefficients of ``distortion_model`` ("plumb_bob": k1 k2 t1 t2 k3;
    "rational_polynomial": 8 coefficients; "equidistant": 4), in OpenCV's order. ``rectification``
    (3x3, ``R``) and ``projection`` (3x4, ``P``) matter for stereo pairs; they default to the
    identity and to ``[K | 0]``. ``binning`` and ``roi`` (x_offset, y_offset, height, width,
    do_rectify) describe a sensor readout mode, kept so that a CameraInfo survives the round trip.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    skew: float = 0.0
    distortion_model: str = "plumb_bob"
    distortion: tuple[float, ...] = ()
    rectification: np.ndarray | None = None
    projection: np.ndarray | None = None
    binning: tuple[int, int] = (0, 0)
    roi: tuple[int, int, int, int, bool] = (0, 0, 0, 0, False)
    frame_id: str = ""
    stamp: float | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if self.width < 0 or self.height < 0:
            raise ImageError(f"image size must not be negative, got {self.width}x{self.height}")
        for name in ("fx", "fy", "cx", "cy", "skew"):
            set_(self, name, float(getattr(self, name)))
        set_(self, "width", int(self.width))
        set_(self, "height", int(self.height))
        set_(self, "distortion", tuple(float(c) for c in np.asarray(self.distortion, dtype=float).reshape(-1)))
        set_(self, "stamp", _optional_seconds(self.stamp))
        for name, shape in (("rectification", (3, 3)), ("projection", (3, 4))):
            value = getattr(self, name)
            if value is not None:
                matrix = np.array(value, dtype=float)
                if matrix.size != shape[0] * shape[1]:
                    raise ImageError(f"{name} must be {shape[0]}x{shape[1]}, got shape {matrix.shape}")
                matrix = matrix.reshape(shape)
                matrix.flags.writeable = False
                set_(self, name, matrix)
        set_(self, "binning", (int(self.binning[0]), int(self.binning[1])))
        x, y, h, w, rectify = self.roi
        set_(self, "roi", (int(x), int(y), int(h), int(w), bool(rectify)))

    @property
    def K(self) -> np.ndarray:  # noqa: N802 - the usual name of the camera matrix
        """3x3 camera matrix ``[[fx, skew, cx], [0, fy, cy], [0, 0, 1]]``."""
        return np.array([[self.fx, self.skew, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def D(self) -> np.ndarray:  # noqa: N802 - OpenCV's name for the distortion coefficients
        """Distortion coefficients as a float64 vector (what ``cv2`` functions take)."""
        return np.array(self.distortion, dtype=float)

    @property
    def R(self) -> np.ndarray:  # noqa: N802
        """3x3 rectification matrix (identity unless given)."""
        return np.eye(3) if self.rectification is None else self.rectification.copy()

    @property
    def P(self) -> np.ndarray:  # noqa: N802
        """3x4 projection matrix (``[K | 0]`` unless given)."""
        if self.projection is not None:
            return self.projection.copy()
        return np.hstack([self.K, np.zeros((3, 1))])

    @classmethod
    def from_matrix(cls, K: Any, width: int, height: int, distortion: Any = (),  # noqa: N803
                    distortion_model: str = "plumb_bob", **kwargs: Any) -> CameraIntrinsics:
        """Intrinsics of a 3x3 (or row-major 9-element) camera matrix."""
        matrix = np.asarray(K, dtype=float).reshape(3, 3)
        return cls(width, height, matrix[0, 0], matrix[1, 1], matrix[0, 2], matrix[1, 2], skew=matrix[0, 1],
                   distortion_model=distortion_model, distortion=tuple(np.asarray(distortion, float).ravel()),
                   **kwargs)

    @classmethod
    def from_json(cls, source: str | Path | Mapping[str, Any], **kwargs: Any) -> CameraIntrinsics:
        """Read intrinsics from a JSON file (or an already parsed mapping).

        Two layouts are understood: ``{"width", "height", "K" (row-major 9), "D", "distortion_model"}``,
        possibly nested under a ``"camera"`` key (the marker data sets), and Open3D's
        ``{"width", "height", "intrinsic_matrix" (column-major 9)}``.
        """
        if isinstance(source, Mapping):
            document: Any = source
            origin = "the mapping"
        else:
            origin = str(source)
            text = read_regular_file(source, DATA_FILE_LIMIT, "intrinsics file")
            try:
                document = json.loads(text)
            except ValueError as error:  # not JSON, or not UTF-8
                raise ImageError(f"{origin}: not a JSON document ({error})") from None
        if isinstance(document, Mapping) and isinstance(document.get("camera"), Mapping):
            document = document["camera"]
        if not isinstance(document, Mapping):
            raise ImageError(f"{origin}: expected a JSON object with camera intrinsics")
        try:
            width, height = int(document["width"]), int(document["height"])
            if "K" in document:
                K = np.asarray(document["K"], dtype=float).reshape(3, 3)  # noqa: N806
            elif "intrinsic_matrix" in document:
                K = np.asarray(document["intrinsic_matrix"], dtype=float).reshape(3, 3).T  # noqa: N806
            else:
                raise UnknownNameError("K (or intrinsic_matrix)")
        except KeyError as error:
            raise ImageError(f"{origin}: camera intrinsics lack {error.args[0]}") from None
        except ValueError as error:
            raise ImageError(f"{origin}: bad camera matrix: {error}") from None
        return cls.from_matrix(K, width, height, document.get("D", ()),
                               document.get("distortion_model", "plumb_bob"), **kwargs)


@value_type
@dataclass(frozen=True, eq=False)
class Image:
    """An image: ``data`` in the layout of ``format``, with time, frame and optionally intrinsics.

    ``data`` is checked against the format (dtype, number of axes, channels, even sizes for YUV) at
    construction. It is not copied: an image converted from a ROS message is usually a read-only
    view of the message's buffer; copy the array before drawing on it. Images compare by identity
    (``eq=False``): comparing pixel arrays is the caller's choice (``np.array_equal``).
    """

    data: np.ndarray
    format: ImageFormat
    stamp: float | None = None
    frame_id: str = ""
    intrinsics: CameraIntrinsics | None = field(default=None)
    _conversions: dict[tuple[ImageFormat, float], Image] = field(
        default_factory=dict, init=False, repr=False, compare=False)
    """Conversions of this image already made by :meth:`to`: several readers of one image that want
    the same format pay for one conversion."""

    def __post_init__(self) -> None:
        image_format = _as_format(self.format)
        object.__setattr__(self, "format", image_format)
        object.__setattr__(self, "stamp", _optional_seconds(self.stamp))
        data = self.data
        if not isinstance(data, np.ndarray):
            raise WrongTypeError(f"{image_format.name} image data must be a numpy array, got {type(data).__name__}")
        if data.dtype != image_format.dtype:
            hint = " (swap the byte order first: data.astype(data.dtype.newbyteorder('='))" \
                if data.dtype.newbyteorder("=") == image_format.dtype else ""
            raise ImageError(f"{image_format.name} image data must be {image_format.dtype}, got {data.dtype}{hint}")
        expected = "HxW" if image_format.channels == 1 else f"HxWx{image_format.channels}"
        if image_format is ImageFormat.I420:
            expected = "(H*3/2)xW"
        ok = data.ndim == 2 if image_format.channels == 1 else (
            data.ndim == 3 and data.shape[2] == image_format.channels)
        if not ok:
            raise ImageError(f"{image_format.name} image data must have shape {expected}, got {data.shape}")
        if image_format is ImageFormat.YUYV and data.shape[1] % 2:
            raise ImageError(f"YUYV images need an even width (pixels come in pairs), got {data.shape[1]}")
        if image_format is ImageFormat.I420:
            rows, width = data.shape
            if rows % 3 or width % 2:
                raise ImageError(f"I420 image data must have shape (H*3/2)xW with H and W even, got {data.shape}")

    def __reduce__(self) -> tuple[type[Image], tuple[Any, ...]]:
        """Pickled (across processes: a shared-memory channel, a child's port) without the
        conversions made so far: each would add a whole image to every transfer, and a reader in the
        other process converts what it needs itself."""
        return Image, (self.data, self.format, self.stamp, self.frame_id, self.intrinsics)

    @property
    def width(self) -> int:
        return int(self.data.shape[1])

    @property
    def height(self) -> int:
        rows = int(self.data.shape[0])
        return rows * 2 // 3 if self.format is ImageFormat.I420 else rows

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels, OpenCV's order."""
        return self.width, self.height

    def to(self, target: ImageFormat | str, depth_scale: float = 1000.0) -> Image:
        """This image in ``target`` format, converted by OpenCV once and remembered (see ``convert``).

        The image itself when it is already in that format. ``depth_scale`` (DEPTH16 units per
        metre) matters only between the two depth formats."""
        key = (_as_format(target), float(depth_scale))
        if key[0] is self.format:
            return self
        done = self._conversions.get(key)
        if done is None:
            from .convert import convert  # OpenCV is imported by conversions only

            done = self._conversions[key] = convert(self, key[0], depth_scale)
        return done

    def to_rgb(self, depth_range: tuple[float, float] | None = None) -> np.ndarray:
        """An HxWx3 uint8 RGB rendering for display; a view of ``data`` when the format allows.

        Grey is replicated, 16-bit grey keeps its high byte, YUV goes through OpenCV (imported only
        then). Depth is shown as grey, linear in metres from ``depth_range`` (near, far), by default
        from 0 to the farthest valid pixel; unknown depth (0 or NaN) is black.
        """
        data, image_format = self.data, self.format
        if image_format is ImageFormat.RGB8:
            return data
        if image_format is ImageFormat.BGR8:
            return data[..., ::-1]
        if image_format is ImageFormat.RGBA8:
            return data[..., :3]
        if image_format is ImageFormat.BGRA8:
            return data[..., 2::-1]
        if image_format is ImageFormat.GRAY8:
            return np.repeat(data[..., None], 3, axis=2)
        if image_format is ImageFormat.GRAY16:
            grey = (data >> 8).astype(np.uint8)
            return np.repeat(grey[..., None], 3, axis=2)
        if image_format.is_depth:
            metres = self.depth_metres()
            valid = np.isfinite(metres) & (metres > 0)
            near, far = depth_range if depth_range is not None else (
                0.0, float(metres[valid].max()) if valid.any() else 1.0)
            span = far - near if far > near else 1.0
            scaled = np.clip((np.nan_to_num(metres, nan=near) - near) * (255.0 / span), 0, 255)
            grey = np.where(valid, scaled, 0).astype(np.uint8)
            return np.repeat(grey[..., None], 3, axis=2)
        import cv2  # YUV only: the other formats need no OpenCV

        code = cv2.COLOR_YUV2RGB_YUYV if image_format is ImageFormat.YUYV else cv2.COLOR_YUV2RGB_I420
        return cv2.cvtColor(np.ascontiguousarray(data), code)

    def depth_metres(self) -> np.ndarray:
        """Depth as float32 metres with NaN where unknown (the data itself for DEPTH32F)."""
        if self.format is ImageFormat.DEPTH32F:
            return self.data
        if self.format is ImageFormat.DEPTH16:
            metres = self.data.astype(np.float32) * np.float32(0.001)
            metres[self.data == 0] = np.nan
            return metres
        raise ImageError(f"a {self.format.name} image holds no depth")
