"""PoseStamped, TransformStamped and TFMessage <-> FramePose and TransformSample."""

from __future__ import annotations

import math

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from coco_core.transforms import se3
from coco_core.transforms.samples import FramePose, TransformSample
from coco_ros.convert import converter_for, geometry
from coco_ros.convert.stamps import RosTime
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion, Transform, TransformStamped, Vector3
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Header

poses = converter_for("geometry_msgs/msg/PoseStamped", child_frame="tool")
transforms = converter_for("geometry_msgs/msg/TransformStamped")


def through_the_wire(msg):
    received = deserialize_message(serialize_message(msg), type(msg))
    assert received == msg
    return received


def a_transform(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    return se3.make(se3.axis_angle(axis / np.linalg.norm(axis), rng.uniform(-3, 3)), rng.normal(size=3))


def quaternion(q: Quaternion) -> np.ndarray:
    return np.array([q.x, q.y, q.z, q.w])


def test_pose_stamped_round_trips():
    msg = PoseStamped(header=Header(stamp=Time(sec=1_700_000_000, nanosec=1), frame_id="base"),
                      pose=Pose(position=Point(x=0.1, y=-0.2, z=0.3),
                                orientation=Quaternion(x=0.0, y=0.0, z=math.sin(0.4), w=math.cos(0.4))))
    pose = poses.to_coco(through_the_wire(msg))
    assert isinstance(pose, FramePose) and (pose.target, pose.source) == ("base", "tool")
    assert pose.stamp == RosTime(1_700_000_000, 1)
    np.testing.assert_allclose(pose.transform[:3, 3], [0.1, -0.2, 0.3])
    np.testing.assert_allclose(pose.transform[:3, :3], se3.axis_angle((0, 0, 1), 0.8), atol=1e-15)
    back = through_the_wire(poses.to_ros(pose))
    assert back.header == msg.header
    np.testing.assert_allclose(quaternion(back.pose.orientation), quaternion(msg.pose.orientation), atol=1e-15)
    assert (back.pose.position.x, back.pose.position.y, back.pose.position.z) == (0.1, -0.2, 0.3)


def test_frame_pose_round_trips():
    pose = FramePose("map", "camera", a_transform(1), 12.75)
    again = poses.to_coco(poses.to_ros(pose))
    assert (again.target, again.source, again.stamp) == ("map", "tool", 12.75)  # source: the option
    np.testing.assert_allclose(again.transform, pose.transform, atol=1e-14)
    assert converter_for("geometry_msgs/PoseStamped").to_coco(poses.to_ros(pose)).source == ""


def test_a_quaternion_is_normalised_and_its_sign_may_flip():
    msg = PoseStamped(pose=Pose(orientation=Quaternion(x=0.0, y=0.0, z=-2 * math.sin(0.4), w=-2 * math.cos(0.4))))
    pose = poses.to_coco(msg)
    np.testing.assert_allclose(pose.transform[:3, :3], se3.axis_angle((0, 0, 1), 0.8), atol=1e-15)
    assert pose.stamp is None and pose.target == ""
    written = quaternion(poses.to_ros(pose).pose.orientation)
    np.testing.assert_allclose(written, [0, 0, math.sin(0.4), math.cos(0.4)], atol=1e-15)  # w >= 0


def test_a_zero_quaternion_is_refused():
    with pytest.raises(ValueError, match="is zero: not a rotation"):
        poses.to_coco(PoseStamped(pose=Pose(orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=0.0))))


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_a_position_that_is_not_finite_is_refused_as_tf2_refuses_it(bad):
    """A tracker that lost the hand may publish NaN: converted, it would make every pose composed
    with it NaN (a device target, a registration); refused, the replay counts it and goes on. Both
    the message and its CDR bytes (a bag's), PoseStamped and the TF paths."""
    msg = PoseStamped(pose=Pose(position=Point(x=0.1, y=bad, z=0.2), orientation=Quaternion(w=1.0)))
    for convert in (poses.to_coco, lambda m: poses.from_cdr(serialize_message(m))):
        with pytest.raises(ValueError, match=r"translation \(0.1, (nan|inf), 0.2\) is not finite: not a pose"):
            convert(msg)
    stamped = TransformStamped(child_frame_id="hand", transform=Transform(translation=Vector3(z=bad),
                                                                         rotation=Quaternion(w=1.0)))
    with pytest.raises(ValueError, match="is not finite: not a pose"):
        transforms.to_coco(stamped)
    tf = converter_for("tf2_msgs/msg/TFMessage")
    with pytest.raises(ValueError, match="is not finite: not a pose"):
        tf.from_cdr(serialize_message(tf.message_type(transforms=[stamped])))
    turned = PoseStamped(pose=Pose(orientation=Quaternion(z=bad, w=1.0)))
    with pytest.raises(ValueError, match="has no direction"):
        poses.to_coco(turned)


def test_transform_stamped_round_trips():
    msg = TransformStamped(header=Header(stamp=Time(sec=5, nanosec=250_000_000), frame_id="world"),
                           child_frame_id="marker_7",
                           transform=Transform(translation=Vector3(x=1.0, y=2.0, z=3.0),
                                               rotation=Quaternion(x=0.5, y=0.5, z=0.5, w=0.5)))
    sample = transforms.to_coco(through_the_wire(msg))
    assert isinstance(sample, TransformSample)
    assert (sample.parent, sample.child, sample.stamp) == ("world", "marker_7", 5.25)
    np.testing.assert_allclose(sample.transform[:3, :3], [[0, 0, 1], [1, 0, 0], [0, 1, 0]], atol=1e-15)
    back = through_the_wire(transforms.to_ros(sample))
    assert back.header == msg.header and back.child_frame_id == "marker_7"
    np.testing.assert_allclose(quaternion(back.transform.rotation), [0.5] * 4, atol=1e-15)
    assert (back.transform.translation.x, back.transform.translation.z) == (1.0, 3.0)
    sample = TransformSample("base", "camera", a_transform(2), None)
    again = transforms.to_coco(transforms.to_ros(sample))
    assert (again.parent, again.child, again.stamp) == ("base", "camera", None)
    np.testing.assert_allclose(again.transform, sample.transform, atol=1e-14)


def test_a_frame_pose_is_published_as_a_transform():
    msg = transforms.to_ros(FramePose("base", "gripper", a_transform(3), 1.0))
    assert (msg.header.frame_id, msg.child_frame_id, msg.header.stamp) == ("base", "gripper", Time(sec=1))


def test_wrong_values_are_refused():
    with pytest.raises(TypeError, match="publishes FramePose values as geometry_msgs/msg/PoseStamped, got "
                                        "TransformSample"):
        poses.to_ros(TransformSample("a", "b", np.eye(4)))
    with pytest.raises(ValueError, match="expected a 4x4 transform, got shape \\(3, 3\\)"):
        transforms.to_ros(TransformSample("a", "b", np.eye(3)))
    with pytest.raises(TypeError, match="converts geometry_msgs/msg/TransformStamped messages, got PoseStamped"):
        transforms.to_coco(PoseStamped())


@pytest.mark.parametrize("frame", ["", "a", "base", "odom_", "a_frame_name_of_some_length"])
@pytest.mark.parametrize("stamp", [None, 12.5, RosTime(1_700_000_000, 123_456_789), -3.25])
def test_pose_stamped_cdr_reads_back_as_the_message_to_ros_builds(frame, stamp):
    """Every length of frame_id (so every padding before the doubles) and every kind of stamp."""
    value = FramePose(frame, "tool", a_transform(7), stamp)
    assert poses.writes_cdr
    assert deserialize_message(poses.to_cdr(value), PoseStamped) == poses.to_ros(value)


def test_writing_cdr_refuses_what_to_ros_refuses():
    with pytest.raises(TypeError, match="publishes FramePose values as geometry_msgs/msg/PoseStamped"):
        poses.to_cdr(TransformSample("a", "b", np.eye(4)))
    with pytest.raises(ValueError, match="expected a 4x4 transform"):
        poses.to_cdr(FramePose("a", "b", np.eye(3)))
    with pytest.raises(ValueError, match="a ROS time must be finite"):
        poses.to_cdr(FramePose("a", "b", np.eye(4), math.nan))


def test_a_converter_that_does_not_write_cdr_serializes_its_message():
    value = FramePose("base", "gripper", a_transform(3), 1.0)
    assert not transforms.writes_cdr
    assert deserialize_message(transforms.to_cdr(value), TransformStamped) == transforms.to_ros(value)


# --- TFMessage -------------------------------------------------------------------------------------
# tf2_msgs has no PyPI wheel: the workspace builds it (vendor/tf2_msgs).

@pytest.fixture
def tf_converter():
    return converter_for("tf2_msgs/msg/TFMessage")


def test_tf_message_to_samples_and_back(tf_converter):
    samples = [TransformSample("world", "base", a_transform(4), RosTime(7, 1)),
               TransformSample("base", "camera", a_transform(5), RosTime(7, 2))]
    msg = tf_converter.to_ros(samples)
    assert [t.child_frame_id for t in msg.transforms] == ["base", "camera"]
    back = tf_converter.to_coco(msg)
    assert [(s.parent, s.child, s.stamp.nanosec) for s in back] == [("world", "base", 1), ("base", "camera", 2)]
    for sample, again in zip(samples, back):
        np.testing.assert_allclose(again.transform, sample.transform, atol=1e-14)
    again = tf_converter.to_ros(tf_converter.to_coco(msg))  # equal up to rounding (quaternion -> matrix -> quaternion)
    for a, b in zip(again.transforms, msg.transforms, strict=True):
        assert (a.header, a.child_frame_id) == (b.header, b.child_frame_id)
        np.testing.assert_allclose(quaternion(a.transform.rotation), quaternion(b.transform.rotation), atol=1e-15)
        assert a.transform.translation == b.transform.translation
    one = tf_converter.to_ros(FramePose("map", "robot", np.eye(4)))
    assert [(t.header.frame_id, t.child_frame_id) for t in one.transforms] == [("map", "robot")]
    assert tf_converter.to_ros([]).transforms == []
    with pytest.raises(TypeError, match="publishes a TransformSample or FramePose, or a list of them, got int"):
        tf_converter.to_ros(3)
    with pytest.raises(TypeError, match="got str"):
        tf_converter.to_ros([samples[0], "base"])


def test_tf_message_with_the_real_package():
    import tf2_msgs.msg as tf2_msgs

    converter = converter_for("tf2_msgs/msg/TFMessage")
    msg = converter.to_ros([TransformSample("world", "base", a_transform(6), 3.5)])
    assert isinstance(msg, tf2_msgs.TFMessage)
    received = deserialize_message(serialize_message(msg), tf2_msgs.TFMessage)
    again = converter.to_ros(converter.to_coco(received))
    assert again.transforms[0].header == msg.transforms[0].header
    assert again.transforms[0].transform.translation == msg.transforms[0].transform.translation


def test_without_tf2_msgs_the_error_says_how_to_get_it(monkeypatch):
    """A shell that did not source the workspace cannot import tf2_msgs: the error says how to get it."""
    real = geometry.message_class

    def missing(name: str) -> type:
        if name.startswith("tf2_msgs/"):
            raise ModuleNotFoundError("No module named 'tf2_msgs'")
        return real(name)

    monkeypatch.setattr(geometry, "message_class", missing)
    with pytest.raises(ImportError, match="needs the tf2_msgs Python package .*vendor/tf2_msgs.*scripts/setup.sh"):
        converter_for("tf2_msgs/msg/TFMessage")


@pytest.mark.parametrize("static", [False, True])
def test_tf_message_from_cdr_reads_the_bytes_as_to_coco_reads_the_message(static):
    """TFMessages of 0-6 transforms with frame names of every length (every alignment), zero and real
    stamps, random poses, serialised by rclpy: from_cdr gives the samples to_coco gives."""
    import random

    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Quaternion, Transform, TransformStamped, Vector3
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Header

    converter = converter_for("tf2_msgs/msg/TFMessage", static=static)
    message_class = converter.message_type
    rng = random.Random(3)
    for _ in range(300):
        transforms = []
        for _ in range(rng.randint(0, 6)):
            quaternion = [rng.uniform(-1, 1) for _ in range(4)]
            transforms.append(TransformStamped(
                header=Header(stamp=Time(sec=rng.choice([0, 1_700_000_000]), nanosec=rng.choice([0, 5])),
                              frame_id="p" * rng.randint(1, 9)),
                child_frame_id="cé" * rng.randint(1, 5),
                transform=Transform(translation=Vector3(x=rng.uniform(-5, 5), y=rng.uniform(-5, 5), z=1.0),
                                    rotation=Quaternion(x=quaternion[0], y=quaternion[1], z=quaternion[2],
                                                        w=quaternion[3]))))
        msg = message_class(transforms=transforms)
        expected = converter.to_coco(msg)
        got = converter.from_cdr(serialize_message(msg))
        assert [(s.parent, s.child, s.stamp, s.static) for s in got] == \
            [(s.parent, s.child, s.stamp, s.static) for s in expected]
        for ours, theirs in zip(got, expected):
            np.testing.assert_allclose(ours.transform, theirs.transform, atol=1e-12)
    zero = message_class(transforms=[TransformStamped(child_frame_id="a", transform=Transform(
        rotation=Quaternion(x=0.0, y=0.0, z=0.0, w=0.0)))])
    with pytest.raises(ValueError, match="is zero: not a rotation"):
        converter.from_cdr(serialize_message(zero))
