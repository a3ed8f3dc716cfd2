"""The packet of the vision stream: one ZeroMQ message per frame, colour and/or depth with a header.

Layout: ``b"CCV1"``, the header length (uint32 little-endian), the header (UTF-8 JSON), then the
colour payload and the depth payload whose byte sizes the header gives. The header carries what a
receiver needs to rebuild the frame without any other channel: sequence number, acquisition and
send times (``time.perf_counter``, CLOCK_MONOTONIC, the same clock in every process on one host),
the image stamp and frame id, formats and encodings, the depth scale, and the intrinsics with their
distortion. Colour is JPEG (``quality``) or raw pixels; depth is lossless: Zstandard (level 1) on
the 16-bit depth, 16-bit PNG or raw. Zstandard is the default: on a 640x480 Redwood depth frame it
gives 92 kB in 1.3 ms (decoded in 0.6 ms) where PNG gives 122 kB in 7.3 ms (2.4 ms), and LZ4
169 kB in 0.7 ms (bench/bench_vision.py measures the packets).

Every check that a packet can fail raises :class:`PacketError` with a ``kind`` (``garbage`` or
``truncated``) the receiver counts; nothing in a bad packet can crash it. Nothing is decoded before
it is checked: the header field by field (:mod:`coco_mr_vision.stream_header`), the image sizes it
declares against the receiver's :class:`FrameLimit`, and the size an encoded image carries in its
own first bytes against the header's (:mod:`coco_mr_vision.image_probe`), so that no packet makes
the receiver allocate more than its largest frame.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import zstandard
from coco_core.errors import ConversionError, PacketError

from .image import CameraIntrinsics, Image, ImageFormat
from .image_probe import EncodedSize, jpeg_size, png_size
from .stream_header import MAX_HEADER, FrameLimit, PacketHeader, PartHeader, parse_header

MAGIC = b"CCV1"
_PREFIX = struct.Struct("<4sI")
COLOR_ENCODINGS = ("jpeg", "raw")
DEPTH_ENCODINGS = ("zstd", "png", "raw")
ZSTD_LEVEL = 1
"""Zstandard's fastest level: higher ones shrink depth by 3% more for 15% more time."""


@dataclass(frozen=True, eq=False)
class StreamFrame:
    """A decoded packet."""

    seq: int
    acquired: float
    sent: float
    color: Image | None
    depth: Image | None
    depth_scale: float
    source: str
    stream: str = ""
    """The sending server's run (new at each start), so that a receiver tells a restart, whose
    sequence numbers begin again, from packets that arrive out of order."""


def _intrinsics_header(k: CameraIntrinsics | None) -> dict[str, Any] | None:
    if k is None:
        return None
    return {"width": k.width, "height": k.height, "K": k.K.ravel().tolist(), "D": list(k.distortion),
            "distortion_model": k.distortion_model}


def encode(seq: int, acquired: float, sent: float, color: Image | None, depth: Image | None, *,
           depth_scale: float = 1000.0, color_encoding: str = "jpeg", quality: int = 90,
           depth_encoding: str = "zstd", source: str = "", stream: str = "") -> bytes:
    """One packet of ``color`` and/or ``depth``."""
    header: dict[str, Any] = {"seq": seq, "acquired": acquired, "sent": sent, "source": source,
                              "stream": stream, "depth_scale": depth_scale}
    payloads: list[bytes] = []
    for name, image in (("color", color), ("depth", depth)):
        if image is None:
            continue
        if name == "color":
            data, encoding, fmt = _encode_color(image, color_encoding, quality)
        else:
            data, encoding, fmt = _encode_depth(image, depth_encoding, depth_scale)
        header[name] = {"format": fmt.name, "encoding": encoding, "width": image.width, "height": image.height,
                        "bytes": len(data), "stamp": image.stamp, "frame_id": image.frame_id,
                        "intrinsics": _intrinsics_header(image.intrinsics)}
        payloads.append(data)
    text = json.dumps(header, separators=(",", ":")).encode("utf-8")
    return b"".join([_PREFIX.pack(MAGIC, len(text)), text, *payloads])


def _encode_color(image: Image, encoding: str, quality: int) -> tuple[bytes, str, ImageFormat]:
    if encoding == "jpeg":
        if image.format is ImageFormat.GRAY8:
            source = image
        else:
            source = image.to(ImageFormat.BGR8)
        ok, data = cv2.imencode(".jpg", source.data, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
        if not ok:
            raise ConversionError("OpenCV could not JPEG-encode the image")
        return data.tobytes(), "jpeg", source.format
    if encoding == "raw":
        return np.ascontiguousarray(image.data).tobytes(), "raw", image.format
    raise ConversionError(f"unknown colour encoding {encoding!r}; expected one of {', '.join(COLOR_ENCODINGS)}")


def _encode_depth(image: Image, encoding: str, depth_scale: float) -> tuple[bytes, str, ImageFormat]:
    depth = image.to(ImageFormat.DEPTH16, depth_scale)
    if encoding == "zstd":
        raw = np.ascontiguousarray(depth.data).astype("<u2", copy=False).tobytes()
        return zstandard.ZstdCompressor(level=ZSTD_LEVEL).compress(raw), "zstd", ImageFormat.DEPTH16
    if encoding == "png":
        ok, data = cv2.imencode(".png", depth.data, [cv2.IMWRITE_PNG_COMPRESSION, 1])
        if not ok:
            raise ConversionError("OpenCV could not PNG-encode the depth")
        return data.tobytes(), "png", ImageFormat.DEPTH16
    if encoding == "raw":
        return np.ascontiguousarray(depth.data).astype("<u2").tobytes(), "raw", ImageFormat.DEPTH16
    raise ConversionError(f"unknown depth encoding {encoding!r}; expected one of {', '.join(DEPTH_ENCODINGS)}")


@dataclass(frozen=True, eq=False)
class OpenedPacket:
    """A packet whose prefix and header were checked, its payloads not yet decoded: what a receiver
    needs to order packets and pick the newest, for about 10 us (decoding a VGA frame takes ms)."""

    header: PacketHeader
    color: memoryview | None
    depth: memoryview | None


def open_packet(packet: bytes | memoryview, limit: FrameLimit = FrameLimit()) -> OpenedPacket:
    """The checked header of ``packet`` (bytes, or a memoryview of a received buffer: nothing is
    copied) and views of its payloads; :class:`PacketError` for anything malformed or larger than
    ``limit``."""
    packet = memoryview(packet)
    if len(packet) < _PREFIX.size:
        raise PacketError("truncated", f"packet of {len(packet)} bytes is shorter than its prefix")
    magic, length = _PREFIX.unpack_from(packet)
    if magic != MAGIC:
        raise PacketError("garbage", f"packet starts with {bytes(magic)!r}, not {MAGIC!r}")
    start = _PREFIX.size
    if length > MAX_HEADER:
        raise PacketError("garbage", f"header of {length} bytes, at most {MAX_HEADER}")
    if len(packet) < start + length:
        raise PacketError("truncated", f"header of {length} bytes, packet has {len(packet) - start}")
    header = parse_header(bytes(packet[start:start + length]), limit)
    offset = start + length
    payloads: dict[str, memoryview | None] = {"color": None, "depth": None}
    for name, part in (("color", header.color), ("depth", header.depth)):
        if part is None:
            continue
        if len(packet) < offset + part.size:
            raise PacketError("truncated", f"{name} payload of {part.size} bytes, {len(packet) - offset} left")
        payloads[name] = packet[offset:offset + part.size]
        offset += part.size
    if offset != len(packet):
        raise PacketError("garbage", f"{len(packet) - offset} bytes after the payloads")
    return OpenedPacket(header, payloads["color"], payloads["depth"])


def decode_opened(opened: OpenedPacket) -> StreamFrame:
    """The frame of a packet :func:`open_packet` checked; :class:`PacketError` when a payload is not
    the image its header describes."""
    header = opened.header
    color = _decode_part(header.color, opened.color)
    depth = _decode_part(header.depth, opened.depth)
    return StreamFrame(header.seq, header.acquired, header.sent, color, depth, header.depth_scale, header.source,
                       header.stream)


def decode(packet: bytes | memoryview, limit: FrameLimit = FrameLimit()) -> StreamFrame:
    """The frame in ``packet``; :class:`PacketError` for anything malformed or larger than ``limit``."""
    return decode_opened(open_packet(packet, limit))


def _decode_part(part: PartHeader | None, payload: memoryview | None) -> Image | None:
    if part is None or payload is None:
        return None
    try:
        data = _decode_pixels(part, payload)
    except (ValueError, cv2.error) as error:  # what OpenCV or numpy may still say about a payload
        if isinstance(error, PacketError):
            raise
        raise PacketError("garbage", f"{part.encoding} payload: {type(error).__name__}: {error}") from None
    if data.shape[:2] != part.format.shape(part.width, part.height)[:2]:
        raise PacketError("garbage", f"payload is {data.shape}, header says {part.width}x{part.height}")
    return Image(data, part.format, part.stamp, part.frame_id, part.intrinsics)


def _encoded(part: PartHeader, size: EncodedSize, channels: tuple[int, ...], bits: int) -> None:
    """Refuse an encoded image that is not the size (and pixel) the header declares, before decoding."""
    if (size.width, size.height) != (part.width, part.height):
        raise PacketError("garbage", f"{part.encoding} payload is {size.width}x{size.height}, the header says "
                          f"{part.width}x{part.height}")
    if size.channels not in channels or size.bits != bits:
        raise PacketError("garbage", f"{part.encoding} payload has {size.channels} channel(s) of {size.bits} "
                          f"bits, a {part.format.name} image needs {bits}")


def _decode_pixels(part: PartHeader, payload: memoryview) -> np.ndarray:
    fmt, width, height, encoding = part.format, part.width, part.height, part.encoding
    if encoding == "jpeg" and fmt in (ImageFormat.GRAY8, ImageFormat.BGR8):
        _encoded(part, jpeg_size(payload), (1, 3), 8)
        flags = cv2.IMREAD_GRAYSCALE if fmt is ImageFormat.GRAY8 else cv2.IMREAD_COLOR
    elif encoding == "png" and fmt is ImageFormat.DEPTH16:
        _encoded(part, png_size(payload), (1,), 16)
        flags = cv2.IMREAD_UNCHANGED
    elif encoding == "raw":
        dtype = np.dtype("<u2") if fmt is ImageFormat.DEPTH16 else fmt.dtype
        shape = fmt.shape(width, height)
        expected = int(np.prod(shape)) * dtype.itemsize
        if len(payload) != expected:
            raise PacketError("garbage", f"raw payload of {len(payload)} bytes, a {width}x{height} {fmt.name} "
                              f"image has {expected}")
        return np.frombuffer(payload, dtype).astype(fmt.dtype, copy=False).reshape(shape)
    elif encoding == "zstd" and fmt is ImageFormat.DEPTH16:
        data = np.frombuffer(_unzstd(payload, 2 * width * height), "<u2").astype(fmt.dtype, copy=False)
        return data.reshape(fmt.shape(width, height))
    else:
        raise PacketError("garbage", f"unknown encoding {encoding!r} for a {fmt.name} image")
    decoded = cv2.imdecode(np.frombuffer(payload, np.uint8), flags)
    if decoded is None:
        raise PacketError("garbage", f"{encoding} payload does not decode")
    return decoded


def _unzstd(payload: memoryview, size: int) -> bytes:
    """A Zstandard payload that must hold exactly ``size`` bytes: the size the frame declares is
    checked before anything is decompressed, so a forged one cannot make the receiver allocate."""
    try:
        declared = zstandard.frame_content_size(payload)
        if declared != size:
            raise PacketError("garbage", f"zstd payload declares {declared} bytes, the header {size}")
        data = zstandard.ZstdDecompressor().decompress(payload, max_output_size=size)
    except zstandard.ZstdError as error:
        raise PacketError("garbage", f"zstd payload does not decode: {error}") from None
    if len(data) != size:
        raise PacketError("garbage", f"zstd payload gave {len(data)} bytes, the header says {size}")
    return data
