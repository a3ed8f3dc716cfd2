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


def test_from_cdr_reads_the_bytes_as_to_coco_reads_the_message():
    """JointStates of every shape (0-25 joints, names of varying length for every alignment, optional
    velocities and efforts, zero and real stamps, mismatched lengths) serialised by rclpy: from_cdr
    gives what to_coco gives, or the same refusal; the positions are views of the CDR bytes."""
    import random

    converter = converter_for("sensor_msgs/msg/JointState")
    rng = random.Random(7)
    refused = 0
    for _ in range(500):
        count = rng.randint(0, 25)
        names = ["".join(rng.choice("abcé_xyz0123") for _ in range(rng.randint(1, 12))) for _ in range(count)]
        msg = JointState(header=Header(stamp=Time(sec=rng.choice([0, 1_700_000_000]), nanosec=rng.choice([0, 123])),
                                       frame_id="f" * rng.randint(0, 9)), name=names)
        msg.position = [rng.uniform(-3, 3) for _ in range(count + rng.choice([0, 0, 0, 1]))]
        if rng.random() < 0.5:
            msg.velocity = [rng.uniform(-3, 3) for _ in range(count)]
        if rng.random() < 0.5:
            msg.effort = [rng.uniform(-3, 3) for _ in range(count)]
        data = serialize_message(msg)
        try:
            expected = converter.to_coco(msg)
        except ValueError as error:
            refused += 1
            with pytest.raises(ValueError, match=str(error).replace("(", r"\(").replace(")", r"\)")):
                converter.from_cdr(data)
            continue
        got = converter.from_cdr(data)
        assert got.names == expected.names and got.stamp == expected.stamp
        np.testing.assert_array_equal(got.positions, expected.positions)
        for ours, theirs in ((got.velocities, expected.velocities), (got.efforts, expected.efforts)):
            assert (ours is None and theirs is None) or np.array_equal(ours, theirs)
        assert got.positions.base is not None and not got.positions.flags.writeable  # a view of the bytes
    assert 0 < refused < 500


def test_from_cdr_refuses_cut_bytes():
    converter = converter_for("sensor_msgs/msg/JointState")
    data = serialize_message(JointState(name=["a", "b"], position=[1.0, 2.0]))
    with pytest.raises(ValueError, match="malformed JointState CDR"):
        converter.from_cdr(data[:-9])


def test_from_cdr_reads_each_message_s_own_names_when_the_list_changes():
    """The last name section is reused only for the same bytes at the same alignment: messages whose
    names differ, share a prefix, or sit after a frame_id of another length are each read anew."""
    converter = converter_for("sensor_msgs/msg/JointState")
    cases = [(["a", "b"], "base"), (["a", "b"], "base"), (["a", "b", "c"], "base"), (["a", "b"], "base_"),
             (["a", "bb"], "base"), ([], "base"), (["a", "b"], "")]
    for names, frame in cases * 2:
        msg = JointState(name=names, position=[float(i) for i in range(len(names))])
        msg.header.frame_id = frame
        sample = converter.from_cdr(serialize_message(msg))
        assert sample.names == tuple(names), (names, frame)
        np.testing.assert_array_equal(sample.positions, np.arange(len(names), dtype=float))
