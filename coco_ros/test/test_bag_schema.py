"""The pieces under the bag files: message definitions, QoS profiles, type lookup, TFMessage CDR."""

from __future__ import annotations

import numpy as np
import pytest

from coco_core.errors import BagError, MessageTypeError
from coco_ros.bag import TF_STATIC, Qos
from coco_ros.bag import qos as qos_module
from coco_ros.bag.message_types import TF_MESSAGE, TypeResolver, normalize_type, type_name_of
from rclpy.serialization import serialize_message as serialize
from coco_ros.bag.schema import DELIMITER, DefinitionSource, dependencies

TYPES = [
    "std_msgs/msg/String",
    "sensor_msgs/msg/JointState",
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CameraInfo",
    "geometry_msgs/msg/PoseStamped",
    "tf2_msgs/msg/TFMessage",
    "rosgraph_msgs/msg/Clock",
    "rcl_interfaces/msg/ParameterEvent",
]


@pytest.fixture(scope="module")
def jazzy():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


@pytest.mark.parametrize("type_name", TYPES)
def test_full_definitions_rebuild_the_exact_types(type_name, jazzy):
    """rosbags parses our ros2msg text into types whose RIHS01 hashes equal Jazzy's."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    source = DefinitionSource()
    text = source.full_text(type_name)
    fresh = get_typestore(Stores.EMPTY)
    fresh.register(get_types_from_msg(text, type_name))
    assert fresh.hash_rihs01(type_name) == jazzy.hash_rihs01(type_name)
    assert source.type_hash(type_name) == jazzy.hash_rihs01(type_name)


def test_definition_layout_follows_rosbag2():
    text = DefinitionSource().full_text("geometry_msgs/msg/PoseStamped")
    parts = text.split(f"\n{DELIMITER}\n")
    assert parts[0].rstrip().endswith("Pose pose")  # the type's own .msg first
    names = [part.split("\n", 1)[0] for part in parts[1:]]
    # Depth first, dependencies sorted by name, each once, named as rosbag2 does (no /msg/).
    assert names == [
        "MSG: geometry_msgs/Pose",
        "MSG: geometry_msgs/Point",
        "MSG: geometry_msgs/Quaternion",
        "MSG: std_msgs/Header",
        "MSG: builtin_interfaces/Time",
    ]


def test_dependencies_of_a_msg_text():
    text = "# comment with words\nHeader header\nfloat64[9] k\nfoo_msgs/Bar[] bars\nuint8 KIND=1\nstring<=5 s\n"
    assert dependencies(text, "my_msgs") == ["foo_msgs/Bar", "my_msgs/Header"]


def test_missing_definition_names_the_type_and_where_it_looked(tmp_path):
    from coco_core.errors import BagError, MessageTypeError

    with pytest.raises(BagError, match=r"no message definition: expected nope_msgs/msg/Thing\.msg under"):
        DefinitionSource([tmp_path]).full_text("nope_msgs/msg/Thing")


def test_qos_reads_old_numbers_and_foxy_infinity_and_jazzy_names():
    old = qos_module.parse_profiles(
        "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 1\n  deadline:\n    sec: 2147483647\n"
        "    nsec: 4294967295\n  lifespan:\n    sec: 10\n    nsec: 0\n  liveliness: 1\n"
        "  liveliness_lease_duration:\n    sec: 0\n    nsec: 0\n  avoid_ros_namespace_conventions: false"
    )
    assert old == (
        Qos(
            history="unknown",
            depth=0,
            reliability="reliable",
            durability="transient_local",
            deadline=qos_module.INFINITE,
            lifespan=(10, 0),
        ),
    )
    new = qos_module.parse_profiles(qos_module.dump_profiles([TF_STATIC, Qos(reliability="best_effort")]))
    assert new == (TF_STATIC, Qos(reliability="best_effort"))
    assert qos_module.parse_profiles(qos_module.dump_profiles_string([TF_STATIC])) == (TF_STATIC,)
    assert qos_module.parse_profiles("") == () and qos_module.parse_profiles(None) == ()
    with pytest.raises(ValueError, match="QoS durability: expected one of .*transient_local.*got 'sticky'"):
        qos_module.parse_profiles([{**TF_STATIC.to_dict(), "durability": "sticky"}])
    with pytest.raises(ValueError, match="without the 'depth' field"):
        qos_module.parse_profiles([{k: v for k, v in TF_STATIC.to_dict().items() if k != "depth"}])


def test_qos_to_and_from_rclpy():
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    profile = TF_STATIC.to_rclpy()
    assert profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert profile.history == HistoryPolicy.KEEP_LAST and profile.depth == 1
    assert Qos.from_rclpy(profile) == TF_STATIC
    sensor = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
    assert Qos.from_rclpy(sensor).reliability == "best_effort"
    infinite = Qos(deadline=qos_module.INFINITE).to_rclpy()
    assert infinite.deadline.nanoseconds == 2**63 - 1


def test_replay_offer_follows_rosbag2():
    assert qos_module.for_replay([TF_STATIC, TF_STATIC], depth=5) == Qos(depth=5, durability="transient_local")
    mixed = qos_module.for_replay([TF_STATIC, Qos()])
    assert mixed == Qos() and not mixed.transient_local
    assert qos_module.for_replay([]) == Qos()
    # Without a depth override, the recorded history: a late subscriber gets what the recording kept.
    amcl = Qos(depth=1, durability="transient_local")
    assert qos_module.for_replay([amcl, amcl]) == amcl
    assert qos_module.for_replay([Qos(depth=5), Qos(depth=50)]).depth == 50
    assert qos_module.for_replay([Qos(history="keep_all", depth=0)]).history == "keep_all"
    old = Qos(history="unknown", depth=0)  # what the talker bag of rosbag2's tests lists
    assert qos_module.for_replay([old]) == Qos(depth=10)


def test_type_names():
    from sensor_msgs.msg import JointState
    from tf2_msgs.msg import TFMessage

    assert normalize_type("std_msgs/String") == "std_msgs/msg/String"
    assert normalize_type("std_msgs/msg/String") == "std_msgs/msg/String"
    with pytest.raises(ValueError, match="expected a message type name like"):
        normalize_type("String")
    assert type_name_of(JointState()) == "sensor_msgs/msg/JointState"
    assert type_name_of(TFMessage()) == "tf2_msgs/msg/TFMessage"
    with pytest.raises(TypeError, match="expected a ROS message object"):
        type_name_of(42)


def test_resolver_caches_classes_and_explains_missing_packages():
    from std_msgs.msg import String

    resolver = TypeResolver()
    assert resolver.message_class("std_msgs/msg/String") is String
    assert resolver.decoder("std_msgs/msg/String") is resolver.decoder("std_msgs/msg/String")
    with pytest.raises(MessageTypeError, match=r"'nope_msgs/msg/Thing'.*'nope_msgs\.msg'.*ros-jazzy-nope-msgs"):
        resolver.decoder("nope_msgs/msg/Thing", "bag topic /thing")
    with pytest.raises(MessageTypeError, match="has no class 'Nothing'"):
        resolver.decoder("std_msgs/msg/Nothing")


def random_tf(rng: np.random.Generator, count: int):
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage

    transforms = []
    for i in range(count):
        t = TransformStamped()
        t.header.stamp.sec, t.header.stamp.nanosec = int(rng.integers(-5, 2**31 - 1)), int(rng.integers(0, 10**9))
        # Frame names of every length modulo 8 exercise every CDR alignment path.
        t.header.frame_id = "f" * int(rng.integers(0, 9))
        t.child_frame_id = "child_é" + "c" * i
        values = rng.normal(size=7)
        t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = map(float, values[:3])
        t.transform.rotation.x, t.transform.rotation.y = float(values[3]), float(values[4])
        t.transform.rotation.z, t.transform.rotation.w = float(values[5]), float(values[6])
        transforms.append(t)
    return TFMessage(transforms=transforms)


def test_tf_message_cdr_matches_rosbags(jazzy):
    """The workspace's tf2_msgs (vendor/tf2_msgs) writes and reads the CDR of ROS 2 Jazzy's TFMessage,
    in both byte orders, as rosbags' independent Jazzy definition does."""
    rng = np.random.default_rng(3)
    decode = TypeResolver().decoder(TF_MESSAGE)
    for count in (0, 1, 2, 5):
        message = random_tf(rng, count)
        data = serialize(message)
        theirs = jazzy.deserialize_cdr(data, TF_MESSAGE)
        assert len(theirs.transforms) == count
        for ours, other in zip(message.transforms, theirs.transforms):
            assert ours.header.stamp.sec == other.header.stamp.sec
            assert ours.header.stamp.nanosec == other.header.stamp.nanosec
            assert (ours.header.frame_id, ours.child_frame_id) == (other.header.frame_id, other.child_frame_id)
            assert ours.transform.translation.z == other.transform.translation.z
            assert ours.transform.rotation.w == other.transform.rotation.w
        # Same layout; the alignment padding is not compared: Fast CDR leaves it unset.
        little = bytes(jazzy.serialize_cdr(theirs, TF_MESSAGE, little_endian=True))
        assert len(little) == len(data)
        assert decode(little) == message and decode(data) == message
        big = bytes(jazzy.serialize_cdr(theirs, TF_MESSAGE, little_endian=False))
        assert decode(big) == message


def test_tf_message_definition_and_hash_come_from_the_built_package():
    source = DefinitionSource()
    assert source.msg_text(TF_MESSAGE).strip() == "geometry_msgs/TransformStamped[] transforms"
    # Jazzy's RIHS01 hash of tf2_msgs/msg/TFMessage (rosbag2 writes it into metadata.yaml).
    assert source.type_hash(TF_MESSAGE) == "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"


def test_tf_message_rejects_short_data():
    decode = TypeResolver().decoder(TF_MESSAGE)
    data = serialize(random_tf(np.random.default_rng(1), 2))
    with pytest.raises(RuntimeError, match="failed to deserialize"):
        decode(data[:-9])
    with pytest.raises(RuntimeError, match="failed to deserialize"):
        decode(b"\x07\x07\x00\x00\x00\x00\x00\x00")
