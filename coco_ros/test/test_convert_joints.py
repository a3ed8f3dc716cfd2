"""sensor_msgs/JointState <-> JointSample (a JointStateSample keeps velocities and efforts)."""

from __future__ import annotations

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from coco_core.transforms.samples import JointSample
from coco_ros.convert import converter_for
from coco_ros.convert.joints import JointStateSample
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

joints = converter_for("sensor_msgs/msg/JointState")


def through_the_wire(msg):
    received = deserialize_message(serialize_message(msg), type(msg))
    assert received == msg
    return received


def test_joint_state_round_trips_with_velocities_and_efforts():
    msg = JointState(header=Header(stamp=Time(sec=1_700_000_000, nanosec=999)), name=["shoulder", "elbow", "wrist"],
                     position=[0.1, -1.2, 3.0], velocity=[0.0, 0.5, -0.5], effort=[1.0, 2.0, 3.0])
    sample = joints.to_coco(through_the_wire(msg))
    assert isinstance(sample, JointSample) and isinstance(sample, JointStateSample)
    assert sample.names == ("shoulder", "elbow", "wrist")
    assert sample.as_mapping() == {"shoulder": 0.1, "elbow": -1.2, "wrist": 3.0}
    np.testing.assert_array_equal(sample.velocities, [0.0, 0.5, -0.5])
    np.testing.assert_array_equal(sample.efforts, [1.0, 2.0, 3.0])
    assert sample.stamp.sec == 1_700_000_000 and sample.stamp.nanosec == 999
    assert through_the_wire(joints.to_ros(sample)) == msg


def test_positions_only():
    msg = JointState(name=["a", "b"], position=[1.0, 2.0])
    sample = joints.to_coco(msg)
    assert sample.velocities is None and sample.efforts is None and sample.stamp is None
    assert joints.to_ros(sample) == msg


def test_a_plain_joint_sample_is_published():
    msg = through_the_wire(joints.to_ros(JointSample(("j1", "j2"), np.array([0.25, 0.5]), 2.5)))
    assert list(msg.name) == ["j1", "j2"] and list(msg.position) == [0.25, 0.5]
    assert list(msg.velocity) == [] and list(msg.effort) == [] and msg.header.stamp == Time(sec=2, nanosec=500_000_000)
    back = joints.to_coco(msg)
    assert back.names == ("j1", "j2") and back.stamp == 2.5
    np.testing.assert_array_equal(back.positions, [0.25, 0.5])


@pytest.mark.parametrize("msg, error", [
    (JointState(name=["a", "b"], position=[1.0]), "2 names but 1 position values"),
    (JointState(name=["a"], velocity=[1.0]), r"1 names but 0 position values \(positions are required\)"),
    (JointState(name=["a"], position=[1.0], effort=[1.0, 2.0]), "1 names but 2 effort values"),
])
def test_inconsistent_joint_states_are_refused(msg, error):
    with pytest.raises(ValueError, match=error):
        joints.to_coco(msg)


def test_inconsistent_samples_are_refused():
    with pytest.raises(ValueError, match="2 names has 3 positions"):
        joints.to_ros(JointSample(("a", "b"), np.zeros(3)))
    with pytest.raises(ValueError, match="1 names has 2 velocities"):
        joints.to_ros(JointStateSample(("a",), np.zeros(1), None, np.zeros(2)))
    with pytest.raises(TypeError, match="publishes JointSample values"):
        joints.to_ros({"a": 1.0})
