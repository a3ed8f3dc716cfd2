"""The Baxter teleoperation replay app (config/baxter_teleop_replay.xml) on a generated session, run
through the installed coco-launch and the ROS launcher node as a user does."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from conftest import ROOT, activity_cycles, connection_counters, damaged_copy, run_launcher

APP = "config/baxter_teleop_replay.xml"
URDF = "package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"



def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def latency(report: str, component: str) -> tuple[float, float]:
    """(mean, max) ms of a component's stamp-to-output latency in a profile report."""
    # The component table (an activity may share the name); with several processes each row starts
    # with the process's name.
    components = report[re.search(r"^(process\s+)?component\s", report, re.M).start():]
    line = re.search(rf"^(\S+\s+)?{component}\s.*$", components, re.M).group(0)
    found = re.search(r"([0-9.]+) / ([0-9.]+)\s*$", line)
    assert found, f"no latency for {component}: {line}"
    return float(found.group(1)), float(found.group(2))


def test_teleop_app_replays_the_session(coco_launch: Path, session, tmp_path: Path) -> None:
    from coco_core.transforms.urdf import UrdfModel

    from coco_ros.baxter.ik import NEUTRAL
    from coco_ros.baxter.joints import ARM_JOINTS

    folder, info = session
    output = tmp_path / "teleop"
    # The data path alone: the display's start (EGL context, Baxter's meshes) competes for the CPU and
    # the GIL and may make the distance skip the first joint states (test_baxter_view.py renders).
    result = run_launcher(coco_launch, APP, f"bag:={folder}", f"output:={output}", "display:=false",
                          f"time_origin:={info.start_ns / 1e9}", "--profile", "100", "--duration", "60", timeout=120)
    assert result.returncode == 0, result.stderr
    assert "bag" in result.stderr and "replayed" in result.stderr, result.stderr
    report = result.stdout
    assert "Profile of application 'baxter_teleop_replay'" in report, report
    for name in ("replay", "tf", "distance", "summary"):
        assert re.search(rf"^{name}\s", report, re.M), f"{name} missing from the profile:\n{report}"
    # The bowl and the target reach the distance and the summary through the transformation graph.
    for connection in ("replay.bowl_pose -> tf.transform", "replay.target_pose -> tf.transform",
                       "tf.bowl -> distance.bowl", "tf.target -> summary.target"):
        assert connection in report, report
    # Latency from the replay's emission: the summary's row comes after the distance, for every sample.
    distance_latency, summary_latency = latency(report, "distance"), latency(report, "summary")
    assert 0 < distance_latency[0] <= summary_latency[0], report

    rows = read_csv(output / "distance.csv")
    assert len(rows) > 500, f"only {len(rows)} distance samples in a 12 s session"
    assert all(0.0 <= float(r[c]) <= 1.0 for r in rows for c in ("r", "g", "b"))
    # Only real data: the first sample is the arm at home (its first joint state), not at zero joints.
    robot = UrdfModel.load(URDF)
    robot.set_positions(dict(zip(ARM_JOINTS["left"], NEUTRAL["left"])))
    home = np.linalg.norm(robot.placement("left_gripper")[:3, 3] - info.bowl[:3, 3])
    first = rows[0]
    assert 0.0 <= float(first["time"]) < 0.05, first
    home_rows = [r for r in rows if float(r["time"]) < 0.45]
    assert home_rows and all(float(r["distance"]) == pytest.approx(home, abs=2e-6) for r in home_rows), (home, home_rows[:3])

    summary = json.loads((output / "summary.json").read_text())
    assert summary["samples"] == len(rows)
    phases = {name: (start, end) for name, start, end in info.phases}
    # The gripper reaches the bowl: within 2 cm first during the descent onto it, by the grasp at the latest.
    assert summary["min_distance"] < 0.02, summary
    assert summary["grasp_time"] is not None, summary
    assert phases["descend"][0] - 0.1 <= summary["grasp_time"] <= info.grasp_time + 0.1, (summary, info.phases)
    # The closest approach is while the gripper holds the bowl, from the grasp to the release.
    assert phases["grasp"][0] - 0.5 <= summary["min_distance_time"] <= info.release_time + 0.5, summary
    # After the release and retreat the gripper is away; the bowl (frame bowl) was placed on its target (frame target).
    assert summary["final_distance"] > 0.05, summary
    assert summary["final_bowl_target_distance"] < 0.01, summary


def test_teleop_app_in_the_ros_launcher(session, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The same app hosted by the rclpy launcher node (its activities in wait sets of their own)."""
    monkeypatch.setenv("ROS_DOMAIN_ID", "65")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    launcher = ROOT / "install" / "coco_ros" / "lib" / "coco_ros" / "launcher"
    if not launcher.exists():
        pytest.fail(f"{launcher} is missing: build the workspace first (scripts/setup.sh does)")
    folder, info = session
    output = tmp_path / "teleop"
    result = run_launcher(launcher, APP, f"bag:={folder}", f"output:={output}", "rate:=3",
                          f"time_origin:={info.start_ns / 1e9}", "--profile", "100", "--duration", "60", timeout=120)
    assert result.returncode == 0, result.stderr
    assert "node /baxter_teleop_replay hosts application baxter_teleop_replay" in result.stderr, result.stderr
    assert "activity frames: triggered -> wait set on its own thread" in result.stderr, result.stderr
    # The view runs in a process of its own (display_process:=true), with a node of its own; there
    # too the display keeps its EGL context on one thread: GLManager is thread-bound.
    assert "coco[view]: process view: activity display: periodic 50 ms, nice 5 -> own thread" in result.stderr, result.stderr
    assert "view" in result.stdout and "display    periodic 50 ms" in result.stdout, result.stdout
    latency(result.stdout, "summary")
    summary = json.loads((output / "summary.json").read_text())
    assert summary["samples"] == len(read_csv(output / "distance.csv")) > 200, summary
    assert summary["min_distance"] < 0.02 and summary["final_bowl_target_distance"] < 0.01, summary
    # Every rendered frame shows the scene (on a thread without the context they came out black or garbled).
    cv2 = pytest.importorskip("cv2", reason="the recorded frames are decoded with OpenCV")
    capture = cv2.VideoCapture(str(output / "frames.mp4"))
    frames = []
    while (frame := capture.read())[0]:
        frames.append(frame[1])
    assert len(frames) == activity_cycles(result.stdout, "view", "display") >= 20, (len(frames), result.stdout)
    background = [frame[5, 5].astype(int) for frame in frames]  # BGR of the clear colour 0.16 0.17 0.20
    assert all(np.abs(pixel - (51, 43, 41)).max() <= 6 for pixel in background), background


def test_a_truncated_bag_makes_the_app_exit_1_with_the_damage_in_its_summary(coco_launch: Path, session,
                                                                             tmp_path: Path) -> None:
    """The session cut at a record boundary, where its last chunk starts (no byte of a record is cut, so
    only metadata.yaml's counts reveal it): the app replays what is readable, exits 1, and summary.json
    names the loss."""
    import shutil

    from mcap.reader import make_reader

    from coco_ros.teleop.summary import describe

    folder, info = session
    damaged = tmp_path / "damaged"
    shutil.copytree(folder, damaged)
    mcap = next(damaged.glob("*.mcap"))
    with mcap.open("rb") as stream:
        chunks = sorted(c.chunk_start_offset for c in make_reader(stream).get_summary().chunk_indexes)
    assert len(chunks) >= 2
    mcap.write_bytes(mcap.read_bytes()[: chunks[-1]])
    output = tmp_path / "teleop"
    result = run_launcher(coco_launch, APP, f"bag:={damaged}", f"output:={output}", "display:=false", "rate:=4",
                          f"time_origin:={info.start_ns / 1e9}", "--duration", "60", timeout=120)
    assert result.returncode == 1, result.stderr
    assert "are lost" in result.stderr, result.stderr
    summary = json.loads((output / "summary.json").read_text())
    assert summary["samples"] > 0 and len(summary["input_damage"]) == 1, summary
    assert "metadata.yaml" in summary["input_damage"][0] and "are lost" in summary["input_damage"][0]
    assert "DAMAGED INPUT" in describe(summary)


def copy_with_malformed_messages(folder: Path, copy: Path, joint_states: set[int], bowl_poses: set[int]) -> None:
    """``folder``'s bag written again into ``copy`` with the given joint states (by index) one position
    short of their names and the given bowl poses' quaternions zero (even index) or NaN (odd)."""

    def damage(topic: str, i: int, _seconds: float, msg: Any) -> Any:
        if topic == "/robot/joint_states" and i in joint_states:
            msg.position = list(msg.position)[:-1]
        elif topic == "/bowl/pose" and i in bowl_poses:
            q = msg.pose.orientation
            q.x, q.y, q.z, q.w = (0.0, 0.0, 0.0, 0.0) if i % 2 == 0 else (q.x, q.y, q.z, float("nan"))
        return msg

    damaged_copy(folder, copy, damage)


@pytest.mark.parametrize("rate", ["0", "4"])
def test_a_malformed_message_in_the_bag_costs_only_itself(coco_launch: Path, session, tmp_path: Path,
                                                          rate: str) -> None:
    """Issue 23: one JointState with a position fewer than names cost the replay's whole read batch (96
    joint states at rate:=0), silently and with exit 0. Now each malformed message (one joint state,
    a zero and a NaN bowl quaternion) is refused alone, counted in the profile's refused column and
    the summary, named in input_damage, and the launcher exits with 1."""
    from coco_ros.teleop.summary import describe

    folder, info = session
    damaged = tmp_path / "malformed"
    copy_with_malformed_messages(folder, damaged, joint_states={600}, bowl_poses={250, 301})
    output = tmp_path / "teleop"
    result = run_launcher(coco_launch, APP, f"bag:={damaged}", f"output:={output}", "display:=false",
                          f"rate:={rate}", "--profile", "100", "--duration", "60", timeout=120)
    assert result.returncode == 1, result.stderr
    report = result.stdout
    joints, poses = info.counts["/robot/joint_states"], info.counts["/bowl/pose"]
    assert connection_counters(report, "replay.robot_joint_states -> tf.joints") == (joints - 1, joints - 1, 0), report
    assert connection_counters(report, "replay.bowl_pose -> tf.transform") == (poses - 2, poses - 2, 0), report
    # component, activity, execs, total, compute mean/std, service mean/std, errors, refused, merged, latency
    refused = re.search(r"^replay\s+replay\s.*$", report, re.M).group(0).split()[9]
    assert refused == "3", report
    summary = json.loads((output / "summary.json").read_text())
    written = connection_counters(report, "distance.distance -> summary.distance")[0]
    assert summary["samples"] == written == len(read_csv(output / "distance.csv"))
    assert summary["input_refused"] == {"replay": 3}, summary
    damage = summary["input_damage"]
    assert len(damage) == 3, damage
    assert "/robot/joint_states message 6.000 s into the bag" in damage[0] and "21 names but 20 position" in damage[0]
    assert "/bowl/pose" in damage[1] and "zero" in damage[1] and "/bowl/pose" in damage[2] and "nan" in damage[2]
    assert "REFUSED INPUT: replay refused 3 malformed samples" in describe(summary)
