"""``sensor_msgs/Image`` <-> :class:`coco_mr_vision.image.Image`, and ``sensor_msgs/CameraInfo``
<-> :class:`coco_mr_vision.image.CameraIntrinsics`.

No pixel is visited in Python. An incoming image is a strided numpy view of the message's buffer
(row padding in ``step`` is skipped by the row stride, UYVY becomes YUYV by a reversed axis), so
converting it copies nothing; the view is read-only, since other subscribers may share the message
(``copy=True`` gives an array of one's own). Copies happen only where the layout demands one:
big-endian 16/32-bit data (byte-swapped to native order) and I420 with padded rows. An outgoing
image costs one ``memcpy`` into the message, with ``step = width * bytes per pixel``.

Encodings read: mono8, 8UC1, mono16, rgb8, bgr8, rgba8, bgra8, yuyv (and its old name
yuv422_yuy2), uyvy (old name yuv422; converted to YUYV), i420, 32FC1 (depth in metres) and 16UC1
(depth in millimetres). Encodings written: mono8, mono16, rgb8, bgr8, rgba8, bgra8, yuyv, i420,
32FC1, 16UC1. ROS defines no planar 4:2:0 encoding: ``i420`` follows GStreamer's name and the
layout ROS uses for ``nv21`` (``height`` and ``step`` of the luma plane, chroma planes after it,
their rows ``step / 2`` bytes long).
"""

from __future__ import annotations

import sys

import numpy as np
from coco_core.errors import MessageError
from coco_mr_vision.image import CameraIntrinsics, Image, ImageFormat
from sensor_msgs.msg import CameraInfo, RegionOfInterest
from sensor_msgs.msg import Image as ImageMsg

from .base import Converter, header_stamp, make_header, read_only, typed_array

#: ROS encoding -> (format, the pixel pairs are UYVY rather than YUYV)
READ_ENCODINGS: dict[str, tuple[ImageFormat, bool]] = {
    "mono8": (ImageFormat.GRAY8, False),
    "8UC1": (ImageFormat.GRAY8, False),
    "mono16": (ImageFormat.GRAY16, False),
    "rgb8": (ImageFormat.RGB8, False),
    "bgr8": (ImageFormat.BGR8, False),
    "rgba8": (ImageFormat.RGBA8, False),
    "bgra8": (ImageFormat.BGRA8, False),
    "yuyv": (ImageFormat.YUYV, False),
    "yuv422_yuy2": (ImageFormat.YUYV, False),
    "uyvy": (ImageFormat.YUYV, True),
    "yuv422": (ImageFormat.YUYV, True),
    "i420": (ImageFormat.I420, False),
    "I420": (ImageFormat.I420, False),
    "32FC1": (ImageFormat.DEPTH32F, False),
    "16UC1": (ImageFormat.DEPTH16, False),
}

#: format -> ROS encoding written
WRITE_ENCODINGS: dict[ImageFormat, str] = {
    ImageFormat.GRAY8: "mono8",
    ImageFormat.GRAY16: "mono16",
    ImageFormat.RGB8: "rgb8",
    ImageFormat.BGR8: "bgr8",
    ImageFormat.RGBA8: "rgba8",
    ImageFormat.BGRA8: "bgra8",
    ImageFormat.YUYV: "yuyv",
    ImageFormat.I420: "i420",
    ImageFormat.DEPTH32F: "32FC1",
    ImageFormat.DEPTH16: "16UC1",
}

_BIG_ENDIAN_HOST = sys.byteorder == "big"


class ImageMessageConverter(Converter[ImageMsg, Image]):
    """``sensor_msgs/Image`` <-> :class:`Image`; ``copy=True`` to own the pixels of incoming images."""

    type_name = "sensor_msgs/msg/Image"
    coco_type = Image

    def __init__(self, copy: bool = False) -> None:
        self.copy = copy

    def to_coco(self, msg: ImageMsg) -> Image:
        self._check_message(msg)
        try:
            image_format, uyvy = READ_ENCODINGS[msg.encoding]
        except KeyError:
            raise MessageError(f"image encoding {msg.encoding!r} is not supported; supported: "
                               f"{', '.join(READ_ENCODINGS)}") from None
        height, width, step = msg.height, msg.width, msg.step
        dtype = image_format.dtype
        if dtype.itemsize > 1:
            dtype = dtype.newbyteorder(">" if msg.is_bigendian else "<")
        buffer = np.frombuffer(msg.data, dtype=np.uint8)
        if image_format is ImageFormat.I420:
            data = _i420_view(buffer, width, height, step, msg.encoding)
        else:
            row_bytes = width * image_format.channels * dtype.itemsize
            _check_size(buffer, width, height, step, row_bytes, msg.encoding)
            shape = image_format.shape(width, height)
            strides = (step, dtype.itemsize) if len(shape) == 2 else (step, image_format.channels * dtype.itemsize,
                                                                    dtype.itemsize)
            data = np.ndarray(shape, dtype=dtype, buffer=buffer, strides=strides)
            if uyvy:
                data = data[..., ::-1]  # (U0, Y0), (V0, Y1) -> (Y0, U0), (Y1, V0): a view, no copy
        if data.dtype != image_format.dtype:  # big-endian message on a little-endian host, or vice versa
            data = data.astype(image_format.dtype)
        elif self.copy and not data.flags.owndata:
            data = data.copy()
        if not data.flags.owndata:  # a view of the message's buffer
            read_only(data)
        return Image(data, image_format, header_stamp(msg.header), msg.header.frame_id)

    def to_ros(self, value: Image) -> ImageMsg:
        self._check_value(value)
        image_format = value.format
        msg = ImageMsg(header=make_header(value.stamp, value.frame_id), height=value.height, width=value.width,
                       encoding=WRITE_ENCODINGS[image_format], is_bigendian=_BIG_ENDIAN_HOST)
        msg.step = value.width if image_format is ImageFormat.I420 else (
            value.width * image_format.channels * image_format.dtype.itemsize)
        msg.data = typed_array(value.data, "B")
        return msg


def _check_size(buffer: np.ndarray, width: int, height: int, step: int, row_bytes: int, encoding: str) -> None:
    if step < row_bytes:
        raise MessageError(f"{encoding} image of width {width} needs step >= {row_bytes} bytes, got step {step}")
    needed = step * (height - 1) + row_bytes if height and width else 0
    if buffer.size < needed:
        raise MessageError(f"{encoding} image {width}x{height} with step {step} needs {needed} bytes of data, "
                           f"got {buffer.size}")


def _i420_view(buffer: np.ndarray, width: int, height: int, step: int, encoding: str) -> np.ndarray:
    """The (H*3/2)xW array of an I420 image: a view when rows are unpadded, else a planar copy."""
    if width % 2 or height % 2:
        raise MessageError(f"{encoding} images need an even width and height, got {width}x{height}")
    if step == width:
        _check_size(buffer, width, height * 3 // 2, step, width, encoding)
        return np.ndarray((height * 3 // 2, width), dtype=np.uint8, buffer=buffer, strides=(step, 1))
    if step % 2:
        raise MessageError(f"{encoding} image with padded rows needs an even step, got {step}")
    _check_size(buffer, width, height * 3 // 2, step, width, encoding)
    chroma_step, luma_bytes = step // 2, step * height
    planes = [np.ndarray((height, width), np.uint8, buffer, 0, (step, 1))] + [
        np.ndarray((height // 2, width // 2), np.uint8, buffer, luma_bytes + k * chroma_step * (height // 2),
                   (chroma_step, 1)) for k in (0, 1)]
    data = np.empty((height * 3 // 2, width), dtype=np.uint8)
    flat = data.reshape(-1)
    start = 0
    for plane in planes:  # three planes, each copied by numpy
        flat[start:start + plane.size] = plane.reshape(-1)
        start += plane.size
    return data


class CameraInfoConverter(Converter[CameraInfo, CameraIntrinsics]):
    """``sensor_msgs/CameraInfo`` <-> :class:`CameraIntrinsics` (every field is kept)."""

    type_name = "sensor_msgs/msg/CameraInfo"
    coco_type = CameraIntrinsics

    def to_coco(self, msg: CameraInfo) -> CameraIntrinsics:
        self._check_message(msg)
        roi = msg.roi
        return CameraIntrinsics.from_matrix(
            np.asarray(msg.k, dtype=float), msg.width, msg.height, np.asarray(msg.d, dtype=float),
            msg.distortion_model, rectification=np.asarray(msg.r, dtype=float).reshape(3, 3),
            projection=np.asarray(msg.p, dtype=float).reshape(3, 4), binning=(msg.binning_x, msg.binning_y),
            roi=(roi.x_offset, roi.y_offset, roi.height, roi.width, roi.do_rectify),
            frame_id=msg.header.frame_id, stamp=header_stamp(msg.header))

    def to_ros(self, value: CameraIntrinsics) -> CameraInfo:
        self._check_value(value)
        x, y, height, width, rectify = value.roi
        return CameraInfo(
            header=make_header(value.stamp, value.frame_id), width=value.width, height=value.height,
            distortion_model=value.distortion_model, d=typed_array(value.D, "d"),
            k=value.K.reshape(-1), r=value.R.reshape(-1), p=value.P.reshape(-1),
            binning_x=value.binning[0], binning_y=value.binning[1],
            roi=RegionOfInterest(x_offset=x, y_offset=y, height=height, width=width, do_rectify=rectify))
