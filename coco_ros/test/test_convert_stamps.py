"""builtin_interfaces/Time <-> float seconds: exact for ROS stamps, nearest nanosecond otherwise."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from coco_ros.convert.stamps import RosTime, seconds_to_time, time_to_seconds


def test_ros_stamps_survive_to_the_nanosecond():
    for sec, nanosec in ((1_700_000_000, 123_456_789), (1_700_000_000, 1), (2_147_483_647, 999_999_999), (0, 1)):
        seconds = time_to_seconds(Time(sec=sec, nanosec=nanosec))
        assert isinstance(seconds, float)
        assert seconds_to_time(seconds) == Time(sec=sec, nanosec=nanosec)
        assert seconds.nanoseconds == sec * 10**9 + nanosec
        assert seconds == (sec * 10**9 + nanosec) / 10**9


def test_epoch_seconds_alone_are_only_as_precise_as_a_float():
    seconds = time_to_seconds(Time(sec=1_700_000_000, nanosec=123_456_789))
    plain = float(seconds) + 0.0
    assert type(plain) is float and type(seconds + 1.0) is float  # arithmetic forgets the exact stamp
    rounded = seconds_to_time(plain)
    assert rounded.sec == 1_700_000_000 and abs(rounded.nanosec - 123_456_789) <= 120  # 2**-22 s / 2


def test_small_times_round_trip_exactly_as_plain_floats():
    rng = np.random.default_rng(7)
    for total in rng.integers(1, 2**22 * 10**9, 2000):
        time = Time(sec=int(total // 10**9), nanosec=int(total % 10**9))
        assert seconds_to_time(float(time_to_seconds(time))) == time


def test_rounding_to_the_nearest_nanosecond():
    assert seconds_to_time(1.5) == Time(sec=1, nanosec=500_000_000)
    assert seconds_to_time(2.9999999999) == Time(sec=3, nanosec=0)
    assert seconds_to_time(-0.25) == Time(sec=-1, nanosec=750_000_000)
    assert seconds_to_time(np.float64(4.0)) == Time(sec=4)
    assert time_to_seconds(Time(sec=-1, nanosec=750_000_000)) == -0.25


def test_zero_is_unset():
    assert time_to_seconds(Time()) is None
    assert seconds_to_time(None) == Time()


def test_bad_times_are_refused():
    with pytest.raises(ValueError, match="must be finite, got nan"):
        seconds_to_time(math.nan)
    with pytest.raises(ValueError, match="outside the range of a ROS time"):
        seconds_to_time(2.0**31)


def test_ros_time_pickles_and_prints():
    stamp = RosTime(12, 34)
    again = pickle.loads(pickle.dumps(stamp))
    assert (again, again.sec, again.nanosec) == (stamp, 12, 34)
    assert repr(stamp) == "RosTime(sec=12, nanosec=34)" and f"{stamp:.3f}" == "12.000"
