"""``sensor_msgs/CompressedImage`` -> :class:`coco_mr_vision.image.Image`: what image_transport's
``compressed`` and ``compressedDepth`` plugins publish, and what librealsense records.

The ``format`` string says what the data holds, as image_transport writes it:

- ``compressed``: ``"ENCODING; jpeg compressed bgr8"`` or ``"...; png compressed ..."`` (older
  publishers: just ``"jpeg"`` or ``"png"``): a JPEG or PNG file of an image whose original
  encoding is ENCODING. It is decoded (OpenCV) into the format that encoding reads as with
  :class:`~.images.ImageMessageConverter` (rgb8 -> RGB8, mono16 -> GRAY16 ...), so a compressed
  stream gives the same Image as the raw one (JPEG: up to its losses).
- ``compressedDepth``: ``"16UC1; compressedDepth png"`` (or ``rvl``; ``32FC1`` too): a 12-byte
  header (int32 format, two float32 depth quantisation parameters), then a 16-bit PNG or an RVL
  stream (Wilson's run-length variable-length code: uint32 width, height, then the code). 16UC1 is
  the depth as it was; 32FC1 is stored as quantised inverse depth, ``A / (v - B)`` metres, 0 unknown.

Sizes are bounded before anything is allocated: the image a header declares must fit
:data:`PIXEL_LIMIT`. The RVL decoder walks the code in Python (one loop step per run and per
changed pixel): a fallback for what a PNG stream would carry faster.
"""

from __future__ import annotations

import struct

import numpy as np
from coco_core.errors import MessageError
from coco_mr_vision.image import Image, ImageFormat
from sensor_msgs.msg import CompressedImage

from .base import Converter, header_stamp
from .images import READ_ENCODINGS

PIXEL_LIMIT = 1 << 26
"""The most pixels a compressed image may declare (64 M: an 8K image is 33 M)."""
_DEPTH_HEADER = struct.Struct("<iff")
"""image_transport's compressedDepth ConfigHeader: format, depthQuantA, depthQuantB."""
_PNG = b"\x89PNG\r\n\x1a\n"
_JPEG = b"\xff\xd8\xff"


class CompressedImageConverter(Converter[CompressedImage, Image]):
    """``sensor_msgs/CompressedImage`` (``compressed`` and ``compressedDepth``) -> :class:`Image`."""

    type_name = "sensor_msgs/msg/CompressedImage"
    coco_type = Image

    def to_coco(self, msg: CompressedImage) -> Image:
        self._check_message(msg)
        fields = [f.strip() for f in msg.format.split(";")]
        data = bytes(msg.data)
        if len(fields) > 1 and fields[1].startswith("compressedDepth"):
            image, image_format = _depth(fields[0], fields[1].split()[1:], data)
        else:
            image, image_format = _picture(fields[0] if len(fields) > 1 else "", msg.format, data)
        return Image(image, image_format, header_stamp(msg.header), msg.header.frame_id)


def _decode(data: bytes, what: str) -> np.ndarray:
    import cv2

    if not data.startswith((_PNG, _JPEG)):
        raise MessageError(f"{what}: the data is neither PNG nor JPEG (it starts {data[:8]!r})")
    # Why the header first: imdecode allocates what the file declares, before finding it damaged.
    if data.startswith(_PNG) and len(data) >= 24:
        width, height = struct.unpack(">II", data[16:24])
        if width * height > PIXEL_LIMIT:
            raise MessageError(f"{what}: the PNG declares {width}x{height} pixels, more than {PIXEL_LIMIT}")
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise MessageError(f"{what}: the PNG or JPEG data cannot be decoded (damaged or cut)")
    return image


def _picture(encoding: str, text: str, data: bytes) -> tuple[np.ndarray, ImageFormat]:
    """A ``compressed`` image in the format its original ``encoding`` reads as (OpenCV decodes to BGR order)."""
    image = _decode(data, f"CompressedImage {text!r}")
    channels = 1 if image.ndim == 2 else image.shape[2]
    wanted = READ_ENCODINGS[encoding][0] if encoding in READ_ENCODINGS else None
    if wanted is None or wanted.channels != channels or wanted.is_depth or wanted.dtype != image.dtype:
        wanted = {1: ImageFormat.GRAY16 if image.dtype == np.uint16 else ImageFormat.GRAY8,
                  3: ImageFormat.BGR8, 4: ImageFormat.BGRA8}[channels]
    if wanted in (ImageFormat.RGB8, ImageFormat.RGBA8):
        image = np.ascontiguousarray(image[..., [2, 1, 0, 3][:channels]])
    return image, wanted


def _depth(encoding: str, codec: list[str], data: bytes) -> tuple[np.ndarray, ImageFormat]:
    what = f"compressedDepth {encoding} {' '.join(codec)}".strip()
    if encoding not in ("16UC1", "32FC1"):
        raise MessageError(f"{what}: depth must be 16UC1 or 32FC1, got {encoding!r}")
    if len(data) < _DEPTH_HEADER.size:
        raise MessageError(f"{what}: {len(data)} bytes cannot hold the 12-byte compressedDepth header")
    _, quant_a, quant_b = _DEPTH_HEADER.unpack_from(data)
    payload = data[_DEPTH_HEADER.size:]
    if codec and codec[0] == "rvl":
        values = _rvl(payload, what)
    else:
        values = _decode(payload, what)
        if values.dtype != np.uint16 or values.ndim != 2:
            raise MessageError(f"{what}: the PNG must hold one 16-bit channel, got {values.dtype} x "
                               f"{1 if values.ndim == 2 else values.shape[2]}")
    if encoding == "16UC1":
        return values, ImageFormat.DEPTH16
    with np.errstate(divide="ignore"):
        metres = (quant_a / (values.astype(np.float32) - quant_b)).astype(np.float32)
    metres[values == 0] = np.nan
    return metres, ImageFormat.DEPTH32F


def _rvl(payload: bytes, what: str) -> np.ndarray:
    """Wilson's RVL: runs of zeros and of non-zero pixels, each pixel a zigzag delta, all in 4-bit
    variable-length groups packed from the high end of little-endian 32-bit words."""
    if len(payload) < 8:
        raise MessageError(f"{what}: {len(payload)} bytes cannot hold the RVL image size")
    width, height = struct.unpack_from("<II", payload)
    if width * height > PIXEL_LIMIT:
        raise MessageError(f"{what}: the RVL header declares {width}x{height} pixels, more than {PIXEL_LIMIT}")
    words = np.frombuffer(payload[8:8 + (len(payload) - 8) // 4 * 4], "<u4").tolist()
    nibbles = [(word >> shift) & 0xF for word in words for shift in range(28, -4, -4)]
    position = 0

    def vle() -> int:
        nonlocal position
        value, shift = 0, 0
        while True:
            if position >= len(nibbles):
                raise MessageError(f"{what}: the RVL code ends before its {width}x{height} pixels")
            nibble = nibbles[position]
            position += 1
            value |= (nibble & 0x7) << shift
            shift += 3
            if not nibble & 0x8:
                return value

    out = np.zeros(width * height, np.uint16)
    index, previous = 0, 0
    while index < out.size:
        index += vle()
        run = vle()
        if index + run > out.size:
            raise MessageError(f"{what}: the RVL code runs past its {width}x{height} pixels")
        for _ in range(run):
            positive = vle()
            previous = (previous + ((positive >> 1) ^ -(positive & 1))) & 0xFFFF
            out[index] = previous
            index += 1
    return out.reshape(height, width)


__all__ = ["CompressedImageConverter", "PIXEL_LIMIT"]
