"""A bag written by BagWriter reads back identically with BagReader and with the independent rosbags.

The bag holds what a CoCo recording holds: joint states (19 joints, 100 Hz), /tf and /tf_static
(transient local), poses and 640x480 RGB images; the poses are written last, out of log-time order,
as a recorder receiving topics at different latencies would, and as CDR bytes (the recorder's path),
the others as message objects.

rclpy's serializer leaves CDR padding bytes uninitialised, so bytes are compared only where they
were given (poses) or made deterministically (TFMessage); everything is compared field by field.
"""

from __future__ import annotations

import array

import numpy as np
import pytest
import yaml
from tf2_msgs.msg import TFMessage

from coco_core.errors import BagError, MessageTypeError
from coco_ros.bag import TF_STATIC, BagReader, BagWriter, Qos
from rclpy.serialization import serialize_message as serialize

T0 = 1_700_000_000_000_000_000
MS = 1_000_000
JOINTS = [f"{side}_{j}" for side in ("left", "right") for j in ("s0", "s1", "e0", "e1", "w0", "w1", "w2")]
JOINTS += ["head_pan", "head_nod", "torso_t0", "left_gripper", "right_gripper"]  # 19, as a Baxter


def stamp(message, log_time: int) -> None:
    message.header.stamp.sec, message.header.stamp.nanosec = divmod(log_time, 1_000_000_000)


def transform(parent: str, child: str, log_time: int, rng: np.random.Generator):
    from geometry_msgs.msg import TransformStamped

    t = TransformStamped()
    stamp(t, log_time)
    t.header.frame_id, t.child_frame_id = parent, child
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = map(float, rng.normal(size=3))
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z, t.transform.rotation.w = map(float, q)
    return t


def recording() -> list[tuple[str, object, int]]:
    """(topic, message, log time) in the order a recorder would write them."""
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import Image, JointState

    rng = np.random.default_rng(7)
    timed: list[tuple[str, object, int]] = [
        ("/tf_static", TFMessage(transforms=[transform("world", "base", T0, rng)]), T0),
        ("/tf_static", TFMessage(transforms=[transform("base", "camera_link", T0 + 1, rng)]), T0 + 1),
    ]
    for i in range(100):
        t = T0 + 1 * MS + i * 10 * MS
        joints = JointState()
        stamp(joints, t)
        joints.name = JOINTS
        joints.position, joints.velocity, joints.effort = (rng.normal(size=19).tolist() for _ in range(3))
        timed.append(("/joint_states", joints, t))
    for i in range(50):
        t = T0 + 2 * MS + i * 20 * MS
        transforms = [transform("base", "left_hand", t, rng), transform("world", "marker_1", t, rng)]
        timed.append(("/tf", TFMessage(transforms=transforms), t))
    for i in range(3):
        t = T0 + 4 * MS + i * 300 * MS
        image = Image()
        stamp(image, t)
        image.header.frame_id = "camera_link"
        image.height, image.width, image.encoding, image.step = 480, 640, "rgb8", 640 * 3
        image.data = rng.integers(0, 256, 640 * 480 * 3, dtype=np.uint8).tobytes()
        timed.append(("/camera/image", image, t))
    timed.sort(key=lambda item: item[2])
    poses = []
    for i in range(20):
        t = T0 + 3 * MS + i * 50 * MS
        pose = PoseStamped()
        stamp(pose, t)
        pose.header.frame_id = "world"
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = map(float, rng.normal(size=3))
        pose.pose.orientation.w = 1.0
        poses.append(("/pose", pose, t))
    return timed + poses  # poses arrive late: written after everything else


@pytest.fixture(scope="module", params=["none", "zstd"])
def written(request, tmp_path_factory):
    """(bag folder, the recording in log-time order, pose bytes by time) for each chunk compression."""
    folder = tmp_path_factory.mktemp(f"roundtrip_{request.param}") / "session"
    items = recording()
    raw = {}
    with BagWriter(folder, compression=request.param, chunk_size=64 * 1024) as writer:
        for topic, message, t in items:
            if topic == "/pose":
                raw[t] = serialize(message)
                writer.write(topic, raw[t], t, type_name="geometry_msgs/msg/PoseStamped")
            else:
                writer.write(topic, message, t, qos=TF_STATIC if topic == "/tf_static" else None)
    return folder, sorted(items, key=lambda item: item[2]), raw


def assert_same(ours, theirs, path: str = "message") -> None:
    """Field-by-field equality of an rclpy message and a rosbags message."""
    if hasattr(type(ours), "get_fields_and_field_types"):
        for name in ours.get_fields_and_field_types():
            assert_same(getattr(ours, name), getattr(theirs, name), f"{path}.{name}")
    elif isinstance(ours, list) and (not ours or hasattr(type(ours[0]), "get_fields_and_field_types")):
        assert len(ours) == len(theirs), f"{path}: {len(ours)} items, rosbags has {len(theirs)}"
        for index, (a, b) in enumerate(zip(ours, theirs)):
            assert_same(a, b, f"{path}[{index}]")
    elif isinstance(ours, (str, bool, int, float)):
        assert ours == theirs, f"{path}: {ours!r} != {theirs!r}"
    else:
        assert isinstance(ours, (array.array, np.ndarray, list, bytes)), f"{path}: unexpected {type(ours)}"
        np.testing.assert_array_equal(np.asarray(ours), np.asarray(theirs), err_msg=path)


def test_reader_reads_back_every_message_identically(written):
    folder, items, raw = written
    with BagReader(folder) as reader:
        assert reader.errors == [] and reader.notes == []
        assert reader.message_count == len(items) == 175
        assert reader.start_time == T0 and reader.end_time == max(t for _, _, t in items)
        back = list(reader.messages())
    assert [(m.topic, m.log_time, m.publish_time) for m in back] == [(topic, t, t) for topic, _, t in items]
    for got, (topic, message, t) in zip(back, items):
        assert got.message == message, f"{topic} at {t}"
        if topic == "/pose":
            assert got.data == raw[t]
        elif topic.startswith("/tf"):  # rclpy's CDR: the same size (Fast CDR leaves the padding unset)
            assert len(got.data) == len(serialize(message))
    image = next(m for m in back if m.topic == "/camera/image").message
    assert (image.width, image.height, len(image.data)) == (640, 480, 640 * 480 * 3)


def test_topics_types_counts_and_qos(written):
    folder, items, raw = written
    with BagReader(folder) as reader:
        topics = reader.topics
    assert {name: (info.type, info.message_count) for name, info in topics.items()} == {
        "/tf_static": ("tf2_msgs/msg/TFMessage", 2),
        "/joint_states": ("sensor_msgs/msg/JointState", 100),
        "/tf": ("tf2_msgs/msg/TFMessage", 50),
        "/camera/image": ("sensor_msgs/msg/Image", 3),
        "/pose": ("geometry_msgs/msg/PoseStamped", 20),
    }
    assert topics["/tf_static"].offered_qos_profiles == (TF_STATIC,)
    assert topics["/tf_static"].latched and not topics["/tf"].latched
    assert topics["/joint_states"].offered_qos_profiles == (Qos(),)


def test_rosbags_reads_back_identically(written):
    from rosbags.interfaces import QosDurability
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    folder, items, raw = written
    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(folder) as reader:
        assert reader.message_count == len(items)
        assert reader.start_time == T0
        counts = {c.topic: c.msgcount for c in reader.connections}
        durability = {c.topic: c.ext.offered_qos_profiles[0].durability for c in reader.connections}
        digests = {c.topic: (c.digest, store.hash_rihs01(c.msgtype)) for c in reader.connections}
        back = [(c.topic, t, store.deserialize_cdr(raw, c.msgtype)) for c, t, raw in reader.messages()]
    assert counts == {"/tf_static": 2, "/joint_states": 100, "/tf": 50, "/camera/image": 3, "/pose": 20}
    assert durability["/tf_static"] == QosDurability.TRANSIENT_LOCAL
    assert durability["/tf"] == QosDurability.VOLATILE
    assert all(ours == theirs for ours, theirs in digests.values()), digests
    assert [(topic, t) for topic, t, _ in back] == [(topic, t) for topic, _, t in items]
    for (topic, t, theirs), (_, ours, _) in zip(back, items):
        assert_same(ours, theirs, f"{topic}@{t}")


def test_schemas_alone_decode_the_messages(written):
    """The stored definitions are complete: rosbags rebuilds each type from them, hash for hash."""
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    folder, _, _ = written
    jazzy = get_typestore(Stores.ROS2_JAZZY)
    with open(folder / "session_0.mcap", "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        first = {}
        for schema, channel, message in reader.iter_messages():
            first.setdefault(schema.name, message.data)
    assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
    for schema in summary.schemas.values():
        fresh = get_typestore(Stores.EMPTY)
        fresh.register(get_types_from_msg(schema.data.decode(), schema.name))
        assert fresh.hash_rihs01(schema.name) == jazzy.hash_rihs01(schema.name), schema.name
        decoded = fresh.deserialize_cdr(first[schema.name], schema.name)
        assert type(decoded).__name__ == schema.name.replace("/", "__")


def test_metadata_yaml_is_rosbag2_version_9(written):
    folder, items, raw = written
    info = yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    end = max(t for _, _, t in items)
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["relative_file_paths"] == ["session_0.mcap"]
    assert info["message_count"] == len(items)
    assert info["starting_time"] == {"nanoseconds_since_epoch": T0}
    assert info["duration"] == {"nanoseconds": end - T0}
    assert info["files"] == [
        {
            "path": "session_0.mcap",
            "starting_time": {"nanoseconds_since_epoch": T0},
            "duration": {"nanoseconds": end - T0},
            "message_count": len(items),
        }
    ]
    topics = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    assert {name: t["message_count"] for name, t in topics.items()}["/joint_states"] == 100
    static = topics["/tf_static"]["topic_metadata"]
    assert static["type"] == "tf2_msgs/msg/TFMessage" and static["serialization_format"] == "cdr"
    assert static["offered_qos_profiles"][0]["durability"] == "transient_local"
    assert static["offered_qos_profiles"][0]["history"] == "keep_last"
    assert topics["/pose"]["topic_metadata"]["type_description_hash"].startswith("RIHS01_")
    assert info["ros_distro"] == "jazzy"


def test_mcap_file_follows_the_ros2_profile(written):
    from mcap.reader import make_reader

    folder, items, raw = written
    with open(folder / "session_0.mcap", "rb") as stream:
        reader = make_reader(stream)
        header = reader.get_header()
        summary = reader.get_summary()
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert header.profile == "ros2" and "coco_ros" in header.library
    assert summary.statistics.message_count == len(items)
    assert summary.statistics.chunk_count > 3  # images do not fit one 64 KiB chunk
    channels = {c.topic: c for c in summary.channels.values()}
    assert {c.message_encoding for c in channels.values()} == {"cdr"}
    static_qos = yaml.safe_load(channels["/tf_static"].metadata["offered_qos_profiles"])
    assert static_qos[0]["durability"] == "transient_local"
    assert channels["/tf"].metadata["topic_type_hash"].startswith("RIHS01_")
    names = {summary.schemas[c.schema_id].name for c in channels.values()}
    assert names == {
        "tf2_msgs/msg/TFMessage",
        "sensor_msgs/msg/JointState",
        "sensor_msgs/msg/Image",
        "geometry_msgs/msg/PoseStamped",
    }
    stored = yaml.safe_load(metadata["rosbag2"]["serialized_metadata"])
    assert stored["message_count"] == len(items) and stored["version"] == 9


def test_writer_refuses_what_it_cannot_record(tmp_path):
    from std_msgs.msg import String

    (tmp_path / "used").mkdir()
    (tmp_path / "used" / "file").write_text("x")
    with pytest.raises(BagError, match="new or empty folder"):
        BagWriter(tmp_path / "used")
    writer = BagWriter(tmp_path / "bag")
    with pytest.raises(BagError, match="need type_name"):
        writer.write("/raw", b"\x00\x01\x00\x00", T0)
    with pytest.raises(BagError, match="fully qualified topic"):
        writer.write("chatter", String(data="x"), T0)
    writer.write("/chatter", String(data="x"), T0)
    with pytest.raises(BagError, match="holds std_msgs/msg/String messages"):
        writer.write("/chatter", b"\x00\x01\x00\x00", T0, type_name="std_msgs/msg/Bool")
    with pytest.raises(BagError, match="integer nanoseconds"):
        writer.write("/chatter", String(data="x"), 1.5)
    assert writer.close() == tmp_path / "bag"
    assert writer.close() == tmp_path / "bag"  # idempotent
    with pytest.raises(BagError, match="closed"):
        writer.write("/chatter", String(data="y"), T0 + 1)
    with BagReader(tmp_path / "bag") as reader:
        assert [m.message.data for m in reader.messages()] == ["x"]


def test_raw_bytes_and_explicit_definition_for_a_type_not_installed(tmp_path):
    """A type whose package is missing is still recorded and replayed as bytes; decoding says why not."""
    from coco_core.errors import BagError, MessageTypeError

    payload = b"\x00\x01\x00\x00\x2a\x00\x00\x00"
    with BagWriter(tmp_path / "bag") as writer:
        writer.add_topic("/custom", "my_robot_msgs/msg/Gauge", definition="int32 value\n")
        writer.write("/custom", payload, T0)
    with BagReader(tmp_path / "bag") as reader:
        assert reader.topics["/custom"].definition == "int32 value\n"
        (message,) = reader.messages("/custom")
        assert message.data == payload
        with pytest.raises(MessageTypeError, match=r"my_robot_msgs/msg/Gauge.*my_robot_msgs"):
            message.message
        with pytest.raises(MessageTypeError, match="/custom"):
            reader.check_types()
        reader.check_types([])  # nothing asked, nothing missing


def test_out_of_order_writes_inside_one_chunk_come_out_in_log_time_order(tmp_path):
    """A recorder receives topics with different latencies: log times are not monotonic in the file."""
    from std_msgs.msg import String

    order = [5, 3, 4, 9, 1, 3, 7]  # two messages at time 3: they keep their write order
    with BagWriter(tmp_path / "bag") as writer:
        for index, t in enumerate(order):
            writer.write("/a" if index % 2 else "/b", String(data=str(index)), T0 + t)
    with BagReader(tmp_path / "bag") as reader:
        back = [(m.log_time - T0, m.message.data) for m in reader.messages()]
        assert reader.start_time == T0 + 1 and reader.end_time == T0 + 9
    assert back == [(1, "4"), (3, "1"), (3, "5"), (4, "2"), (5, "0"), (7, "6"), (9, "3")]


def write_unchunked(path, items) -> None:
    """An MCAP file without chunks, as rosbag2's ``fastwrite`` storage preset writes them."""
    from mcap.writer import Writer

    from coco_ros.bag.message_types import type_name_of
    from coco_ros.bag.qos import dump_profiles_string
    from coco_ros.bag.schema import DefinitionSource

    source = DefinitionSource()
    with open(path, "wb") as stream:
        writer = Writer(stream, use_chunking=False)
        writer.start(profile="ros2", library="test")
        channels = {}
        for topic, message, _ in items:
            if topic not in channels:
                type_name = type_name_of(message)
                schema = writer.register_schema(type_name, "ros2msg", source.full_text(type_name).encode())
                channels[topic] = writer.register_channel(
                    topic, "cdr", schema, {"offered_qos_profiles": dump_profiles_string([Qos()])}
                )
        for topic, message, t in items:
            writer.add_message(channels[topic], t, serialize(message), t)
        writer.finish()


def test_unchunked_files_are_read_by_scanning_in_log_time_order(tmp_path):
    items = recording()  # poses last, out of order; three 900 KB images make several runs
    path = tmp_path / "fastwrite.mcap"
    write_unchunked(path, items)
    expected = sorted(items, key=lambda item: item[2])
    with BagReader(path) as reader:
        assert reader.errors == [] and any("not chunked" in note for note in reader.notes)
        assert reader.message_count == len(items)
        back = list(reader.messages())
        assert [(m.topic, m.log_time) for m in back] == [(topic, t) for topic, _, t in expected]
        assert all(m.message == message for m, (_, message, _) in zip(back, expected))
        start, end, topics = T0 + 100 * MS, T0 + 700 * MS, ("/pose", "/camera/image")
        window = [(m.topic, m.log_time) for m in reader.messages(topics, start, end)]
    assert window == [(topic, t) for topic, _, t in expected if topic in topics and start <= t < end]


def test_truncated_unchunked_file_keeps_the_messages_before_the_cut(tmp_path):
    items = sorted(recording(), key=lambda item: item[2])
    path = tmp_path / "fastwrite.mcap"
    write_unchunked(path, items)
    data = path.read_bytes()
    image_at = data.index(b"rgb8")  # inside the first image message
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:image_at])
    with BagReader(cut) as reader:
        got = []
        with pytest.raises(BagError, match=r"cut\.mcap at byte \d+: a Message record declares \d+ bytes"):
            for message in reader.messages():
                got.append((message.topic, message.log_time))
    first_image = next(i for i, (topic, _, _) in enumerate(items) if topic == "/camera/image")
    assert got == [(topic, t) for topic, _, t in items[:first_image]]


def test_a_type_without_definition_is_refused_naming_topic_and_type(tmp_path):
    with BagWriter(tmp_path / "bag") as writer:
        with pytest.raises(BagError, match=r"topic /gauge: nope_msgs/msg/Gauge: no message definition"):
            writer.write("/gauge", b"\x00\x01\x00\x00", T0, type_name="nope_msgs/msg/Gauge")


def test_message_objects_are_written_as_canonical_cdr(tmp_path):
    """rclpy's own CDR of a JointState without efforts ends in unset padding that rosbags refuses; the
    writer stores zero-padded bytes ending at the last field, the same for equal messages."""
    from rosbags.typesys import Stores, get_typestore
    from sensor_msgs.msg import JointState

    jazzy = get_typestore(Stores.ROS2_JAZZY)
    message = JointState(name=["a", "b", "c"], position=[1.0, 2.0, 3.0], velocity=[0.1, 0.2, 0.3])
    with pytest.raises(Exception, match="size mismatch"):
        jazzy.deserialize_cdr(serialize(message), "sensor_msgs/msg/JointState")
    with BagWriter(tmp_path / "bag") as writer:
        for i in range(3):
            writer.write("/joint_states", message, T0 + i * MS)
    with BagReader(tmp_path / "bag") as reader:
        back = list(reader.messages())
    assert len({m.data for m in back}) == 1
    data = back[0].data
    decoded = jazzy.deserialize_cdr(data, "sensor_msgs/msg/JointState")
    assert list(decoded.name) == ["a", "b", "c"] and decoded.effort.size == 0
    assert bytes(jazzy.serialize_cdr(decoded, "sensor_msgs/msg/JointState")) == data
    assert back[0].message == message


def test_a_type_the_rosbags_store_lacks_is_encoded_from_its_definition(tmp_path):
    """nav_msgs/Goals is newer than rosbags' Jazzy store: the writer registers it from its .msg text."""
    from geometry_msgs.msg import PoseStamped
    from mcap.reader import make_reader
    from nav_msgs.msg import Goals
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    goals = Goals(goals=[PoseStamped(), PoseStamped()])
    goals.header.frame_id = "map"
    goals.goals[1].pose.position.x = 1.5
    with BagWriter(tmp_path / "bag") as writer:
        writer.write("/goals", goals, T0)
        writer.write("/goals", goals, T0 + MS)
    with BagReader(tmp_path / "bag") as reader:
        back = list(reader.messages())
        type_name = reader.topics["/goals"].type
    assert type_name == "nav_msgs/msg/Goals"
    assert back[0].data == back[1].data and back[0].message == goals
    with open(tmp_path / "bag" / "bag_0.mcap", "rb") as stream:
        schema = next(iter(make_reader(stream).get_summary().schemas.values()))
    fresh = get_typestore(Stores.EMPTY)
    fresh.register(get_types_from_msg(schema.data.decode(), schema.name))
    decoded = fresh.deserialize_cdr(back[0].data, "nav_msgs/msg/Goals")
    assert decoded.header.frame_id == "map" and decoded.goals[1].pose.position.x == 1.5
