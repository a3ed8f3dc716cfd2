"""The generated Baxter teleoperation session: IK reaches the bowl, limits, smoothness, bowl, determinism."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from coco_ros.bag import BagReader
from coco_ros.baxter.joints import BAXTER_JOINT_NAMES
from coco_ros.baxter.session import generate_session, main

URDF = "package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    folder = tmp_path_factory.mktemp("baxter") / "session"
    info = generate_session(folder, seed=0, duration=12.0)
    return info, BagReader(folder)


@pytest.fixture(scope="module")
def robot():
    from coco_core.transforms.urdf import UrdfModel

    return UrdfModel.load(URDF)


def stamp(message) -> float:
    return message.header.stamp.sec + message.header.stamp.nanosec * 1e-9


def position(pose) -> np.ndarray:
    return np.array([pose.position.x, pose.position.y, pose.position.z])


def gripper_at(robot, joint_state) -> np.ndarray:
    robot.set_positions(dict(zip(joint_state.name, joint_state.position)))
    return robot.placement("left_gripper")[:3, 3]


def test_topics_and_rates(session):
    info, reader = session
    counts = {topic: sum(1 for _ in reader.messages(topic)) for topic in reader.topics}
    assert counts["/robot/joint_states"] == 1201
    assert counts["/bowl/pose"] == 361
    assert counts["/operator/wrist_pose"] == 721
    assert counts["/head_camera/camera_info"] == 121
    assert counts["/target/pose"] >= 1
    assert reader.topics["/target/pose"].latched
    assert "/target/pose" in reader.latched_topics()
    info_message = next(iter(reader.messages("/head_camera/camera_info"))).message
    assert (info_message.width, info_message.height) == (640, 480)
    wrist = next(iter(reader.messages("/operator/wrist_pose"))).message
    assert wrist.header.frame_id == "operator_base"
    states = [m.message for m in reader.messages("/robot/joint_states")]
    assert all(tuple(s.name) == BAXTER_JOINT_NAMES for s in states)
    times = [stamp(s) for s in states]
    assert np.allclose(np.diff(times), 0.01, atol=1e-6)


def test_joints_within_limits_and_smooth(session, robot):
    _, reader = session
    limits = robot.limits
    states = [m.message for m in reader.messages("/robot/joint_states")]
    positions = np.array([s.position for s in states])
    for column, name in enumerate(BAXTER_JOINT_NAMES):
        if name in limits:
            lower, upper = limits[name]
            assert np.all(positions[:, column] >= lower - 1e-9), name
            assert np.all(positions[:, column] <= upper + 1e-9), name
    steps = np.abs(np.diff(positions, axis=0))
    assert steps.max() < 0.03, "a joint moved more than 0.03 rad in 10 ms"
    assert np.abs(np.diff(positions, n=2, axis=0)).max() < 0.005  # no velocity jumps
    moved = np.abs(positions[-1] - positions[0]).max()
    assert moved > 0.2


def test_ik_reaches_bowl_and_bowl_follows_to_target(session, robot):
    info, reader = session
    states = [m.message for m in reader.messages("/robot/joint_states")]
    bowls = [m.message for m in reader.messages("/bowl/pose")]
    assert all(b.header.frame_id == "base" for b in bowls)
    finger = BAXTER_JOINT_NAMES.index("l_gripper_l_finger_joint")
    closing = next(i for i, s in enumerate(states) if s.position[finger] < states[0].position[finger] - 1e-6)
    bowl_start = position(bowls[0].pose)
    assert np.allclose(bowl_start, info.bowl[:3, 3])
    # At the grasp the gripper is at the bowl (forward kinematics of the recorded joint states).
    assert np.linalg.norm(gripper_at(robot, states[closing]) - bowl_start) < 0.01
    start = stamp(states[0])
    by_time = {round(stamp(s) - start, 2): s for s in states}
    carried = [b for b in bowls if info.grasp_time + 0.05 < stamp(b) - start < info.release_time - 0.05]
    assert len(carried) > 30
    travelled = 0.0
    for bowl in carried:
        state = by_time.get(round(stamp(bowl) - start, 2))
        if state is None:
            continue
        assert np.linalg.norm(gripper_at(robot, state) - position(bowl.pose)) < 0.01
        travelled = max(travelled, np.linalg.norm(position(bowl.pose) - bowl_start))
    assert travelled > 0.1
    target = next(iter(reader.messages("/target/pose"))).message
    assert np.linalg.norm(position(bowls[-1].pose) - position(target.pose)) < 0.01
    assert np.linalg.norm(position(target.pose) - bowl_start) > 0.1


def messages(folder):
    return [(m.topic, m.log_time, m.data) for m in BagReader(folder).messages()]


def test_deterministic_with_a_seed(tmp_path):
    generate_session(tmp_path / "a", seed=3, duration=8.0)
    generate_session(tmp_path / "b", seed=3, duration=8.0)
    generate_session(tmp_path / "c", seed=4, duration=8.0)
    a, b, c = messages(tmp_path / "a"), messages(tmp_path / "b"), messages(tmp_path / "c")
    assert a == b
    assert [m[:2] for m in a] == [m[:2] for m in c]
    bowl_a = [m[2] for m in a if m[0] == "/bowl/pose"]
    bowl_c = [m[2] for m in c if m[0] == "/bowl/pose"]
    assert bowl_a != bowl_c


def test_cli(tmp_path):
    assert main([str(tmp_path / "s"), "--seed", "1", "--duration", "7", "--quiet"]) == 0
    assert BagReader(tmp_path / "s").message_count > 700
    assert main([str(tmp_path / "t"), "--duration", "1", "--quiet"]) == 1


def test_rosbags_reads_every_topic(session):
    from rosbags.highlevel import AnyReader

    info, reader = session
    with AnyReader([info.folder]) as theirs:
        decoded = [theirs.deserialize(raw, c.msgtype) for c, _, raw in theirs.messages()]
    assert len(decoded) == reader.message_count
