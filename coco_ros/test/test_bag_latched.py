"""Latched topics (/tf_static) reach a replay that starts at an offset or loops.

rosbag2's long-standing complaint: ``ros2 bag play --start-offset`` (or ``--loop``) skips the
/tf_static messages recorded at the start, so the static frames never appear. ``latched(before=t)``
returns what a subscriber joining at ``t`` would have received, for the replay to publish first.
"""

from __future__ import annotations

import pytest
from tf2_msgs.msg import TFMessage

from coco_ros.bag import TF_STATIC, BagReader, BagWriter, Qos

T0 = 1_700_000_000_000_000_000
MS = 1_000_000
S = 1_000_000_000


def static(parent: str, child: str, x: float) -> TFMessage:
    from geometry_msgs.msg import TransformStamped

    t = TransformStamped()
    t.header.frame_id, t.child_frame_id = parent, child
    t.transform.translation.x = x
    t.transform.rotation.w = 1.0
    return TFMessage(transforms=[t])


@pytest.fixture
def bag(tmp_path):
    """Two static broadcasters at the start, a latched robot description updated once, live data."""
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    latched = Qos(depth=1, durability="transient_local")
    with BagWriter(tmp_path / "bag", chunk_size=4096) as writer:
        writer.write("/tf_static", static("world", "base", 1.0), T0, qos=TF_STATIC)
        writer.write("/tf_static", static("base", "camera", 2.0), T0 + 1 * MS)
        writer.write("/robot_description", String(data="<robot name='v1'/>"), T0 + 2 * MS, qos=latched)
        for i in range(300):
            joints = JointState(name=["j"], position=[float(i)])
            writer.write("/joint_states", joints, T0 + 10 * MS + i * 10 * MS)
            if i % 10 == 0:
                writer.write("/tf", static("base", "hand", float(i)), T0 + 11 * MS + i * 10 * MS)
        writer.write("/robot_description", String(data="<robot name='v2'/>"), T0 + 2 * S, qos=latched)
    return tmp_path / "bag"


def frames(messages) -> list[tuple[str, str]]:
    static_messages = [m.message for m in messages if m.topic == "/tf_static"]
    return [(t.header.frame_id, t.child_frame_id) for m in static_messages for t in m.transforms]


def test_latched_topics_are_those_offered_transient_local(bag):
    with BagReader(bag) as reader:
        assert reader.latched_topics() == ["/tf_static", "/robot_description"]


def test_replay_from_an_offset_gets_every_static_transform_first(bag):
    with BagReader(bag) as reader:
        start = reader.start_time + 1 * S
        first = reader.latched(before=start)
        rest = list(reader.messages(start=start))
    assert frames(first) == [("world", "base"), ("base", "camera")]
    assert [m.topic for m in first] == ["/tf_static", "/tf_static", "/robot_description"]
    assert first[2].message.data == "<robot name='v1'/>"  # the version current at the offset
    assert all(m.log_time < start for m in first)
    assert rest and all(m.log_time >= start for m in rest)
    assert not any(m.topic == "/tf_static" for m in rest)  # not twice


def test_latched_keeps_only_the_last_message_of_other_latched_topics(bag):
    with BagReader(bag) as reader:
        late = reader.latched(before=reader.end_time + 1)
    descriptions = [m.message.data for m in late if m.topic == "/robot_description"]
    assert descriptions == ["<robot name='v2'/>"]
    assert len([m for m in late if m.topic == "/tf_static"]) == 2


def test_each_loop_pass_delivers_the_static_transforms(bag):
    """A looping replay from an offset: every pass starts with latched() then messages(start=...)."""
    with BagReader(bag) as reader:
        start = reader.start_time + 500 * MS
        passes = []
        for _ in range(3):
            delivered = reader.latched(before=start) + list(reader.messages(start=start))
            passes.append(frames(delivered))
    assert passes == [[("world", "base"), ("base", "camera")]] * 3


def test_from_the_start_latched_is_empty_and_the_stream_has_them(bag):
    with BagReader(bag) as reader:
        assert reader.latched(before=reader.start_time) == []
        assert frames(reader.messages(start=reader.start_time))[:2] == [("world", "base"), ("base", "camera")]


def test_topic_filter_applies(bag):
    with BagReader(bag) as reader:
        assert reader.latched(["/joint_states", "/tf"], before=T0 + 3 * S) == []
        only = reader.latched("/robot_description", before=T0 + 3 * S)
    assert [m.topic for m in only] == ["/robot_description"]


def test_tf_static_without_qos_information_counts_as_latched(tmp_path):
    """Old bags have no offered_qos_profiles; /tf_static is latched by its nature."""
    with BagWriter(tmp_path / "old") as writer:
        writer.write("/tf_static", static("world", "base", 1.0), T0, qos=())
        writer.write("/robot/tf_static", static("robot", "arm", 1.0), T0, qos=())
        writer.write("/tf", static("base", "hand", 0.5), T0 + S, qos=())
    with BagReader(tmp_path / "old") as reader:
        assert reader.topics["/tf_static"].offered_qos_profiles == ()
        assert reader.latched_topics() == ["/tf_static", "/robot/tf_static"]
        assert len(reader.latched(before=T0 + S)) == 2


def test_tf_static_written_without_qos_is_recorded_transient_local(tmp_path):
    with BagWriter(tmp_path / "bag") as writer:
        writer.write("/tf_static", static("world", "base", 1.0), T0)
        writer.write("/tf", static("base", "hand", 0.5), T0 + S)
    with BagReader(tmp_path / "bag") as reader:
        assert reader.topics["/tf_static"].offered_qos_profiles == (TF_STATIC,)
        assert reader.topics["/tf"].offered_qos_profiles == (Qos(),)
        assert [m.topic for m in reader.latched(before=T0 + S)] == ["/tf_static"]
