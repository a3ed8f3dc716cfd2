"""The main job under the ROS launcher shows what RViz and Foxglove need (config/baxter_teleop_replay.xml,
issue 37): the graph on /tf with the gripper moving, the URDF on /robot_description once and latched,
every distance on /distance equal to the CSV, its colour, the joint states; coco-launch runs the same
file without any of it.

The launcher runs as the installed script (``--managed``: this test's subscriptions are matched
before the replay starts, so that every value can be compared); the other side is a real rclpy node
of this test, on its own DDS domain (localhost only)."""

from __future__ import annotations

import csv
import subprocess
import threading
import time
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import pytest

from conftest import ROOT, run_launcher

APP = "config/baxter_teleop_replay.xml"
DOMAIN = "85"
LAUNCHER = ROOT / "install" / "coco_ros" / "lib" / "coco_ros" / "launcher"


@pytest.fixture
def peer(monkeypatch: pytest.MonkeyPatch) -> Iterator[Any]:
    """This test's rclpy node on its own domain, spun by a thread of its own."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    monkeypatch.setenv("ROS_DOMAIN_ID", DOMAIN)
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    context = Context()
    rclpy.init(context=context)
    node = Node("rviz_stand_in", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    yield node
    executor.shutdown()
    spinner.join(5)
    node.destroy_node()
    context.try_shutdown()
    context.destroy()


def wait_for(condition: Callable[[], Any], what: str, seconds: float = 60) -> Any:
    deadline = time.monotonic() + seconds
    while not (result := condition()):
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.02)
    return result


def answer(node: Any, service: type, name: str, request: Any) -> Any:
    client = node.create_client(service, name)
    wait_for(client.service_is_ready, f"the service {name}")
    future = client.call_async(request)
    return wait_for(lambda: future.done() and future.result(), f"an answer from {name}")


def transition(step: int) -> Any:
    """A lifecycle_msgs ChangeState request for the transition ``step``."""
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState

    return ChangeState.Request(transition=Transition(id=step))


def gripper_positions(tf: list[Any], static: list[Any]) -> list[np.ndarray]:
    """The position of left_gripper in base after each /tf message: the URDF's chain composed from
    the newest transform of each link (moving ones on /tf, fixed ones on /tf_static)."""
    from coco_ros.convert.geometry import matrix_of

    links: dict[str, tuple[str, np.ndarray]] = {}
    for message in static:
        for t in message.transforms:
            links[t.child_frame_id] = (t.header.frame_id, matrix_of(t.transform.translation, t.transform.rotation))
    positions = []
    for message in tf:
        for t in message.transforms:
            links[t.child_frame_id] = (t.header.frame_id, matrix_of(t.transform.translation, t.transform.rotation))
        pose, frame = np.eye(4), "left_gripper"
        while frame != "base" and frame in links:
            parent, matrix = links[frame]
            pose, frame = matrix @ pose, parent
        if frame == "base":
            positions.append(pose[:3, 3])
    return positions


def test_the_main_job_publishes_tf_the_urdf_the_distance_and_its_colour(session, tmp_path: Path, peer: Any) -> None:
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState
    from rclpy.event_handler import SubscriptionEventCallbacks
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from sensor_msgs.msg import JointState
    from std_msgs.msg import ColorRGBA, Float64, String
    from tf2_msgs.msg import TFMessage

    if not LAUNCHER.exists():
        pytest.fail(f"{LAUNCHER} is missing: build the workspace first (scripts/setup.sh does)")
    folder, info = session
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    tf: list[Any] = []
    static: list[Any] = []
    distances: list[float] = []
    colors: list[Any] = []
    joints: list[Any] = []
    matched: set[str] = set()

    def subscribe(kind: type, topic: str, into: list[Any], qos: Any, field: str | None = None) -> None:
        events = SubscriptionEventCallbacks(matched=lambda status: matched.add(topic) if status.current_count else None)
        peer.create_subscription(kind, topic, lambda msg: into.append(getattr(msg, field) if field else msg), qos,
                                 event_callbacks=events)

    subscribe(TFMessage, "/tf", tf, QoSProfile(depth=100))
    subscribe(TFMessage, "/tf_static", static, latched)
    subscribe(Float64, "/distance", distances, QoSProfile(depth=1000), "data")
    subscribe(ColorRGBA, "/distance_color", colors, QoSProfile(depth=1000))
    subscribe(JointState, "/joint_states", joints, QoSProfile(depth=1000))
    output = tmp_path / "teleop"
    process = subprocess.Popen(
        [str(LAUNCHER), APP, f"bag:={folder}", f"output:={output}", "display:=false", "rate:=4",
         f"time_origin:={info.start_ns / 1e9}", "--managed", "--ros-args", "-r", "__node:=teleop_under_test"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        change = "/teleop_under_test/change_state"
        wait_for(lambda: {"/distance", "/distance_color", "/joint_states"} <= matched, "the mirrors to match")
        assert answer(peer, ChangeState, change, transition(Transition.TRANSITION_CONFIGURE)).success
        descriptions: list[str] = []  # a viewer that starts after the URDF was published still gets it
        peer.create_subscription(String, "/robot_description", lambda msg: descriptions.append(msg.data), latched)
        assert answer(peer, ChangeState, change, transition(Transition.TRANSITION_ACTIVATE)).success
        out, _ = process.communicate(timeout=120)
    finally:
        process.kill()
    assert process.returncode == 0, out
    rows = list(csv.DictReader((output / "distance.csv").open(newline="")))
    wait_for(lambda: len(distances) >= len(rows), "every distance")
    assert [f"{value:.6f}" for value in distances] == [row["distance"] for row in rows]
    assert len(colors) == len(rows) and [(c.r, c.g, c.b) for c in colors[:3]] == [
        (float(row["r"]), float(row["g"]), float(row["b"])) for row in rows[:3]]
    assert joints and "left_s0" in joints[0].name
    assert len(descriptions) == 1 and '<robot name="baxter"' in descriptions[0]
    assert static and any(t.child_frame_id == "left_gripper" for m in static for t in m.transforms)
    positions = gripper_positions(tf, static)
    assert len(positions) > 20, len(positions)
    travel = max(np.linalg.norm(p - positions[0]) for p in positions)
    assert travel > 0.2, f"the gripper moved {travel:.3f} m on /tf"


def test_coco_launch_runs_the_same_file_without_ros(session, coco_launch: Path) -> None:
    folder, _ = session
    result = run_launcher(coco_launch, APP, f"bag:={folder}", "display:=false", "--check")
    assert result.returncode == 0, result.stderr
    assert "ros_tf" not in result.stdout and "robot_description" not in result.stdout, result.stdout


def test_a_recording_of_the_mirrored_joint_states_replays_into_the_same_application_with_the_same_outputs(
        session, tmp_path: Path, peer: Any) -> None:
    """``ros2 bag record /joint_states`` (here: a subscription of this test writing the CDR bytes with
    the project's BagWriter, as rosbag2 does), then ``coco-replay`` of that recording into the same
    application taking its inputs from the topics (``source:=topics``): every distance, its time and
    its colour as the run on the original bag wrote them. The bowl is fixed (``fixed_bowl:=true``):
    one input topic, so the order of the inputs is the recording's."""
    import os
    import signal

    from coco_ros.bag import BagWriter
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState
    from rclpy.event_handler import SubscriptionEventCallbacks
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    folder, info = session
    common = ["display:=false", "fixed_bowl:=true", f"time_origin:={info.start_ns / 1e9}"]
    recording, first, second = tmp_path / "recording", tmp_path / "first", tmp_path / "second"
    matched: list[int] = []
    with BagWriter(recording) as writer:
        recorder = peer.create_subscription(
            JointState, "/joint_states", lambda data: writer.write("/joint_states", data, time.time_ns(),
                                                                   "sensor_msgs/msg/JointState"),
            QoSProfile(depth=1000), raw=True,
            event_callbacks=SubscriptionEventCallbacks(matched=lambda status: matched.append(status.current_count)))
        process = subprocess.Popen([str(LAUNCHER), APP, f"bag:={folder}", f"output:={first}", "rate:=4", *common,
                                    "--managed", "--ros-args", "-r", "__node:=recorded_under_test"],
                                   cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            wait_for(lambda: matched and matched[-1], "the recorder to match /joint_states")
            for step in (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE):
                assert answer(peer, ChangeState, "/recorded_under_test/change_state", transition(step)).success
            out, _ = process.communicate(timeout=120)
        finally:
            process.kill()
        assert process.returncode == 0, out
        peer.destroy_subscription(recorder)
    rows = list(csv.DictReader((first / "distance.csv").open(newline="")))
    assert len(rows) > 200

    distances: list[float] = []
    seen: list[int] = []
    peer.create_subscription(Float64, "/distance", lambda msg: distances.append(msg.data), QoSProfile(depth=1000),
                             event_callbacks=SubscriptionEventCallbacks(matched=lambda s: seen.append(s.current_count)))
    process = subprocess.Popen([str(LAUNCHER), APP, "source:=topics", f"output:={second}", *common],
                               cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        # The application subscribed before the replay starts (coco-replay waits 10 s at most, and a
        # loaded machine may take longer to build the application).
        wait_for(lambda: peer.count_subscribers("/joint_states") >= 1 and seen and seen[-1],
                 "the application's /joint_states subscription and /distance publisher")
        replay = subprocess.run([str(LAUNCHER.with_name("coco-replay")), str(recording), "--rate", "4",
                                 "--wait-subscribers", "1", "--no-progress"],
                                cwd=ROOT, capture_output=True, text=True, timeout=120,
                                env={**os.environ, "ROS_DOMAIN_ID": DOMAIN})
        assert replay.returncode == 0, replay.stderr
        wait_for(lambda: len(distances) >= len(rows), "every distance of the replayed recording")
        process.send_signal(signal.SIGINT)
        out, _ = process.communicate(timeout=60)
    finally:
        process.kill()
    assert process.returncode == 0, out
    replayed = list(csv.DictReader((second / "distance.csv").open(newline="")))
    columns = ("time", "distance", "r", "g", "b")
    assert [[row[c] for c in columns] for row in replayed] == [[row[c] for c in columns] for row in rows]
