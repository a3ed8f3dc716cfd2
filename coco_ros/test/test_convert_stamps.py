"""builtin_interfaces/Time <-> float seconds: exact for ROS stamps, nearest nanosecond otherwise."""

from __future__ import annotations

import math
import time
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


def _received_messages(stamp: Time) -> list[tuple[str, object]]:
    """A message of each converter path that reads a header stamp: rclpy messages (PoseStamped) and
    the converters that read the CDR bytes themselves (JointState, TFMessage, /tf_static)."""
    from geometry_msgs.msg import PoseStamped, TransformStamped
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Header
    from tf2_msgs.msg import TFMessage

    header = Header(stamp=stamp, frame_id="world")
    transform = TransformStamped(header=header, child_frame_id="tool")
    transform.transform.rotation.w = 1.0
    pose = PoseStamped(header=header)
    pose.pose.orientation.w = 1.0
    return [("geometry_msgs/msg/PoseStamped", pose),
            ("sensor_msgs/msg/JointState", JointState(header=header, name=["a"], position=[0.5])),
            ("tf2_msgs/msg/TFMessage", TFMessage(transforms=[transform]))]


@pytest.mark.parametrize("sec, nanosec, problem", [
    (2**31 - 1, 0, r"the stamp sec=2147483647 is \d+ s ahead of this machine's clock \(at most 86400\)"),
    (1_700_000_000, 1_000_000_000, "the stamp's nanosec=1000000000 is not between 0 and 999999999"),
    (-5, 0, "the stamp sec=-5 is before 1970"),
])
def test_a_received_stamp_that_is_no_acquisition_time_is_refused(sec, nanosec, problem):
    # sec=2**31-1 was accepted and put 447,483,647 s into a CSV's time column.
    from coco_core.errors import MessageError
    from coco_ros.convert import converter_for
    from rclpy.serialization import serialize_message

    for type_name, message in _received_messages(Time(sec=sec, nanosec=nanosec)):
        converter = converter_for(type_name)
        with pytest.raises(MessageError, match=problem):
            converter.from_cdr(serialize_message(message))
    now = Time(sec=int(time.time()) + 60, nanosec=5)  # a sender's clock a minute ahead: accepted
    for type_name, message in _received_messages(now):
        converter_for(type_name).from_cdr(serialize_message(message))
