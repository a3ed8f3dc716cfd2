"""CoCo values -> CDR bytes, for the converters that write their message's layout themselves.

Publishing an rclpy message costs building it (its constructor and every property setter, nested
messages included: 16 us for a PoseStamped) and then rclpy's conversion of it to C, field by field,
before DDS serializes it. A converter whose message is a header and a few numbers can instead pack
the CDR bytes with one ``struct`` format (about 3 us) and have them published as they are
(``Publisher.publish`` of ``bytes``): what a ROSInterface does when the converter says so
(``writes_cdr``). rclpy's ``deserialize_message`` reads them back into the message ``to_ros``
builds (the tests check), and they equal its ``serialize_message`` but for the padding bytes, which
this writes as zeros.

The layout is :mod:`coco_ros.bag.cdr_decoder`'s: XCDR1 little endian, a 4-byte encapsulation
header, each value aligned to its own size from the end of that header, a string as a uint32 length
(counting the terminating NUL) and its bytes.
"""

from __future__ import annotations

import struct

from .stamps import sec_nanosec

ENCAPSULATION = b"\x00\x01\x00\x00"
"""CDR, little endian, no options."""
_HEADER = struct.Struct("<iII")
"""stamp.sec, stamp.nanosec, the length of frame_id (with its NUL)."""


def with_header(stamp: float | None, frame_id: str) -> bytearray:
    """The encapsulation and a ``std_msgs/Header``: the start of a stamped message."""
    sec, nanosec = sec_nanosec(stamp)
    name = frame_id.encode() + b"\0"
    buffer = bytearray(ENCAPSULATION)
    buffer += _HEADER.pack(sec, nanosec, len(name))
    buffer += name
    return buffer


def align(buffer: bytearray, size: int) -> bytearray:
    """Pad ``buffer`` so that the next value (of ``size`` bytes) is aligned, counted from the end of
    the encapsulation header."""
    buffer += bytes(-(len(buffer) - len(ENCAPSULATION)) % size)
    return buffer
