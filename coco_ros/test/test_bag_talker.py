"""Reading a bag written by rosbag2 itself (shared/data/rosbag2: the talker demo, 20 messages)."""

from __future__ import annotations

import pytest
import yaml

from coco_ros.bag import BagReader


@pytest.fixture
def expected(talker_bag):
    """What rosbag2 wrote into the bag's metadata.yaml."""
    return yaml.safe_load((talker_bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]


def test_topics_types_and_counts_match_metadata_yaml(talker_bag, expected):
    with BagReader(talker_bag) as reader:
        declared = {
            t["topic_metadata"]["name"]: (t["topic_metadata"]["type"], t["message_count"])
            for t in expected["topics_with_message_count"]
        }
        assert {name: (info.type, info.message_count) for name, info in reader.topics.items()} == declared
        assert reader.message_count == expected["message_count"] == 20
        assert reader.start_time == expected["starting_time"]["nanoseconds_since_epoch"]
        assert reader.duration == expected["duration"]["nanoseconds"]
        assert all(info.serialization_format == "cdr" for info in reader.topics.values())
        assert reader.errors == [] and reader.notes == []
        messages = list(reader.messages())
    assert len(messages) == 20
    times = [m.log_time for m in messages]
    assert times == sorted(times)
    assert sum(1 for m in messages if m.topic == "/topic") == 10


def test_string_and_log_messages_deserialize_with_rclpy(talker_bag):
    from rcl_interfaces.msg import Log
    from std_msgs.msg import String

    with BagReader(talker_bag) as reader:
        strings = list(reader.messages("/topic"))
        logs = list(reader.messages(["/rosout"]))
    assert all(isinstance(m.message, String) for m in strings)
    assert [m.message.data for m in strings] == [f"Hello, world! {i}" for i in range(10)]
    assert all(isinstance(m.message, Log) for m in logs)
    assert logs[0].message.name == "minimal_publisher"
    assert logs[0].message.msg == "Publishing: 'Hello, world! 0'"
    assert strings[0].type == "std_msgs/msg/String"


def test_offered_qos_profiles_come_from_the_bag(talker_bag):
    with BagReader(talker_bag) as reader:
        rosout, topic = reader.topics["/rosout"], reader.topics["/topic"]
    # Recorded by an old rosbag2 with enum numbers: durability 1 = transient local, 2 = volatile.
    assert rosout.offered_qos_profiles[0].durability == "transient_local"
    assert rosout.offered_qos_profiles[0].lifespan == (10, 0)
    assert rosout.latched and not topic.latched
    assert topic.offered_qos_profiles[0].reliability == "reliable"
    assert "string data" in topic.definition and topic.definition_encoding == "ros2msg"


def test_the_mcap_file_alone_reads_the_same_as_the_folder(talker_bag):
    with BagReader(talker_bag) as folder, BagReader(talker_bag / "talker.mcap") as file:
        assert folder.files == [talker_bag / "talker.mcap"]
        assert set(file.topics) == set(folder.topics)
        one = [(m.topic, m.log_time, m.publish_time, m.data) for m in folder.messages()]
        other = [(m.topic, m.log_time, m.publish_time, m.data) for m in file.messages()]
    assert one == other


def test_time_window_selects_log_times_in_start_inclusive_end_exclusive(talker_bag):
    with BagReader(talker_bag) as reader:
        everything = list(reader.messages())
        start, end = everything[5].log_time, everything[12].log_time
        window = list(reader.messages(start=start, end=end))
        late_topic = list(reader.messages("/topic", start=start))
    assert [m.log_time for m in window] == [m.log_time for m in everything[5:12]]
    assert [m.log_time for m in late_topic] == [m.log_time for m in everything[5:] if m.topic == "/topic"]


def test_same_messages_as_rosbags_reads(talker_bag):
    from rosbags.rosbag2 import Reader

    # rosbags is given the file: with this folder (metadata.yaml version 4) it numbers topics from
    # metadata.yaml, which do not match the file's channel ids, and yields nothing.
    with Reader(talker_bag / "talker.mcap") as other:
        theirs = [(c.topic, t, bytes(raw)) for c, t, raw in other.messages()]
    with BagReader(talker_bag) as reader:
        ours = [(m.topic, m.log_time, m.data) for m in reader.messages()]
    assert ours == theirs


def test_latched_rosout_is_its_last_message_before_the_offset(talker_bag):
    with BagReader(talker_bag) as reader:
        rosout = list(reader.messages("/rosout"))
        offset = rosout[3].log_time + 1
        latched = reader.latched(before=offset)
    assert [(m.topic, m.log_time) for m in latched] == [("/rosout", rosout[3].log_time)]
