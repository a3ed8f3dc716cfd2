"""A real Baxter recording through the teleop app: the SDK's joint_recorder file shake_hand.dat, imported
with the installed ``baxter-import`` and replayed by config/baxter_teleop_replay.xml with a fixed bowl
(the recording has no bowl topic). Every distance the app writes must be the one that Pinocchio's
forward kinematics of the recorded joint values gives."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT, SHARED_DATA, connection_counters, run_launcher

APP = "config/baxter_teleop_replay.xml"
URDF = "package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"
RECORDING = SHARED_DATA / "baxter" / "shake_hand.dat"
START = 1_700_000_000.0
BOWL = np.array([0.9, -0.65, 0.0])
"""A fixed bowl in ``base`` near the right hand, which shakes hands in this recording (the left arm rests)."""


@pytest.fixture(scope="module")
def imported(tmp_path_factory) -> Path:
    if not RECORDING.is_file():
        pytest.skip(f"shared test data absent: expected {RECORDING} (see shared/data/README.md)")
    script = ROOT / "install" / "coco_ros" / "lib" / "coco_ros" / "baxter-import"
    if not script.exists():
        pytest.fail(f"{script} is missing: build the workspace first (scripts/setup.sh does)")
    folder = tmp_path_factory.mktemp("baxter") / "shake_hand"
    result = run_launcher(script, str(RECORDING), str(folder), "--start", str(START), "--quiet", timeout=120)
    assert result.returncode == 0, result.stderr
    return folder


def test_recording_without_bowl_needs_fixed_bowl(coco_launch: Path, imported: Path, tmp_path: Path) -> None:
    result = run_launcher(coco_launch, APP, f"bag:={imported}", f"output:={tmp_path}", timeout=60)
    assert result.returncode != 0
    assert "no topic '/bowl/pose' in the bag (topics: /robot/joint_states)" in result.stderr, result.stderr


def test_shake_hand_moves_the_gripper_as_recorded(coco_launch: Path, imported: Path, tmp_path: Path) -> None:
    from coco_core.transforms.urdf import UrdfModel

    from coco_ros.baxter.importer import read_recording
    from coco_ros.baxter.joints import BAXTER_JOINT_NAMES

    output = tmp_path / "teleop"
    # The data path: the distances of the recording's joint states. Nothing here looks at the frames
    # (display:=false); the same recording with the view rendering beside the data path is
    # test_at_full_speed_every_joint_state_that_moves_the_gripper_is_one_row[true], and the README's
    # line with the display on runs in test_documented_commands.
    result = run_launcher(coco_launch, APP, f"bag:={imported}", f"output:={output}", "fixed_bowl:=true",
                          f"bowl_xyz:={' '.join(map(str, BOWL))}", "arm:=right", f"time_origin:={START}",
                          "rate:=2", "display:=false", "--profile", "100", "--duration", "60", timeout=120)
    assert result.returncode == 0, result.stderr
    assert "replayed (813 messages)" in result.stderr, result.stderr

    recording = read_recording(RECORDING)
    robot = UrdfModel.load(URDF)
    expected = []
    for positions in recording.positions:
        robot.set_positions(dict(zip(BAXTER_JOINT_NAMES, positions)))
        expected.append(float(np.linalg.norm(robot.placement("right_gripper")[:3, 3] - BOWL)))
    times = np.array(recording.times)

    with (output / "distance.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) > len(recording) // 4, f"{len(rows)} samples for {len(recording)} joint states"
    matched = []
    for row in rows:
        index = int(np.argmin(np.abs(times - float(row["time"]))))
        assert abs(times[index] - float(row["time"])) < 1e-4, row  # each sample is one recorded joint state
        assert float(row["distance"]) == pytest.approx(expected[index], abs=2e-6), (row, expected[index])
        matched.append(index)
    assert matched == sorted(matched) and len(set(matched)) == len(matched)
    # From the start of the recording (the distance takes the newest pose: it may skip some at the
    # start while the activities come up) to its very last row; and the hand really moves in it.
    assert matched[0] < len(recording) // 10 and matched[-1] == len(recording) - 1
    distances = [float(row["distance"]) for row in rows]
    assert max(distances) - min(distances) > 0.1

    summary = json.loads((output / "summary.json").read_text())
    assert summary["samples"] == len(rows)
    assert summary["final_distance"] == pytest.approx(expected[-1], abs=1e-9)
    assert summary["final_bowl_target_distance"] is None  # no target in a recording


@pytest.mark.parametrize("display", ["false", "true"])
def test_at_full_speed_every_joint_state_that_moves_the_gripper_is_one_row(
        coco_launch: Path, imported: Path, tmp_path: Path, display: str) -> None:
    """``rate:=0`` replays the recording far faster than the graph, the distance and the summary take
    it (and, with the display, while the view renders): still one CSV row per joint state that moved
    the right gripper, in order, and nothing dropped on the way to the summary."""
    from coco_ros.baxter.importer import read_recording

    output = tmp_path / "teleop"
    result = run_launcher(coco_launch, APP, f"bag:={imported}", f"output:={output}", "fixed_bowl:=true",
                          f"bowl_xyz:={' '.join(map(str, BOWL))}", "arm:=right", f"time_origin:={START}",
                          "rate:=0", f"display:={display}", "frames_format:=png", "--profile", "100",
                          # the view in the launcher's process, where it competes for the GIL (the
                          # case that lost samples; in a process of its own it cannot)
                          "display_process:=false",
                          "--duration", "120", timeout=180)
    assert result.returncode == 0, result.stderr
    assert "replayed (813 messages)" in result.stderr, result.stderr

    recording = read_recording(RECORDING)
    moved = moved_distances()
    assert 100 < len(moved) <= len(recording)

    with (output / "distance.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == len(moved), f"{len(rows)} rows for {len(moved)} joint states that moved the gripper"
    assert [int(row["seq"]) for row in rows] == list(range(1, len(rows) + 1))
    assert [float(row["distance"]) for row in rows] == pytest.approx(moved, abs=2e-6)
    summary = json.loads((output / "summary.json").read_text())
    assert summary["samples"] == len(moved)
    if display == "false":  # with the display, whether a frame is drawn before this fast replay ends
        assert summary["display_latency_ms"]["frames"] == 0  # is a race: test_baxter_view checks it

    check_nothing_dropped(result.stdout + result.stderr)


def moved_distances() -> list[float]:
    """The gripper-to-bowl distance of every recorded joint state that moves the right gripper (an
    independent forward kinematics of the recording: one CSV row each)."""
    from coco_core.transforms.urdf import UrdfModel

    from coco_ros.baxter.importer import read_recording
    from coco_ros.baxter.joints import BAXTER_JOINT_NAMES

    robot = UrdfModel.load(URDF)
    moved, previous = [], None
    for positions in read_recording(RECORDING).positions:
        robot.set_positions(dict(zip(BAXTER_JOINT_NAMES, positions)))
        gripper = robot.placement("right_gripper").copy()
        if previous is None or not np.array_equal(gripper, previous):
            moved.append(float(np.linalg.norm(gripper[:3, 3] - BOWL)))
        previous = gripper
    return moved


def check_nothing_dropped(profile: str) -> None:
    """The profile's connection table: nothing dropped between the replay and the summary."""
    for connection in ("replay.robot_joint_states -> tf.joints", "tf.gripper -> distance.gripper",
                       "distance.distance -> summary.distance", "distance.color -> summary.color"):
        written, read, dropped = connection_counters(profile, connection)
        assert dropped == 0 and written == read, (connection, written, read, dropped)


LAYOUTS = {
    "coco-launch": ("coco_core", "coco-launch", ()),
    "ros-wait-sets": ("coco_ros", "launcher", ()),
    "ros-executor-1": ("coco_ros", "launcher", ("--executor-threads", "1")),
    "ros-executor-3": ("coco_ros", "launcher", ("--executor-threads", "3")),
    # the view in a <process> of its own: its configuration (an OpenGL context, the URDF's meshes)
    # takes long, and the replay must not begin before it is done
    "ros-view-process": ("coco_ros", "launcher", ("display:=true", "display_process:=true", "frames_format:=png")),
}


@pytest.mark.parametrize("layout", LAYOUTS)
def test_every_launcher_and_hosting_gives_the_same_rows_from_the_first_sample(
        imported: Path, tmp_path: Path, layout: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every activity of every process is configured before any starts (configure all, then start
    all): so with any launcher and hosting, the replay emits nothing before the tf and the distance
    are configured, the fixed bowl that tf publishes in on_config comes before every gripper pose,
    and the CSV has one row per joint state that moved the gripper, from the recording's first
    (the ROS launcher's hostings configured each activity in its first callback: with one executor
    thread the replay emitted hundreds of joint states first, which the distance merged into one row,
    silently)."""
    monkeypatch.setenv("ROS_DOMAIN_ID", "67")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    package, name, options = LAYOUTS[layout]
    script = ROOT / "install" / package / "lib" / package / name
    output = tmp_path / "teleop"
    result = run_launcher(script, APP, f"bag:={imported}", f"output:={output}", "fixed_bowl:=true",
                          f"bowl_xyz:={' '.join(map(str, BOWL))}", "arm:=right", f"time_origin:={START}",
                          "rate:=0", "display:=false", *options, "--profile", "100", "--duration", "120",
                          timeout=180)
    assert result.returncode == 0, result.stderr
    moved = moved_distances()
    with (output / "distance.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == len(moved), f"{len(rows)} rows for {len(moved)} joint states that moved the gripper"
    assert [float(row["distance"]) for row in rows] == pytest.approx(moved, abs=2e-6)
    from coco_ros.baxter.importer import read_recording

    assert abs(float(rows[0]["time"]) - read_recording(RECORDING).times[0]) < 1e-4  # its first joint state
    profile = result.stdout + result.stderr
    check_nothing_dropped(profile)
    header = next(line for line in profile.splitlines() if " component " in f" {line}" and " merged " in line)
    row = next(line for line in profile.splitlines() if "distance" in line.split()[:2] and "teleop" in line.split())
    assert row[header.index(" merged ") + 1:].split()[0] == "0", row  # no pose superseded unseen
