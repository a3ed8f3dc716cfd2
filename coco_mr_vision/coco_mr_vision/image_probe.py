"""The size of an encoded image, read from its first bytes, before anything is decoded.

OpenCV's ``imdecode`` cannot be told a largest size: it allocates what the encoded header says, so
an 877-byte JPEG that claims 30000x30000 pixels costs gigabytes and half a minute. A receiver reads
the dimensions here (the JPEG's start-of-frame segment, the PNG's IHDR chunk: a few dozen bytes)
and compares them with what the packet's header declares, which is itself bounded by the
receiver's largest frame; only an image of the declared size is handed to OpenCV.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from coco_core.errors import PacketError

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

_JPEG_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
"""Start-of-frame markers (baseline, extended, progressive, lossless...); C4, C8 and CC are not."""

_JPEG_STANDALONE = frozenset({0x01, *range(0xD0, 0xD8)})
"""Markers without a length (TEM, RSTn)."""


@dataclass(frozen=True)
class EncodedSize:
    width: int
    height: int
    channels: int
    bits: int
    """Bits per sample: 8 for JPEG, 1 to 16 for PNG."""


def _garbage(message: str) -> PacketError:
    return PacketError("garbage", message)


def jpeg_size(data: bytes | memoryview) -> EncodedSize:
    """The size in a JPEG's start-of-frame segment; garbage when there is none before the scan."""
    view = memoryview(data)
    if bytes(view[:2]) != b"\xff\xd8":
        raise _garbage("colour payload is not a JPEG (no start-of-image marker)")
    offset = 2
    while offset + 4 <= len(view):
        if view[offset] != 0xFF:
            raise _garbage(f"JPEG has no marker at byte {offset}")
        marker = view[offset + 1]
        if marker == 0xFF:  # fill byte
            offset += 1
            continue
        if marker in _JPEG_STANDALONE:
            offset += 2
            continue
        if marker in (0xD9, 0xDA):  # end of image, start of scan: no frame header before it
            break
        (length,) = struct.unpack_from(">H", view, offset + 2)
        if marker in _JPEG_SOF:
            if length < 8 or offset + 2 + length > len(view):
                break
            bits, height, width, channels = struct.unpack_from(">BHHB", view, offset + 4)
            return EncodedSize(width, height, channels, bits)
        if length < 2:
            raise _garbage(f"JPEG segment {marker:#x} has length {length}")
        offset += 2 + length
    raise _garbage("JPEG has no frame header")


def png_size(data: bytes | memoryview) -> EncodedSize:
    """The size in a PNG's IHDR chunk (which the format puts first)."""
    view = memoryview(data)
    if bytes(view[:8]) != PNG_SIGNATURE or len(view) < 8 + 8 + 13 or bytes(view[12:16]) != b"IHDR":
        raise _garbage("payload is not a PNG (no signature and IHDR chunk)")
    width, height, bits, colour_type = struct.unpack_from(">IIBB", view, 16)
    channels = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}.get(colour_type)
    if channels is None:
        raise _garbage(f"PNG colour type {colour_type} is not one of 0, 2, 3, 4, 6")
    return EncodedSize(width, height, channels, bits)
