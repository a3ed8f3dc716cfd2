"""Baxter joint_recorder CSV -> bag: the real shake_hand.dat recording, naming, gripper mapping, errors."""

from __future__ import annotations

import csv

import pytest
from conftest import SHARED_DATA

from coco_ros.bag import BagReader
from coco_ros.baxter.importer import import_recording, main, read_recording
from coco_ros.baxter.joints import (
    BAXTER_JOINT_NAMES,
    FINGER_UPPER,
    ROBOT_JOINT_NAMES,
    gripper_to_fingers,
    parse_joint_state_dump,
)

from coco_core.errors import RecordingError

BAXTER = SHARED_DATA / "baxter"
START = 1_700_000_000 * 10**9


@pytest.fixture
def shake_hand():
    path = BAXTER / "shake_hand.dat"
    if not path.is_file():
        pytest.skip(f"shared test data absent: expected the real joint_recorder file {path}")
    return path


def test_real_order_matches_a_real_joint_states_message():
    path = BAXTER / "hand_calib_pos.dat"
    if not path.is_file():
        pytest.skip(f"shared test data absent: expected the real /robot/joint_states dump {path}")
    assert tuple(parse_joint_state_dump(path)["name"]) == ROBOT_JOINT_NAMES
    assert BAXTER_JOINT_NAMES[: len(ROBOT_JOINT_NAMES)] == ROBOT_JOINT_NAMES


def test_gripper_mapping_follows_the_urdf():
    from coco_core.transforms.urdf import UrdfModel

    model = UrdfModel.load("package://example-robot-data/robots/baxter_description/urdf/baxter.urdf")
    lower, upper = model.limits["l_gripper_l_finger_joint"]
    assert (lower, upper) == (0.0, FINGER_UPPER)
    assert model.mimic_joints["l_gripper_r_finger_joint"] == ("l_gripper_l_finger_joint", -1.0, 0.0)
    assert gripper_to_fingers(0) == (0.0, -0.0)
    assert gripper_to_fingers(100) == (upper, -upper)
    assert gripper_to_fingers(50)[0] == pytest.approx(upper / 2)


def test_shake_hand_to_bag(shake_hand, tmp_path):
    with open(shake_hand, newline="") as stream:
        rows = list(csv.DictReader(stream))
    folder = tmp_path / "shake"
    assert import_recording(shake_hand, folder, start_stamp=START) == len(rows) == 813

    reader = BagReader(folder)
    assert reader.message_count == 813
    messages = [m.message for m in reader.messages("/robot/joint_states")]
    assert len(messages) == 813
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in messages]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
    assert stamps[0] == START + round(float(rows[0]["time"]) * 1e9)
    for message in messages:
        assert tuple(message.name) == BAXTER_JOINT_NAMES
        assert len(message.position) == len(message.velocity) == len(BAXTER_JOINT_NAMES)
    row, message = rows[400], messages[400]
    values = dict(zip(message.name, message.position))
    for column in row:
        if column in values:
            assert values[column] == float(row[column])
    assert values["head_nod"] == values["torso_t0"] == values["head_pan"] == 0.0
    for message, row in zip(messages, rows):
        values = dict(zip(message.name, message.position))
        assert 0.0 <= values["l_gripper_l_finger_joint"] <= FINGER_UPPER
        assert values["l_gripper_r_finger_joint"] == -values["l_gripper_l_finger_joint"]
        assert values["l_gripper_l_finger_joint"] == pytest.approx(float(row["left_gripper"]) / 100 * FINGER_UPPER)
        assert values["r_gripper_l_finger_joint"] == pytest.approx(float(row["right_gripper"]) / 100 * FINGER_UPPER)


def test_bag_readable_by_rosbags(shake_hand, tmp_path):
    from rosbags.highlevel import AnyReader

    folder = tmp_path / "shake"
    import_recording(shake_hand, folder, start_stamp=START)
    with AnyReader([folder]) as reader:
        connections = [c for c in reader.connections if c.topic == "/robot/joint_states"]
        assert connections and connections[0].msgtype == "sensor_msgs/msg/JointState"
        decoded = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(connections=connections)]
    assert len(decoded) == 813
    assert tuple(decoded[0].name) == BAXTER_JOINT_NAMES


def test_cli(shake_hand, tmp_path, capsys):
    assert main([str(shake_hand), str(tmp_path / "out"), "--start", "1700000000", "--quiet"]) == 0
    assert BagReader(tmp_path / "out").message_count == 813


@pytest.mark.parametrize(
    "text, line, expected",
    [
        ("time,left_s0,left_s1\n0.0,0.1,0.2\n0.01,0.1\n", 3, "expected 3 comma-separated values"),
        ("time,left_s0,left_s1\n0.0,0.1,0.2\n0.01,0.1,abc\n", 3, "column 'left_s1': expected a number, got 'abc'"),
        ("time,left_s0,left_elbow\n0.0,0.1,0.2\n", 1, "unknown column(s) 'left_elbow'"),
        ("left_s0,left_s1\n0.1,0.2\n", 1, "starting with 'time'"),
        ("time,left_s0\n0.5,0.1\n0.4,0.1\n", 3, "expected increasing seconds"),
        ("time,left_gripper\n0.0,250\n", 2, "expected percent 0..100"),
        ("time,left_s0\n", 2, "no data rows"),
    ],
)
def test_malformed_csv_names_file_and_line(tmp_path, text, line, expected):
    path = tmp_path / "bad.dat"
    path.write_text(text)
    with pytest.raises(RecordingError) as error:
        read_recording(path)
    assert f"{path}:{line}:" in str(error.value)
    assert expected in str(error.value)
    assert main([str(path), str(tmp_path / "out"), "--quiet"]) == 1


def test_partial_recording_fills_missing_joints_with_zero(tmp_path):
    path = tmp_path / "left.dat"
    path.write_text("time,left_s0,left_gripper\n0.0,0.5,0\n0.01,0.6,100\n")
    recording = read_recording(path)
    index = BAXTER_JOINT_NAMES.index
    assert recording.positions[1][index("left_s0")] == 0.6
    assert recording.positions[1][index("right_s0")] == 0.0
    assert recording.positions[0][index("l_gripper_l_finger_joint")] == 0.0
