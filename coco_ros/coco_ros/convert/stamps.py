"""``builtin_interfaces/Time`` <-> float seconds, the time base of CoCo port data.

Precision: a float64 holds about 16 significant digits, so seconds since 1970 (about 1.7e9) are
resolved to 2**-22 s, about 240 ns; times under 2**22 s (48 days, e.g. simulated time) are resolved
to better than a nanosecond and survive ``seconds -> Time -> seconds`` exactly.

To keep ROS stamps exact anyway, :func:`time_to_seconds` returns a :class:`RosTime`: a ``float`` in
every respect that also remembers the ``sec`` and ``nanosec`` it came from, and
:func:`seconds_to_time` gives those back unchanged. A stamp copied from an incoming message to an
outgoing one (an image to the pose computed from it) therefore matches to the nanosecond, as
ROS's exact-time synchronisers need; any arithmetic on it yields a plain float, rounded to the
nearest nanosecond on the way out.

A zero ``Time`` (ROS's "unset", also tf2's "latest") maps to ``None``, and ``None`` back to zero.

A stamp that arrives in a message's header is an acquisition time (:func:`received_time`): not before 1970,
``nanosec`` below 10^9, and not more than :data:`FUTURE_LIMIT` ahead of this machine's clock. The
rest (``sec=2**31-1``, builtin_interfaces' largest time, put 447,483,647 s into a CSV's time column)
is refused: the converter raises :class:`MessageError`, and the ROSInterface counts the message
among its route's conversion errors.
"""

from __future__ import annotations

import math
import time
from typing import Any

from builtin_interfaces.msg import Time
from coco_core.errors import MessageError
from coco_core.wire import value_type

_NS = 1_000_000_000
_INT32 = 2**31
FUTURE_LIMIT = 86_400.0
"""Seconds a received stamp may lie ahead of this machine's clock (a day: clocks of machines that
exchange data agree far better; a sender's wrong clock or a sentinel does not)."""


class RosTime(float):
    """Float seconds that remember the exact ``builtin_interfaces/Time`` they were made from."""

    __slots__ = ("sec", "nanosec")

    sec: int
    nanosec: int

    def __new__(cls, sec: int, nanosec: int) -> RosTime:
        value = super().__new__(cls, (int(sec) * _NS + int(nanosec)) / _NS)  # int / int: correctly rounded
        value.sec = int(sec)
        value.nanosec = int(nanosec)
        return value

    @property
    def nanoseconds(self) -> int:
        """The exact time in integer nanoseconds."""
        return self.sec * _NS + self.nanosec

    def __reduce__(self) -> tuple[Any, ...]:
        return (RosTime, (self.sec, self.nanosec))

    def __repr__(self) -> str:
        return f"RosTime(sec={self.sec}, nanosec={self.nanosec})"


value_type(RosTime, reduce=lambda time: (time.sec, time.nanosec), build=RosTime)


def time_to_seconds(stamp: Time) -> RosTime | None:
    """Seconds of a ``builtin_interfaces/Time``; ``None`` for the zero (unset) time."""
    if stamp.sec == 0 and stamp.nanosec == 0:
        return None
    return RosTime(stamp.sec, stamp.nanosec)


def received_time(sec: int, nanosec: int) -> RosTime:
    """The :class:`RosTime` of a stamp received in a message, checked as an acquisition time (see the
    module); :class:`MessageError` says what is wrong with it."""
    if not 0 <= nanosec < _NS:
        raise MessageError(f"the stamp's nanosec={nanosec} is not between 0 and 999999999")
    if sec < 0:
        raise MessageError(f"the stamp sec={sec} is before 1970")
    ahead = sec - time.time()
    if ahead > FUTURE_LIMIT:
        raise MessageError(f"the stamp sec={sec} is {ahead:.0f} s ahead of this machine's clock (at most "
                           f"{FUTURE_LIMIT:.0f}): not a time of acquisition")
    return RosTime(sec, nanosec)


def seconds_to_time(seconds: float | None) -> Time:
    """``builtin_interfaces/Time`` of float seconds, rounded to the nearest nanosecond (exact for a
    :class:`RosTime`); ``None`` gives the zero time."""
    sec, nanosec = sec_nanosec(seconds)
    return Time(sec=sec, nanosec=nanosec)


def sec_nanosec(seconds: float | None) -> tuple[int, int]:
    """The ``(sec, nanosec)`` of a ``builtin_interfaces/Time`` for float seconds, as
    :func:`seconds_to_time` gives them, without building the message."""
    if seconds is None:
        return 0, 0
    if isinstance(seconds, RosTime):
        return seconds.sec, seconds.nanosec
    value = float(seconds)
    if not math.isfinite(value):
        raise MessageError(f"a ROS time must be finite, got {value}")
    sec = math.floor(value)
    nanosec = round((value - sec) * _NS)  # value - floor(value) is exact in floating point
    if nanosec >= _NS:
        sec, nanosec = sec + 1, nanosec - _NS
    if not -_INT32 <= sec < _INT32:
        raise MessageError(f"{value} s is outside the range of a ROS time (int32 seconds)")
    return sec, nanosec
