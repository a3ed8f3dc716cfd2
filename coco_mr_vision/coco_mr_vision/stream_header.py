"""The header of a vision-stream packet, checked field by field before anything is decoded.

A packet comes from the network: its header is JSON that anyone may have written. Parsing it into
:class:`PacketHeader` checks the type and the range of every field, so that a list, a null, a
nesting 1,000 deep, ``1e400``, ``Infinity``, ``NaN`` or a sequence number of 10^18 is one
:class:`~coco_core.errors.PacketError` (``garbage``), never an AttributeError, a RecursionError or
an OverflowError in the receiver, and never a value that poisons what comes after (a NaN
acquisition time in the latency mean). The image sizes are checked against the receiver's
:class:`FrameLimit` here, before any payload is touched; :mod:`coco_mr_vision.image_probe` then
checks that the encoded image is the size the header declares.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

from coco_core.errors import PacketError

from .image import CameraIntrinsics, ImageFormat

MAX_HEADER = 1 << 16
"""Bytes of JSON a header may have (a real one has about 600)."""

MAX_SEQ = 1 << 53
"""Sequence numbers are counted from 1 and stay below 2^53, the integers JSON carries exactly."""

MAX_TIME = 1e10
"""Seconds on the monotonic clock (the time since boot) are below 10^10 (317 years)."""

MAX_TEXT = 256
"""Characters of a source name, a stream id, a frame id, an encoding or a distortion model."""

MAX_DISTORTION = 16
"""Distortion coefficients (OpenCV's models have at most 14)."""

COLOR_BYTES_PER_PIXEL = 4
"""The widest colour pixel a packet may carry raw (RGBA8, BGRA8)."""


@dataclass(frozen=True)
class FrameLimit:
    """The largest frame a receiver accepts: every image of a packet is at most ``width`` x ``height``."""

    width: int = 4096
    height: int = 4096

    @property
    def packet_bytes(self) -> int:
        """The largest packet such frames make (raw RGBA colour, raw 16-bit depth, the largest header):
        what ZeroMQ is told to accept at most."""
        return 8 + MAX_HEADER + self.width * self.height * (COLOR_BYTES_PER_PIXEL + 2)


@dataclass(frozen=True)
class PartHeader:
    """The colour or the depth image of a packet, as its header describes it."""

    format: ImageFormat
    encoding: str
    width: int
    height: int
    size: int
    """Bytes of the payload."""
    stamp: float | None
    frame_id: str
    intrinsics: CameraIntrinsics | None


@dataclass(frozen=True)
class PacketHeader:
    seq: int
    acquired: float
    sent: float
    depth_scale: float
    source: str
    stream: str
    color: PartHeader | None
    depth: PartHeader | None


def _garbage(message: str) -> PacketError:
    return PacketError("garbage", message)


def _refuse_constant(name: str) -> float:
    raise _garbage(f"header has {name}, not a number")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise _garbage(f"header number {text} overflows")
    return value


def _field(mapping: dict[str, Any], name: str, kinds: tuple[type, ...], required: bool = True) -> Any:
    if name not in mapping:
        if required:
            raise _garbage(f"header lacks {name!r}")
        return None
    value = mapping[name]
    if value is None and not required:
        return None
    if not isinstance(value, kinds) or isinstance(value, bool):
        raise _garbage(f"header field {name!r} is a {type(value).__name__}, expected "
                       f"{' or '.join(kind.__name__ for kind in kinds)}")
    return value


def _int(mapping: dict[str, Any], name: str, low: int, high: int) -> int:
    value = _field(mapping, name, (int,))
    if not low <= value <= high:
        raise _garbage(f"header field {name!r} is {value}, expected {low} to {high}")
    return int(value)


def _number(mapping: dict[str, Any], name: str, low: float, high: float) -> float:
    value = _field(mapping, name, (int, float))
    if not low <= value <= high:  # the parser let no NaN or infinity through
        raise _garbage(f"header field {name!r} is {value}, expected {low:g} to {high:g}")
    return float(value)


def _text(mapping: dict[str, Any], name: str, default: str | None = None) -> str:
    value = _field(mapping, name, (str,), required=default is None)
    if value is None:
        return default or ""
    if len(value) > MAX_TEXT:
        raise _garbage(f"header field {name!r} has {len(value)} characters, at most {MAX_TEXT}")
    return str(value)


def _numbers(mapping: dict[str, Any], name: str, low: int, high: int) -> list[float]:
    values = _field(mapping, name, (list,))
    if not low <= len(values) <= high or any(isinstance(v, bool) or not isinstance(v, (int, float))
                                             for v in values):
        raise _garbage(f"header field {name!r} must hold {low} to {high} numbers")
    return [float(v) for v in values]


def _intrinsics(part: dict[str, Any], limit: FrameLimit, frame_id: str) -> CameraIntrinsics | None:
    camera = _field(part, "intrinsics", (dict,), required=False)
    if camera is None:
        return None
    width = _int(camera, "width", 0, limit.width)
    height = _int(camera, "height", 0, limit.height)
    matrix = _numbers(camera, "K", 9, 9)
    distortion = _numbers(camera, "D", 0, MAX_DISTORTION)
    try:
        return CameraIntrinsics.from_matrix(matrix, width, height, distortion, _text(camera, "distortion_model"),
                                            frame_id=frame_id)
    except ValueError as error:  # ImageError: not a camera
        raise _garbage(f"header intrinsics: {error}") from None


def _part(header: dict[str, Any], name: str, limit: FrameLimit) -> PartHeader | None:
    part = _field(header, name, (dict,), required=False)
    if part is None:
        return None
    format_name = _text(part, "format")
    try:
        fmt = ImageFormat[format_name]
    except KeyError:
        raise _garbage(f"{name} format {format_name!r} is not one of "
                       f"{', '.join(f.name for f in ImageFormat)}") from None
    width = _int(part, "width", 1, limit.width)
    height = _int(part, "height", 1, limit.height)
    size = _int(part, "bytes", 0, limit.packet_bytes)
    frame_id = _text(part, "frame_id", "")
    stamp = None if part.get("stamp") is None else _number(part, "stamp", -MAX_TIME, MAX_TIME)
    return PartHeader(fmt, _text(part, "encoding"), width, height, size, stamp, frame_id,
                      _intrinsics(part, limit, frame_id))


def parse_header(text: bytes, limit: FrameLimit) -> PacketHeader:
    """The header in ``text`` (UTF-8 JSON), every field checked; :class:`PacketError` (``garbage``)
    naming the first field that is wrong."""
    if len(text) > MAX_HEADER:
        raise _garbage(f"header of {len(text)} bytes, at most {MAX_HEADER}")
    try:
        header = json.loads(text, parse_constant=_refuse_constant, parse_float=_finite_float)
    except PacketError:
        raise
    except RecursionError:
        raise _garbage("header nests too deep") from None
    except ValueError as error:  # JSONDecodeError, UnicodeDecodeError, an integer of too many digits
        raise _garbage(f"header is not JSON: {error}") from None
    if not isinstance(header, dict):
        raise _garbage(f"header is a JSON {type(header).__name__}, not an object")
    return PacketHeader(
        _int(header, "seq", 1, MAX_SEQ),
        _number(header, "acquired", 0.0, MAX_TIME), _number(header, "sent", 0.0, MAX_TIME),
        _number(header, "depth_scale", 1e-6, 1e9),
        _text(header, "source", ""), _text(header, "stream", ""),
        _part(header, "color", limit), _part(header, "depth", limit))
