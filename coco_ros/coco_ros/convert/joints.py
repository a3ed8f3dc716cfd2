"""``sensor_msgs/JointState`` <-> :class:`JointSample`.

Incoming joint states become a :class:`JointStateSample`: a ``JointSample`` (so the transformation
interface and anything else that takes joint samples accepts it) that also keeps the velocities and
efforts, ``None`` when the message has none. Positions are required: a JointState that carries only
velocities or efforts is refused, since a sample without positions would move no joint. Any
``JointSample`` can be published; velocities and efforts are written when it has them.
"""

from __future__ import annotations

import functools
import struct
from dataclasses import dataclass

import numpy as np
from coco_core.errors import MessageError
from coco_core.transforms.samples import JointSample
from coco_core.wire import value_type
from sensor_msgs.msg import JointState

from .base import Converter, header_stamp, make_header, typed_array
from .stamps import received_time

_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")


@value_type
@dataclass(frozen=True, slots=True)
class JointStateSample(JointSample):
    """A :class:`JointSample` with the optional velocities and efforts of a JointState, in the order
    of ``names``."""

    velocities: np.ndarray | None = None
    efforts: np.ndarray | None = None


class JointStateConverter(Converter[JointState, JointSample]):
    """``sensor_msgs/JointState`` <-> :class:`JointSample` (a :class:`JointStateSample` when read)."""

    type_name = "sensor_msgs/msg/JointState"
    coco_type = JointSample

    def to_coco(self, msg: JointState) -> JointStateSample:
        self._check_message(msg)
        names = tuple(msg.name)
        positions = _values(msg.position, "position", names, required=True)
        assert positions is not None  # required: refused rather than None
        return JointStateSample(names, positions, header_stamp(msg.header),
                                _values(msg.velocity, "velocity", names), _values(msg.effort, "effort", names))

    def from_cdr(self, data: bytes) -> JointStateSample:
        """Read a JointState's CDR bytes directly: the positions, velocities and efforts are numpy
        views of the bytes (no copy, no rclpy message, no list of floats), so a recorded joint state
        stays an array from the bag to Pinocchio. Same result and same refusals as :meth:`to_coco`;
        a big-endian message (never written by rosbag2 on the usual machines) goes through rclpy."""
        if len(data) < 4 or data[1] != 1:  # encapsulation: CDR little-endian is 00 01
            sample = super().from_cdr(data)  # through to_coco
            assert isinstance(sample, JointStateSample)
            return sample
        try:
            return _joint_state_from_cdr(data)
        except (struct.error, ValueError, UnicodeDecodeError) as error:
            if isinstance(error, ValueError) and "JointState has" in str(error):
                raise
            raise MessageError(f"malformed JointState CDR ({len(data)} bytes): {error}") from None

    def to_ros(self, value: JointSample) -> JointState:
        self._check_value(value)
        msg = JointState(header=make_header(value.stamp, ""), name=list(value.names))
        msg.position = _checked(value.positions, "positions", value.names)
        if isinstance(value, JointStateSample):
            if value.velocities is not None:
                msg.velocity = _checked(value.velocities, "velocities", value.names)
            if value.efforts is not None:
                msg.effort = _checked(value.efforts, "efforts", value.names)
        return msg


def _values(field: object, label: str, names: tuple[str, ...], required: bool = False) -> np.ndarray | None:
    values = np.array(field, dtype=np.float64)
    if len(values) == len(names) and (len(values) or required):
        return values
    if len(values) == 0 and not required:
        return None
    raise MessageError(f"JointState has {len(names)} names but {len(values)} {label} values"
                       + (" (positions are required)" if required and not len(values) else ""))


def _joint_state_from_cdr(data: bytes) -> JointStateSample:
    """XCDR1 little-endian layout of sensor_msgs/JointState: positions are aligned from byte 4 (after
    the encapsulation header); a double sequence aligns its first element to 8 bytes."""
    global _LAST_NAMES
    position = 4
    sec, nanosec = _STAMP.unpack_from(data, position)
    position += 8
    length = _U32.unpack_from(data, position)[0]
    position += 4 + length  # header.frame_id (not kept by JointStateSample)

    def count_at(position: int) -> tuple[int, int]:
        position += -(position - 4) % 4
        return _U32.unpack_from(data, position)[0], position + 4

    start = position
    misalignment = (start - 4) % 4
    last_misalignment, last_section, last_names = _LAST_NAMES
    if misalignment == last_misalignment and data[start:start + len(last_section)] == last_section:
        # The names of the previous message (a robot sends the same list every time): a name section
        # is self-delimiting (a count, then length-prefixed strings), so the same bytes at the same
        # alignment are the same names and end at the same place; one comparison instead of a walk.
        names_tuple, position = last_names, start + len(last_section)
    else:
        count, position = count_at(position)
        for _ in range(count):  # walk the names; they are decoded once per distinct list (_names)
            length, position = count_at(position)
            position += length
        if position > len(data):
            raise MessageError("the joint names run past the end")
        section = data[start:position]
        names_tuple = _names(section, misalignment)
        _LAST_NAMES = (misalignment, bytes(section), names_tuple)
    arrays = []
    for _ in range(3):  # position, velocity, effort
        count, position = count_at(position)
        if count:
            position += -(position - 4) % 8
        if position + 8 * count > len(data):
            raise MessageError(f"a sequence of {count} doubles runs past the end")
        arrays.append(np.frombuffer(data, "<f8", count, position))
        position += 8 * count
    positions, velocities, efforts = (_sized(values, label, names_tuple, required)
                                      for values, label, required in zip(arrays, ("position", "velocity", "effort"),
                                                                         (True, False, False)))
    assert positions is not None  # required: refused rather than None
    stamp = None if sec == 0 and nanosec == 0 else received_time(sec, nanosec)
    return JointStateSample(names_tuple, positions, stamp, velocities, efforts)


_LAST_NAMES: tuple[int, bytes, tuple[str, ...]] = (-1, b"", ())
"""(alignment, bytes, names) of the last name section walked: replaced whole, so a reader in another
thread sees one consistent triple."""


@functools.lru_cache(maxsize=256)
def _names(section: bytes, misalignment: int) -> tuple[str, ...]:
    """The joint names of a JointState's name section (its count, then each length-prefixed string):
    a robot sends the same list every time, so the strings are decoded once, and every sample of
    that robot carries the same tuple (which the kinematic models' plans are keyed by)."""
    padded = bytes(misalignment) + section  # re-create the alignment the section had in its message
    position = misalignment + (-misalignment % 4)  # offsets in ``padded`` align as in the message
    count = _U32.unpack_from(padded, position)[0]
    position += 4
    names = []
    for _ in range(count):
        position += -position % 4
        length = _U32.unpack_from(padded, position)[0]
        names.append(padded[position + 4:position + 3 + length].decode("utf-8"))
        position += 4 + length
    return tuple(names)


def _sized(values: np.ndarray, label: str, names: tuple[str, ...], required: bool) -> np.ndarray | None:
    """``values`` when there is one per name; None for an empty optional field; else the refusal
    :func:`_values` gives."""
    if len(values) == len(names) and (len(values) or required):
        return values
    return _values(values, label, names, required)


def _checked(values: np.ndarray, label: str, names: tuple[str, ...]):
    array = np.asarray(values, dtype=np.float64).reshape(-1)
    if len(array) != len(names):
        raise MessageError(f"a joint sample with {len(names)} names has {len(array)} {label}")
    return typed_array(array, "d")
