"""What every converter offers, and the few helpers they share."""

from __future__ import annotations

import array
import importlib
from typing import Any, ClassVar, Generic, TypeVar

import numpy as np
from coco_core.errors import MessageError, WrongTypeError
from std_msgs.msg import Header

from .stamps import received_time, seconds_to_time

M = TypeVar("M")
V = TypeVar("V")


class Converter(Generic[M, V]):
    """Converts one ROS message type to a CoCo port value and back.

    ``type_name`` is the ROS name (``sensor_msgs/msg/Image``), ``coco_type`` the class (or classes)
    of the CoCo values, the type a ROSInterface gives its port. Options (a child frame name, field
    labels...) are constructor keywords; :func:`coco_ros.convert.converter_for` checks them.
    Converters hold no state between messages: one instance may serve several threads.
    """

    type_name: ClassVar[str]
    coco_type: ClassVar[type | tuple[type, ...]]
    writes_cdr: ClassVar[bool] = False
    """Whether :meth:`to_cdr` packs the message's bytes itself (:mod:`coco_ros.convert.cdr_writer`):
    a ROSInterface then publishes those bytes, and no rclpy message is built."""

    @property
    def message_type(self) -> type:
        """The rclpy message class of ``type_name``."""
        return message_class(self.type_name)

    def to_coco(self, msg: M) -> V:
        raise NotImplementedError

    def from_cdr(self, data: bytes) -> V:
        """The CoCo value of a message given as its CDR bytes (a recorded message): decoded into the
        rclpy message (:mod:`coco_ros.bag.cdr_decoder`), then :meth:`to_coco`. A converter that can
        read the bytes directly overrides this, so that a replay skips building the rclpy message."""
        from ..bag.cdr_decoder import message_decoder

        return self.to_coco(message_decoder(self.message_type)(data))

    def to_ros(self, value: V) -> M:
        raise NotImplementedError

    def to_cdr(self, value: V) -> bytes:
        """The CDR bytes of the message of ``value``: by default rclpy's serialization of
        :meth:`to_ros`; converters that set ``writes_cdr`` pack them directly (rclpy reads them back as
        the same message)."""
        from rclpy.serialization import serialize_message

        return serialize_message(self.to_ros(value))

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.type_name})"

    def _check_message(self, msg: Any) -> None:
        name = self.type_name.rsplit("/", 1)[-1]
        if type(msg).__name__ != name:
            raise WrongTypeError(f"{type(self).__name__} converts {self.type_name} messages, got {type(msg).__name__}")

    def _check_value(self, value: Any, expected: type | tuple[type, ...] | None = None) -> None:
        expected = self.coco_type if expected is None else expected
        if not isinstance(value, expected):
            names = " or ".join(t.__name__ for t in (expected if isinstance(expected, tuple) else (expected,)))
            raise WrongTypeError(f"{type(self).__name__} publishes {names} values as {self.type_name}, "
                                 f"got {type(value).__name__}")


def message_class(type_name: str) -> type:
    """``"sensor_msgs/msg/Image"`` -> ``sensor_msgs.msg.Image``."""
    package, _, name = type_name.partition("/msg/")
    return getattr(importlib.import_module(f"{package}.msg"), name)


def make_header(stamp: float | None, frame_id: str) -> Header:
    return Header(stamp=seconds_to_time(stamp), frame_id=frame_id)


def header_stamp(header: Header) -> float | None:
    """The stamp of a received message's header, checked (:func:`~.stamps.received_time`); None when
    unset (zero)."""
    stamp = header.stamp
    return None if stamp.sec == 0 and stamp.nanosec == 0 else received_time(stamp.sec, stamp.nanosec)


def typed_array(values: np.ndarray, typecode: str) -> array.array:
    """An ``array.array`` copy of a numpy array, in one ``memcpy``: what rclpy message fields take
    without checking element by element (a list or bytes would be checked in a Python loop)."""
    result = array.array(typecode)
    contiguous = np.ascontiguousarray(values)
    if contiguous.dtype.itemsize != result.itemsize and typecode != "B":
        raise MessageError(f"cannot store {contiguous.dtype} values in an array of {typecode!r}")
    result.frombytes(contiguous.reshape(-1).view(np.uint8))  # type: ignore[arg-type]  # an ndarray is a buffer
    return result


def read_only(view: np.ndarray) -> np.ndarray:
    """Mark a view of a message's buffer read-only: the message may be shared with other callbacks."""
    view.flags.writeable = False
    return view
