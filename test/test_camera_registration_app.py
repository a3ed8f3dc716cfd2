"""config/camera_registration.xml, run as a user runs it: the simulated head camera registered to the
Baxter within the goal (5 mm, 0.5 degree of the true pose), the same application on the bag that the
simulated run recorded (joint states, images, camera_info: what a real robot records), and the
failures a user meets: a source it does not know, a recording in which the marker never rests in sight."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from conftest import ROOT, run_launcher
from test_documented_commands import shell_blocks

APP = "config/camera_registration.xml"
GOAL_M, GOAL_DEG = 0.005, 0.5
DOCUMENTED = ROOT / "docs" / "vision.md"
"""Where the application's two command lines are documented: these tests run those very lines (with
their own outputs), and test_documented_commands.py does not run them again (its NOT_RUN)."""


def documented_run(kind: str, outputs: dict[str, Path]) -> list[str]:
    """The arguments after ``coco-launch`` of the documented line that records the simulation (``sim``)
    or registers from its bag (``bag``), each ``out/...`` value replaced by the test's own folder."""
    lines = [command.bare.split() for block in shell_blocks(DOCUMENTED) for command in block.commands
             if APP in command.bare]
    assert len(lines) == 2 and all(line[:2] == ["coco-launch", APP] for line in lines), lines
    line = next(words for words in lines if ("source:=bag" in words) == (kind == "bag"))[1:]
    args = []
    for word in line:
        name, _, value = word.partition(":=")
        if value.startswith("out/"):
            assert value in outputs, f"{DOCUMENTED.name} names {value}: give the test a folder for it"
            word = f"{name}:={outputs[value]}"
        args.append(word)
    return args


def registration(folder: Path) -> dict:
    return json.loads((folder / "registration.json").read_text())


@pytest.fixture(scope="module")
def simulated(coco_launch, tmp_path_factory) -> tuple[Path, Path]:
    """One simulated run that also records its bag: (its output folder, the bag)."""
    folder = tmp_path_factory.mktemp("registration")
    bag = folder / "bag"
    args = documented_run("sim", {"out/registration_bag": bag})
    assert not any(word.startswith("output:=") for word in args), args  # the file's default: out/registration
    result = run_launcher(coco_launch, *args, f"output:={folder / 'sim'}", timeout=180)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "error against truth_camera" in result.stderr, result.stderr
    return folder / "sim", bag


def test_simulated_head_camera_is_registered_within_the_goal(simulated):
    report = registration(simulated[0])
    assert report["used"] >= 4 and report["samples"] >= 5, report  # 8 rests, fewer on a loaded machine
    assert report["error_m"] < GOAL_M and report["error_deg"] < GOAL_DEG, report
    assert report["rms_translation"] < GOAL_M, "the residual is reported, and small"


def test_the_same_application_registers_from_the_recorded_bag(coco_launch, simulated, tmp_path):
    """The bag holds what a robot with a head camera records; truth:=true compares with the pose
    the simulation rendered from, which the bag does not contain."""
    _, bag = simulated
    topics = (bag / "metadata.yaml").read_text()
    for topic in ("/robot/joint_states", "/cameras/head_camera/image", "/cameras/head_camera/camera_info"):
        assert topic in topics
    args = documented_run("bag", {"out/registration_bag": bag, "out/registration_from_bag": tmp_path})
    assert {"source:=bag", f"bag:={bag}", "truth:=true", f"output:={tmp_path}"} <= set(args), args
    result = run_launcher(coco_launch, *args, timeout=180)
    assert result.returncode == 0, result.stdout + result.stderr
    report = registration(tmp_path)
    assert report["error_m"] < GOAL_M and report["error_deg"] < GOAL_DEG, report
    simulated_report = registration(simulated[0])
    moved = math.dist(report["translation"], simulated_report["translation"])
    assert moved < 0.003, f"bag and live results differ by {moved * 1000:.1f} mm"


def test_an_unknown_source_names_the_choices(coco_launch):
    result = run_launcher(coco_launch, APP, "source:=kinect", "--check")
    assert result.returncode == 1
    assert "camera_registration.xml:" in result.stderr and "arg 'source' is 'kinect'; expected one of: sim, bag" \
        in result.stderr, result.stderr


def test_a_recording_without_the_marker_at_rest_fails_clearly(coco_launch, tmp_path):
    """The arm never rests (each pose held for a single camera frame): no sample, nothing installed,
    a non-zero exit that says why."""
    poses = tmp_path / "poses.csv"
    poses.write_text("left_s0,left_s1,left_e1,left_w1,left_w2\n0.30,-0.30,1.50,0.80,0.00\n0.15,-0.20,1.40,0.90,0.30\n")
    result = run_launcher(coco_launch, APP, f"poses:={poses}", "hold:=0.05", "rest_frames:=0", f"output:={tmp_path}", timeout=120)
    assert result.returncode == 1, result.stdout + result.stderr
    assert "nothing registered" in result.stderr and not (tmp_path / "registration.json").exists()
