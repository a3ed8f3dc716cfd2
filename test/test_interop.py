"""Interoperability with plain ROS 2 nodes over real DDS, between processes.

- The installed ROS launcher runs ``test/data/interop_teleop.xml`` (ROSInterface -> Baxter URDF in
  the transformation graph -> EndEffectorDistance -> ROSInterface), with one activity per stage and
  with the whole pipeline in one activity (``one_activity:=true``); this test's own rclpy node, in
  its own process, publishes joint states and a bowl pose and receives the gripper pose (stamped
  with the joint state it comes from) and the distance (std_msgs/Float64, published from
  EndEffectorDistance's ``Stamped[float]`` by the bridge itself), which it checks against Pinocchio
  forward kinematics computed here from the URDF.
- A generated Baxter session bag is replayed to DDS topics, by the launcher (BagReplay ->
  ROSInterface, ``test/data/interop_replay.xml``) and by the ``coco-replay`` CLI; this test's node
  receives every message, checked in count and content against the bag.

Every test has its own DDS domain (70-72, 81), discovery on localhost only.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from coco_core.interrupt import interrupt
from conftest import ROOT

DATA = ROOT / "test" / "data"
INSTALLED = ROOT / "install" / "coco_ros" / "lib" / "coco_ros"
LAUNCHER = INSTALLED / "launcher"
COCO_REPLAY = INSTALLED / "coco-replay"
REPLAYED = ("/robot/joint_states", "/bowl/pose")

pytestmark = pytest.mark.skipif(not LAUNCHER.exists(), reason="workspace not built (source scripts/setup.sh)")


# --- a ROS peer in this process ---------------------------------------------------------------------

class Peer:
    """This test's rclpy node on its own context and domain; ``spin_until`` runs its callbacks."""

    def __init__(self, domain: str) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        self.domain = domain
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node("interop_peer", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_until(self, done: Callable[[], bool], timeout_s: float, between: Callable[[], None] | None = None,
                   process: subprocess.Popen | None = None) -> bool:
        """Spin until ``done()``, calling ``between()`` every 50 ms; False on timeout or if ``process`` exited."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if done():
                return True
            if process is not None and process.poll() is not None:
                return done()
            if between is not None:
                between()
            self.executor.spin_once(timeout_sec=0.05)
        return done()

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()


@pytest.fixture
def peer(request, monkeypatch: pytest.MonkeyPatch) -> Iterator[Peer]:
    """A :class:`Peer` on the domain given by ``@pytest.mark.parametrize('peer', [...], indirect=True)``."""
    domain = str(request.param)
    monkeypatch.setenv("ROS_DOMAIN_ID", domain)  # read by rclpy.init
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    ros_peer = Peer(domain)
    yield ros_peer
    ros_peer.close()


def start(domain: str, *command: str | Path) -> subprocess.Popen[str]:
    """Start an installed script in its own process on ``domain``."""
    env = dict(os.environ, ROS_DOMAIN_ID=domain, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, *map(str, command)], cwd=ROOT, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


# --- 1. joint states and a bowl pose in, gripper pose and distance out ------------------------------

class BaxterFk:
    """Forward kinematics of the Baxter URDF with Pinocchio, independent of CoCo's graph."""

    def __init__(self) -> None:
        import pinocchio as pin
        from coco_core.transforms.resources import resolve
        from coco_ros.baxter.ik import BAXTER_URDF

        self.pin = pin
        self.model = pin.buildModelFromUrdf(str(resolve(BAXTER_URDF)))
        self.data = self.model.createData()
        self.base = self.model.getFrameId("base")
        self.gripper = self.model.getFrameId("left_gripper")

    def left_gripper(self, positions: dict[str, float]) -> np.ndarray:
        """``T_base_left_gripper`` (4x4) for joint values by name; joints not given stay at 0."""
        q = self.pin.neutral(self.model)
        for name, value in positions.items():
            if self.model.existJointName(name):
                q[self.model.joints[self.model.getJointId(name)].idx_q] = value
        self.pin.framesForwardKinematics(self.model, self.data, q)
        placement = self.data.oMf[self.base].actInv(self.data.oMf[self.gripper])
        return placement.homogeneous


def pose_matrix(pose: Any) -> np.ndarray:
    """4x4 of a geometry_msgs/Pose."""
    import pinocchio as pin

    o, p = pose.orientation, pose.position
    matrix = np.eye(4)
    matrix[:3, :3] = pin.Quaternion(o.w, o.x, o.y, o.z).normalized().toRotationMatrix()
    matrix[:3, 3] = (p.x, p.y, p.z)
    return matrix


def left_arm(s0: float, s1: float, e0: float, e1: float, w0: float, w1: float, w2: float) -> dict[str, float]:
    return dict(zip(("left_s0", "left_s1", "left_e0", "left_e1", "left_w0", "left_w1", "left_w2"),
                    (s0, s1, e0, e1, w0, w1, w2)))


# Three reachable left-arm postures (inside the URDF limits) and two bowl positions in ``base``.
POSTURES = [left_arm(0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0),          # baxter_interface's neutral
            left_arm(0.4, -0.3, -0.5, 1.2, 0.3, 0.6, -0.8),
            left_arm(-0.3, 0.2, 0.6, 0.4, -0.7, 1.0, 1.5)]
BOWLS = [(0.75, 0.25, -0.15), (0.6, 0.45, -0.05)]


@pytest.mark.parametrize(("peer", "schedule"), [(70, "one_activity:=false"), (81, "one_activity:=true")],
                         indirect=["peer"], ids=["activity_per_stage", "one_activity"])
def test_launcher_computes_the_gripper_pose_and_distance_of_published_joint_states(peer: Peer, schedule: str) -> None:
    from coco_ros.baxter.joints import BAXTER_JOINT_NAMES
    from geometry_msgs.msg import PoseStamped
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    fk = BaxterFk()
    expected_poses = [fk.left_gripper(posture) for posture in POSTURES]
    poses: list[PoseStamped] = []
    distances: list[Float64] = []
    node = peer.node
    node.create_subscription(PoseStamped, "/coco/gripper_pose", poses.append, QoSProfile(depth=200))
    node.create_subscription(Float64, "/coco/distance", distances.append, QoSProfile(depth=200))
    joints_out = node.create_publisher(JointState, "/robot/joint_states", QoSProfile(depth=50))
    bowl_out = node.create_publisher(PoseStamped, "/bowl/pose", QoSProfile(depth=10))

    current = {"posture": 0, "bowl": 0}
    published: dict[tuple[int, int], int] = {}
    """(sec, nanosec) of every joint state published -> its posture."""

    def publish() -> None:
        stamp = node.get_clock().now().to_msg()
        published[(stamp.sec, stamp.nanosec)] = current["posture"]
        posture = POSTURES[current["posture"]]
        msg = JointState(name=list(BAXTER_JOINT_NAMES), position=[posture.get(n, 0.0) for n in BAXTER_JOINT_NAMES])
        msg.header.stamp = stamp
        joints_out.publish(msg)
        bowl = PoseStamped()
        bowl.header.stamp, bowl.header.frame_id = stamp, "base"
        bowl.pose.position.x, bowl.pose.position.y, bowl.pose.position.z = BOWLS[current["bowl"]]
        bowl.pose.orientation.w = 1.0
        bowl_out.publish(bowl)

    def expected_distance() -> float:
        return float(np.linalg.norm(expected_poses[current["posture"]][:3, 3] - np.array(BOWLS[current["bowl"]])))

    def settled() -> bool:
        """The newest outputs are those of the posture and bowl being published."""
        return bool(poses and distances) \
            and np.allclose(pose_matrix(poses[-1].pose), expected_poses[current["posture"]], atol=1e-9) \
            and abs(distances[-1].data - expected_distance()) < 1e-9

    process = start(peer.domain, LAUNCHER, DATA / "interop_teleop.xml", schedule, "--duration", "60", "--profile",
                    "3600")
    reached = []
    try:
        for posture, bowl in [(0, 0), (1, 0), (2, 0), (2, 1)]:
            current.update(posture=posture, bowl=bowl)
            if not peer.spin_until(settled, 30 if not reached else 10, between=publish, process=process):
                break
            reached.append((posture, bowl))
    finally:
        code, output = interrupt(process)

    assert reached == [(0, 0), (1, 0), (2, 0), (2, 1)], \
        f"outputs never matched posture/bowl {current}; last pose {poses[-1:]}, " \
        f"last distance {distances[-1:]}\n{output}"
    assert code == 0 and "(clean)" in output, output
    # Every gripper pose is that of a published posture, stamped with the joint state it was computed
    # from (or the URDF's zero posture, unstamped, if the graph published it before the first joint
    # state); every distance is one of a published posture and bowl.
    zero = fk.left_gripper({})
    for pose in poses:
        assert pose.header.frame_id == "base"
        stamp = (pose.header.stamp.sec, pose.header.stamp.nanosec)
        if stamp == (0, 0):
            np.testing.assert_allclose(pose_matrix(pose.pose), zero, atol=1e-9)
            continue
        assert stamp in published, f"gripper pose stamped {stamp}, not the stamp of a published joint state"
        np.testing.assert_allclose(pose_matrix(pose.pose), expected_poses[published[stamp]], atol=1e-9)
    known = expected_poses + [zero]
    pairs = [float(np.linalg.norm(T[:3, 3] - np.array(b))) for T in known for b in BOWLS]
    for distance in distances:
        assert min(abs(distance.data - d) for d in pairs) < 1e-9, (distance.data, pairs)
    # The bridge profiled each published distance's age (EndEffectorDistance's Stamp -> handed to DDS).
    profiled = re.findall(r"^bridge\s+.*\s([0-9.]+) / ([0-9.]+)\s*$", output, re.M)
    assert profiled and 0 < float(profiled[-1][0]) <= float(profiled[-1][1]), output


# --- 2. a bag replayed to DDS topics ----------------------------------------------------------------

@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    """A 6 s generated Baxter session (the shortest it plans: 600 joint states, 180 bowl poses, ...)."""
    from coco_ros.baxter.session import generate_session

    folder = tmp_path_factory.mktemp("interop") / "session"
    generate_session(folder, duration=6.0)
    return folder


def bag_messages(folder: Path) -> dict[str, list[Any]]:
    """The replayed topics' messages of the bag, in order: (CDR bytes, deserialized message)."""
    from coco_ros.bag import BagReader
    from rclpy.serialization import deserialize_message

    by_topic: dict[str, list[Any]] = {topic: [] for topic in REPLAYED}
    with BagReader(folder) as reader:
        classes = {topic: reader.message_class(topic) for topic in REPLAYED}
        for message in reader.messages(REPLAYED):
            by_topic[message.topic].append((message.data, deserialize_message(message.data, classes[message.topic])))
    return by_topic


def reliable_late_joiner(depth: int) -> Any:
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def assert_same_joint_state(got: Any, want: Any) -> None:
    assert got.header.stamp == want.header.stamp
    assert list(got.name) == list(want.name)
    assert list(got.position) == list(want.position)
    assert list(got.velocity) == list(want.velocity)
    assert list(got.effort) == list(want.effort)


def assert_same_pose(got: Any, want: Any) -> None:
    """Same stamp and frame; the same pose (the quaternion went through a matrix: sign and last bits)."""
    assert got.header.stamp == want.header.stamp and got.header.frame_id == want.header.frame_id
    np.testing.assert_allclose(pose_matrix(got.pose), pose_matrix(want.pose), atol=1e-12)


@pytest.mark.parametrize("peer, output", [(71, "coco"), (73, "bag")], indirect=["peer"])
def test_launcher_replays_a_bag_to_topics_a_ros_node_receives(peer: Peer, session: Path, output: str) -> None:
    """output=coco: through CoCo values and back to messages; output=bag: the recorded CDR passed through."""
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import JointState

    bag = bag_messages(session)
    received: dict[str, list[Any]] = {topic: [] for topic in REPLAYED}
    for topic, cls in zip(REPLAYED, (JointState, PoseStamped)):
        peer.node.create_subscription(cls, topic, received[topic].append, reliable_late_joiner(2000))

    def complete() -> bool:
        return all(len(received[t]) >= len(bag[t]) for t in REPLAYED)

    process = start(peer.domain, LAUNCHER, DATA / "interop_replay.xml", f"bag:={session}", "rate:=2",
                    f"output:={output}", "--duration", "60")
    try:
        peer.spin_until(complete, 30, process=process)
        peer.spin_until(lambda: False, 0.3)  # anything beyond the bag would arrive now
    finally:
        code, output = interrupt(process)

    assert code == 0 and "(clean)" in output, output
    for topic in REPLAYED:
        assert len(received[topic]) == len(bag[topic]), (topic, len(received[topic]), len(bag[topic]), output)
    for got, (_, want) in zip(received["/robot/joint_states"], bag["/robot/joint_states"]):
        assert_same_joint_state(got, want)
    for got, (_, want) in zip(received["/bowl/pose"], bag["/bowl/pose"]):
        assert_same_pose(got, want)


@pytest.mark.parametrize("peer", [72], indirect=True)
def test_coco_replay_publishes_every_message_byte_for_byte(peer: Peer, session: Path) -> None:
    from geometry_msgs.msg import PoseStamped
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    bag = bag_messages(session)
    received: dict[str, list[bytes]] = {topic: [] for topic in REPLAYED}
    for topic, cls in zip(REPLAYED, (JointState, PoseStamped)):
        # raw=True: the serialized bytes as they came over DDS, to compare with the bag's CDR.
        peer.node.create_subscription(cls, topic, received[topic].append,
                                      QoSProfile(depth=2000, reliability=ReliabilityPolicy.RELIABLE), raw=True)

    process = start(peer.domain, COCO_REPLAY, session, "--fast", "--topics", *REPLAYED,
                    "--wait-subscribers", str(len(REPLAYED)), "--depth", "2000", "--no-progress")
    try:
        peer.spin_until(lambda: process.poll() is not None, 30)
        peer.spin_until(lambda: all(len(received[t]) >= len(bag[t]) for t in REPLAYED), 5)
    finally:
        code, output = interrupt(process)

    assert code == 0, output
    total = sum(len(messages) for messages in bag.values())
    assert f"coco-replay: {total} messages published" in output, output
    for topic in REPLAYED:
        assert received[topic] == [data for data, _ in bag[topic]], (topic, len(received[topic]), len(bag[topic]))
