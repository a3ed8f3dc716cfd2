"""BagReplay and BagRecorder in a real coco_core Application, fed through ports."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from coco_core.activity import PeriodicActivity
from coco_core.application import Application
from coco_core.component import Component
from coco_core.policy import BufferPolicy, ConnectionPolicy
from coco_core.ports import InputPort
from coco_core.transforms.samples import JointSample
from tf2_msgs.msg import TFMessage

from coco_ros.bag import BagReader, BagWriter
from coco_ros.replay.component import BagReplay, port_name_for
from coco_ros.replay.recorder import BagRecorder

T0 = 1_700_000_000_000_000_000
MS = 1_000_000
BUFFER = ConnectionPolicy(BufferPolicy.BUFFER, size=1000)


class Sink(Component):
    values = InputPort(object)

    def init(self) -> None:
        self.got: list = []

    def on_update(self) -> None:
        self.got.extend(self.values.read_all())


@pytest.fixture(scope="module")
def joints_bag(tmp_path_factory) -> Path:
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import TransformStamped
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Header

    folder = tmp_path_factory.mktemp("replay_component") / "joints"
    with BagWriter(folder) as writer:
        writer.write("/tf_static", TFMessage(transforms=[TransformStamped(child_frame_id="tool")]), T0)
        for i in range(100):
            msg = JointState(header=Header(stamp=Time(sec=1_700_000_000, nanosec=i * MS)),
                             name=["a", "b"], position=[i * 0.01, -i * 0.02], velocity=[0.5, float(i)], effort=[1.0, -1.0])
            writer.write("/robot/joint_states", msg, T0 + (i + 1) * MS)
    return folder


def run(app: Application, timeout: float = 10.0) -> None:
    app.run(duration=timeout)
    assert app.stop_reason.endswith("replayed"), app.stop_reason


def test_port_names():
    assert port_name_for("/robot/joint_states") == "robot_joint_states"
    assert port_name_for("/tf_static") == "tf_static"


def test_joint_states_arrive_in_order_as_joint_samples(joints_bag):
    app = Application("replay")
    replay = app.add(BagReplay("replay", bag=joints_bag, rate=0, stop_at_end=True))
    sink = app.add(Sink("sink"))
    assert set(replay.outputs) == {"clock", "tf_static", "robot_joint_states"}
    assert replay.outputs["robot_joint_states"].type is JointSample
    app.connect("replay.robot_joint_states", "sink.values", BUFFER)
    activity = PeriodicActivity("loop", 0.002)
    app.schedule(replay, activity)
    app.schedule(sink, activity)
    run(app)
    assert len(sink.got) == 100
    assert all(isinstance(v, JointSample) for v in sink.got)
    np.testing.assert_allclose([v.positions[0] for v in sink.got], [i * 0.01 for i in range(100)])
    assert sink.got[0].names == ("a", "b")


def test_tf_static_becomes_transform_samples_after_offset(joints_bag):
    app = Application("replay_tf")
    replay = app.add(BagReplay("replay", bag=joints_bag, rate=0, start_offset=0.05, stop_at_end=True,
                               ports=["/tf_static=static"], topics=["/tf_static"]))
    sink = app.add(Sink("sink"))
    app.connect("replay.static", "sink.values", BUFFER)
    activity = PeriodicActivity("loop", 0.002)
    app.schedule(replay, activity)
    app.schedule(sink, activity)
    run(app)
    assert len(sink.got) == 1 and len(sink.got[0]) == 1
    assert "tool" in repr(sink.got[0][0])


def test_talker_string_into_a_port(talker_bag):
    app = Application("talker")
    replay = app.add(BagReplay("replay", bag=talker_bag, rate=0, topics=["/topic"], remap=["/topic:=/chatter"],
                               stop_at_end=True))
    sink = app.add(Sink("sink"))
    assert set(replay.outputs) == {"clock", "chatter"}
    app.connect("replay.chatter", "sink.values", BUFFER)
    activity = PeriodicActivity("loop", 0.002)
    app.schedule(replay, activity)
    app.schedule(sink, activity)
    run(app)
    assert [m.data for m in sink.got] == [f"Hello World: {i}" for i in range(1, 11)] or len(sink.got) == 10
    assert all(type(m).__name__ == "String" for m in sink.got)


def test_pause_step_operations(joints_bag):
    app = Application("ops")
    replay = app.add(BagReplay("replay", bag=joints_bag, rate=1.0, topics=["/robot/joint_states"]))
    sink = app.add(Sink("sink"))
    app.connect("replay.robot_joint_states", "sink.values", BUFFER)
    activity = PeriodicActivity("loop", 0.002)
    app.schedule(replay, activity)
    app.schedule(sink, activity)
    app.start()
    try:
        replay.call("pause").result(2)
        time.sleep(0.05)
        before = len(sink.got)
        time.sleep(0.1)
        assert len(sink.got) == before  # paused: nothing flows
        replay.call("step", 2).result(2)
        deadline = time.monotonic() + 2
        while len(sink.got) < before + 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.05)
        assert len(sink.got) == before + 2
        now, end = replay.call("progress").result(2)
        assert 0 <= now <= end == pytest.approx(0.1)
    finally:
        app.stop()


@pytest.mark.parametrize("stamped", [False, True], ids=["plain", "stamped"])
def test_recorder_round_trip_read_back_with_rosbags(joints_bag, tmp_path, stamped):
    """Stamped values (the emission stamp travels for the latency) are recorded as their values."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    out = tmp_path / "recorded"
    app = Application("record")
    app.add(BagReplay("replay", bag=joints_bag, rate=0, stop_at_end=True, topics=["/robot/joint_states"],
                      max_per_update=10, stamped=stamped))
    app.add(BagRecorder("recorder", folder=out, topics=["joints=/joint_states:sensor_msgs/msg/JointState"],
                        time="stamp"))
    app.connect("replay.robot_joint_states", "recorder.joints", BUFFER)
    app.schedule("replay", PeriodicActivity("replay_loop", 0.002))
    app.schedule("recorder", PeriodicActivity("record_loop", 0.02))
    run(app)
    assert (out / "metadata.yaml").is_file()
    with BagReader(joints_bag) as reader:
        original = [m.message for m in reader.messages(["/robot/joint_states"])]
    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(out) as reader:
        assert reader.message_count == 100
        back = [(t, store.deserialize_cdr(raw, c.msgtype)) for c, t, raw in reader.messages()]
    for (t, theirs), ours in zip(back, original):
        assert list(theirs.name) == list(ours.name)
        np.testing.assert_array_equal(theirs.position, np.asarray(ours.position))
        np.testing.assert_array_equal(theirs.velocity, np.asarray(ours.velocity))
        np.testing.assert_array_equal(theirs.effort, np.asarray(ours.effort))
        assert (theirs.header.stamp.sec, theirs.header.stamp.nanosec) == (ours.header.stamp.sec,
                                                                          ours.header.stamp.nanosec)
        assert t == ours.header.stamp.sec * 10**9 + ours.header.stamp.nanosec


def test_damaged_bag_replays_what_is_readable(joints_bag, tmp_path, caplog):
    with BagReader(joints_bag) as reader, BagWriter(tmp_path / "small", chunk_size=1024) as writer:
        for m in reader.messages(["/robot/joint_states"]):
            writer.write(m.topic, m.message, m.log_time)
    data = (tmp_path / "small" / "small_0.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    app = Application("damaged")
    app.add(BagReplay("replay", bag=cut, rate=0, stop_at_end=True, topics=["/robot/joint_states"]))
    sink = app.add(Sink("sink"))
    app.connect("replay.robot_joint_states", "sink.values", BUFFER)
    activity = PeriodicActivity("loop", 0.002)
    app.schedule("replay", activity)
    app.schedule(sink, activity)
    with caplog.at_level("ERROR", logger="coco.replay"):
        run(app)
    errors = [r.getMessage() for r in caplog.records if "damaged" in r.getMessage()]
    assert len(errors) == 1 and "cut.mcap at byte" in errors[0]
    assert 0 < len(sink.got) < 100
    np.testing.assert_allclose([v.positions[0] for v in sink.got], [i * 0.01 for i in range(len(sink.got))])


@pytest.fixture(scope="module")
def poses_bag(tmp_path_factory) -> Path:
    """20 bowl poses in ``base`` (x = 0.5 + i cm) and joint states, 10 ms apart."""
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Header

    folder = tmp_path_factory.mktemp("replay_component") / "poses"
    with BagWriter(folder) as writer:
        for i in range(20):
            header = Header(stamp=Time(sec=1_700_000_000, nanosec=i * 10 * MS), frame_id="base")
            pose = PoseStamped(header=header)
            pose.pose.position.x, pose.pose.orientation.w = 0.5 + 0.01 * i, 1.0
            writer.write("/bowl/pose", pose, T0 + i * 10 * MS)
            writer.write("/joints", JointState(header=header, name=["a"], position=[0.1 * i]), T0 + i * 10 * MS + 1)
    return folder


def test_converter_options_make_the_pose_an_edge_of_the_graph_with_emission_stamps(poses_bag):
    """``options`` gives PoseStamped its child frame, so a TransformationInterface writes it as the edge
    base -> bowl; with ``stamped`` the replay's emission stamp travels through the interface's lookups."""
    from coco_core.activity import TriggeredActivity
    from coco_core.stamps import Stamped
    from coco_core.transforms.interface import TransformationInterface
    from coco_core.transforms.samples import FramePose

    app = Application("bowl")
    replay = app.add(BagReplay("replay", bag=poses_bag, rate=0, topics=["/bowl/pose", "/joints"],
                               options=["/bowl/pose;child_frame=bowl"], stamped=True))
    tf = app.add(TransformationInterface("tf", publish=["bowl=base:bowl"], stamped=True), TriggeredActivity("tf"))
    sink = app.add(Sink("sink"))
    emitted = app.add(Sink("emitted"))
    assert replay.outputs["bowl_pose"].type is Stamped and tf.outputs["bowl"].type is Stamped
    app.connect("replay.bowl_pose", "tf.transform", BUFFER)
    app.connect("replay.joints", "emitted.values", BUFFER)
    app.connect("tf.bowl", "sink.values", BUFFER)
    activity = PeriodicActivity("loop", 0.002)
    app.schedule(replay, activity)
    app.schedule(sink, activity)
    app.schedule(emitted, activity)
    app.start()
    try:
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and (len(sink.got) < 20 or len(emitted.got) < 20):
            time.sleep(0.01)
    finally:
        app.stop()
    np.testing.assert_allclose(app.transforms.lookup("base", "bowl")[:3, 3], [0.69, 0.0, 0.0])
    assert len(sink.got) == 20
    assert all(isinstance(s, Stamped) and isinstance(s.value, FramePose) for s in sink.got)
    assert [(s.value.target, s.value.source) for s in sink.got[:1]] == [("base", "bowl")]
    np.testing.assert_allclose([s.value.transform[0, 3] for s in sink.got], [0.5 + 0.01 * i for i in range(20)])
    # The pose's stamp is the message's ROS stamp; the Stamp is the replay's, taken at emission.
    assert [s.value.stamp for s in sink.got] == pytest.approx([1_700_000_000 + 0.01 * i for i in range(20)])
    assert {s.stamp.source for s in sink.got} == {"/bowl/pose"}
    # One sequence over every topic the replay emits, in emission order.
    seqs = sorted([s.stamp.seq for s in sink.got] + [s.stamp.seq for s in emitted.got])
    assert seqs == list(range(1, 41))
    times = [s.stamp.time for s in sink.got]
    assert times == sorted(times)
    assert all(isinstance(s.value, JointSample) for s in emitted.got)


@pytest.mark.parametrize("options, output, expected", [
    (["/other;child_frame=x"], "coco", r"options name topic\(s\) /other that are not replayed \(replayed: /bowl/pose\)"),
    (["/bowl/pose;frame=x"], "coco", r"options of /bowl/pose \(geometry_msgs/msg/PoseStamped\):.*no option\(s\) frame; "
                                     r"its options: child_frame"),
    (["/bowl/pose;child_frame"], "coco", r"options item '/bowl/pose;child_frame': option 'child_frame' is not key=value"),
    (["bowl;child_frame=x"], "coco", r"expected '/topic;key=value\[;key=value\]'"),
    (["/bowl/pose;child_frame=x"], "bag", r"converter options need output=coco \(output is bag\)"),
])
def test_bad_options_name_the_item_and_what_is_expected(poses_bag, options, output, expected):
    from coco_core.errors import CocoError

    with pytest.raises(CocoError, match=expected):
        Application("bad").add(BagReplay("replay", bag=poses_bag, topics=["/bowl/pose"], options=options, output=output))


def test_replay_in_a_triggered_activity_starts_by_itself(talker_bag):
    """A triggered activity runs only when woken and BagReplay has no inputs: it must wake itself for
    its first update (then each update asks for the next), on the activity's own thread."""
    from coco_core.activity import TriggeredActivity

    app = Application("triggered_replay")
    activity = TriggeredActivity("a")
    replay = app.add(BagReplay("replay", bag=talker_bag, rate=0.0, topics=["/topic"], stop_at_end=True), activity)
    sink = app.add(Sink("sink"), activity)
    app.connect("replay.topic", "sink.values", BUFFER)
    run(app, timeout=5.0)
    assert replay._player.delivered == 10
    assert [m.data for m in sink.got] == [f"Hello, world! {i}" for i in range(10)]


def test_tf_static_from_a_bag_becomes_static_edges_for_timed_lookups(tmp_path):
    """A /tf_static stamped 0 (as static broadcasters send it) and a moving /tf: through BagReplay
    and a TransformationInterface the static transform is a static edge, so a timed lookup through
    it only needs the dynamic edge's history (issue 13: it was a dynamic edge at wall-clock time)."""
    from builtin_interfaces.msg import Time
    from coco_core.activity import TriggeredActivity
    from coco_core.transforms.edges import DynamicEdge, StaticEdge
    from coco_core.transforms.interface import TransformationInterface
    from geometry_msgs.msg import Transform, TransformStamped, Vector3
    from std_msgs.msg import Header

    folder = tmp_path / "tf"
    with BagWriter(folder) as writer:
        static = TransformStamped(header=Header(frame_id="base_link"), child_frame_id="laser",
                                  transform=Transform(translation=Vector3(x=0.2)))
        static.transform.rotation.w = 1.0
        writer.write("/tf_static", TFMessage(transforms=[static]), T0)
        for i in range(20):
            moving = TransformStamped(header=Header(frame_id="odom", stamp=Time(sec=1_700_000_000, nanosec=i * MS)),
                                      child_frame_id="base_link", transform=Transform(translation=Vector3(x=0.01 * i)))
            moving.transform.rotation.w = 1.0
            writer.write("/tf", TFMessage(transforms=[moving]), T0 + (i + 1) * MS)
    app = Application("tf_static")
    app.add(BagReplay("replay", bag=folder, rate=0, stop_at_end=True))
    interface = app.add(TransformationInterface("tf"), TriggeredActivity("tf"))
    app.connect("replay.tf", "tf.transform", BUFFER)
    app.connect("replay.tf_static", "tf.transform", BUFFER)
    app.schedule("replay", PeriodicActivity("loop", 0.002))
    run(app)
    graph = app.transforms
    assert isinstance(graph.edge("base_link", "laser"), StaticEdge)
    assert isinstance(graph.edge("odom", "base_link"), DynamicEdge)
    at = 1_700_000_000 + 0.0105
    np.testing.assert_allclose(graph.lookup("odom", "laser", at)[:3, 3], [0.105 + 0.2, 0.0, 0.0], atol=1e-9)
    assert interface.stats.refused == 0


@pytest.fixture(scope="module")
def malformed_bag(tmp_path_factory) -> Path:
    """30 joint states and 30 bowl poses, 10 ms apart, of which four are malformed: joint state 7 has
    one position fewer than names, pose 12 a zero quaternion, pose 21 a NaN one, pose 25 a NaN
    position (a tracker that lost its target)."""
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Header

    folder = tmp_path_factory.mktemp("replay_component") / "malformed"
    with BagWriter(folder) as writer:
        for i in range(30):
            header = Header(stamp=Time(sec=1_700_000_000, nanosec=i * 10 * MS), frame_id="base")
            positions = [0.1 * i, -0.1 * i][: 1 if i == 7 else 2]
            writer.write("/joints", JointState(header=header, name=["a", "b"], position=positions), T0 + i * 10 * MS)
            pose = PoseStamped(header=header)
            pose.pose.position.x, pose.pose.orientation.w = 0.01 * i, float("nan") if i == 21 else 1.0
            if i == 12:
                pose.pose.orientation.w = 0.0
            if i == 25:
                pose.pose.position.y = float("nan")
            writer.write("/bowl/pose", pose, T0 + i * 10 * MS + 1)
    return folder


@pytest.mark.parametrize("rate", [0.0, 20.0, 1.0], ids=["as-fast-as-possible", "fast", "real-time"])
def test_a_malformed_message_is_refused_alone_counted_and_reported(malformed_bag, rate):
    """A message the converter refuses costs only itself, at every rate: the rest of its batch is
    delivered (issue 23: one bad JointState lost the whole batch of 256, silently), the profile's refused
    column counts it and the application's damage names it (the launcher then exits with 1)."""
    app = Application("malformed")
    replay = app.add(BagReplay("replay", bag=malformed_bag, rate=rate, stop_at_end=True,
                               options=["/bowl/pose;child_frame=bowl"]))
    joints, poses = app.add(Sink("joints")), app.add(Sink("poses"))
    app.connect("replay.joints", "joints.values", BUFFER)
    app.connect("replay.bowl_pose", "poses.values", BUFFER)
    activity = PeriodicActivity("loop", 0.002)
    for component in (replay, joints, poses):
        app.schedule(component, activity)
    run(app)
    assert [round(v.positions[0] * 10) for v in joints.got] == [i for i in range(30) if i != 7]
    assert [round(v.transform[0, 3] * 100) for v in poses.got] == [i for i in range(30) if i not in (12, 21, 25)]
    assert replay.stats.refused == 4 and replay.refused_messages == 4
    assert len(app.damage) == 4, app.damage
    assert "/joints message 0.070 s into the bag" in app.damage[0] and "2 names but 1 position" in app.damage[0]
    assert "/bowl/pose message 0.120 s into the bag" in app.damage[1] and "zero" in app.damage[1]
    assert "/bowl/pose message 0.210 s into the bag" in app.damage[2] and "nan" in app.damage[2]
    assert "/bowl/pose message 0.250 s into the bag" in app.damage[3] and "not finite" in app.damage[3]
    assert all(entry.startswith(f"replay: {malformed_bag}:") for entry in app.damage)
