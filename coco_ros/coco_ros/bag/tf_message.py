"""tf2_msgs/msg/TFMessage without the tf2_msgs package.

Every bag with /tf or /tf_static holds TFMessage, but tf2_msgs is not published as a Python wheel
(only the message packages of ``ros-jazzy-common-interfaces`` are), so rclpy cannot deserialize it
here. TFMessage is a plain sequence of ``geometry_msgs/TransformStamped``, whose class *is* installed,
so this module encodes and decodes its CDR by hand and hands out real
``geometry_msgs.msg.TransformStamped`` objects. When tf2_msgs is installed, its class is used instead
(see :mod:`.message_types`); both serialize to the same bytes.

CDR here is XCDR1 as ROS 2 writes it: a 4-byte encapsulation header (``00 01 00 00`` little endian,
``00 00 00 00`` big endian), then fields aligned to their size, counted from the end of that header.
"""

from __future__ import annotations

import struct
from typing import Any, Iterable

TYPE_NAME = "tf2_msgs/msg/TFMessage"

DEFINITION = "geometry_msgs/TransformStamped[] transforms\n"
"""The text of tf2_msgs' TFMessage.msg (its dependencies are resolved from geometry_msgs' files)."""

TYPE_HASH = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
"""The RIHS01 type description hash of tf2_msgs/msg/TFMessage in Jazzy (checked against rosbags)."""

_HEADER_LE = b"\x00\x01\x00\x00"


class TFMessage:
    """Stand-in for ``tf2_msgs.msg.TFMessage``: ``transforms`` is a list of TransformStamped."""

    __slots__ = ("transforms",)
    _type_name = TYPE_NAME

    def __init__(self, transforms: Iterable[Any] = ()) -> None:
        self.transforms = list(transforms)

    def __eq__(self, other: object) -> bool:
        return hasattr(other, "transforms") and list(other.transforms) == self.transforms

    def __repr__(self) -> str:
        frames = ", ".join(f"{t.header.frame_id}->{t.child_frame_id}" for t in self.transforms)
        return f"TFMessage([{frames}])"


MESSAGE_CLASS = TFMessage


def serialize(message: Any) -> bytes:
    """CDR bytes (little endian) of a TFMessage, either this stand-in or tf2_msgs' class."""
    out = bytearray(_HEADER_LE)

    def align(size: int) -> None:
        out.extend(b"\x00" * (-(len(out) - 4) % size))

    def string(text: str) -> None:
        encoded = text.encode("utf-8") + b"\x00"
        align(4)
        out.extend(struct.pack("<I", len(encoded)))
        out.extend(encoded)

    transforms = list(message.transforms)
    align(4)
    out.extend(struct.pack("<I", len(transforms)))
    for stamped in transforms:
        align(4)
        out.extend(struct.pack("<iI", stamped.header.stamp.sec, stamped.header.stamp.nanosec))
        string(stamped.header.frame_id)
        string(stamped.child_frame_id)
        translation, rotation = stamped.transform.translation, stamped.transform.rotation
        align(8)
        out.extend(
            struct.pack(
                "<7d",
                translation.x,
                translation.y,
                translation.z,
                rotation.x,
                rotation.y,
                rotation.z,
                rotation.w,
            )
        )
    return bytes(out)


def deserialize(data: bytes | memoryview) -> TFMessage:
    """A :class:`TFMessage` of ``geometry_msgs.msg.TransformStamped`` from CDR bytes."""
    from geometry_msgs.msg import TransformStamped

    view = memoryview(data)
    if len(view) < 8 or view[0] != 0 or view[1] not in (0, 1):
        raise ValueError(
            f"expected CDR data (encapsulation header 00 01 or 00 00), got {bytes(view[:4]).hex(' ')}"
        )
    endian = "<" if view[1] == 1 else ">"
    position = 4

    def take(fmt: str, align_to: int) -> tuple:
        nonlocal position
        position += -(position - 4) % align_to
        size = struct.calcsize(fmt)
        if position + size > len(view):
            raise ValueError(
                f"TFMessage CDR data ends at byte {len(view)}, expected {size} more at {position}"
            )
        values = struct.unpack_from(endian + fmt, view, position)
        position += size
        return values

    def string() -> str:
        nonlocal position
        (length,) = take("I", 4)
        if length == 0 or position + length > len(view):
            raise ValueError(f"TFMessage CDR string of {length} bytes at byte {position} overruns the data")
        text = bytes(view[position : position + length - 1]).decode("utf-8")
        position += length
        return text

    (count,) = take("I", 4)
    transforms = []
    for _ in range(count):
        stamped = TransformStamped()
        stamped.header.stamp.sec, stamped.header.stamp.nanosec = take("iI", 4)
        stamped.header.frame_id = string()
        stamped.child_frame_id = string()
        tx, ty, tz, qx, qy, qz, qw = take("7d", 8)
        translation, rotation = stamped.transform.translation, stamped.transform.rotation
        translation.x, translation.y, translation.z = tx, ty, tz
        rotation.x, rotation.y, rotation.z, rotation.w = qx, qy, qz, qw
        transforms.append(stamped)
    return TFMessage(transforms)
