"""The remote palpation app (config/palpation_replay.xml) on bad input, run through the installed
coco-launch on damaged copies of a generated session (issue 20): a stream that stops, camera frames
of the wrong size or encoding, hand poses with NaN, and a surface far stiffer than the device can
render. None of it crashes the app or stops the haptic loop; each is counted in summary.json and its
printed form; damaged messages (a frame, a pose) make the launcher exit 1, a stream that stops does
not (its frames were sound: it is a reported event of the run, docs/haptics.md).

Every count is checked against what was damaged and against the run's own profile, never against
wall time: a loaded machine runs fewer haptic cycles, not other counts."""

from __future__ import annotations

import csv
import json
import math
import re
from pathlib import Path
from typing import Any

import pytest

from conftest import ROOT, damaged_copy, run_launcher
from test_palpation_app import HAND_RATE, free_port

APP = ROOT / "config" / "palpation_replay.xml"


def run_app(bag: Path, output: Path, *args: str):
    """The app on ``bag`` without the view (it only watches), the hand at the app tests' speed."""
    return run_launcher(ROOT / "install" / "coco_core" / "lib" / "coco_core" / "coco-launch", str(APP),
                        f"bag:={bag}", f"output:={output}", f"rate:={HAND_RATE}",
                        f"stream:=tcp://127.0.0.1:{free_port()}", "display:=false", *args,
                        "--profile", "100", "--duration", "60", timeout=240)


def profile_row(report: str, process: str, component: str) -> dict[str, int]:
    """The errors and refused columns of a component's row in the profile (peers read ``name (peer)``)."""
    table = report[report.index("\nprocess   component "):]  # not the activity table (activities named as components)
    match = re.search(rf"^{process}\s+{re.escape(component)}(?: \(peer\))?\s+\S+\s+(.*)$", table, re.M)
    assert match, f"no component {component} of process {process} in the profile:\n{report}"
    # execs, total, compute mean/std, service mean/std, errors, refused, merged, latency
    fields = match.group(1).split()
    return {"execs": int(fields[0]), "errors": int(fields[6]), "refused": int(fields[7])}


def forces(output: Path) -> list[float]:
    """The force's magnitude of every haptic cycle in haptic.csv, after a check that every number is finite."""
    with (output / "haptic.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert rows, "no haptic sample: the workspace was never joined to the camera"
    numbers = [float(value) for row in rows for key, value in row.items() if key[-2:] in ("_x", "_y", "_z")]
    assert all(math.isfinite(n) for n in numbers), "a non-finite number in haptic.csv"
    return [math.sqrt(sum(float(row[f"force_{a}"]) ** 2 for a in "xyz")) for row in rows]


def test_a_stream_that_stops_and_a_surface_stiffer_than_the_device(palpation_session: Path,
                                                                    tmp_path: Path) -> None:
    """The camera's recording ends at 2 s (after the calibration touch) and is not started again
    (camera_loop:=false): the remote camera stops streaming while the hand goes on to palpate. The
    haptic loop goes on with the last structure: it touches the body in the presses after the
    stream stopped. The stall is counted in the summary and printed; the exit status is 0 (the
    frames that came were sound). The surface is 125 times stiffer than the app's and the device's
    limit 1.5 N, under what a press asks (the coupling of a hand 8 mm in): every force the loop
    sends is at most the limit, and the limit is reached."""
    from coco_ros.palpation.summary import describe

    bag, output, limit = tmp_path / "stream_stops", tmp_path / "out", 1.5
    counts = damaged_copy(palpation_session, bag,
                          lambda topic, _, t, message: None if topic.startswith("/camera") and t > 2.0 else message)
    frames = counts["/camera/depth/image_raw"]
    result = run_app(bag, output, "camera_loop:=false", "stiffness:=100000", f"max_force:={limit}")
    assert result.returncode == 0, result.stderr[-6000:]
    summary = json.loads((output / "summary.json").read_text())
    stream, haptics = summary["stream"], summary["haptics"]
    assert 0 < stream["frames"] <= frames, (stream, frames)
    assert stream["stalls"] >= 1 and stream["silent_at_end_s"] > stream["stall_s"], stream
    assert stream["longest_gap_s"] >= stream["silent_at_end_s"], stream
    assert haptics["contact_after_last_frame_s"] > 0, f"no contact on the last structure after the stream stopped: {summary}"
    assert summary["input_damage"] == [] and summary["registration_residual_mm"] is not None, summary
    printed = describe(summary)
    assert f"STREAM STALLED {stream['stalls']} time" in printed, printed
    for process, component in (("haptics", "device"), ("haptics", "renderer"), ("stream", "receiver"),
                               ("stream", "tree"), ("local", "summary")):
        assert profile_row(result.stdout, process, component)["errors"] == 0, (process, component)
    # The force limit, whatever the surface asks.
    magnitudes = forces(output)
    assert len(magnitudes) == haptics["samples"]
    assert haptics["max_force_n"] <= limit * (1 + 1e-12), haptics  # the samples' own numbers
    assert max(magnitudes) <= limit * (1 + 1e-5), max(magnitudes)  # the CSV's: 6 significant digits
    assert max(magnitudes) >= limit * 0.999, f"the presses never asked for more than {limit} N: {max(magnitudes)}"


BAD_FRAMES = {
    ("/camera/color/image_raw", 6): "must be registered: same size",  # 0.2 s: half the colour's rows
    ("/camera/depth/image_raw", 12): "must be DEPTH16 or DEPTH32F",  # 0.4 s: the depth as rgb8
    ("/camera/depth/image_raw", 18): "'bogus16' is not supported",  # 0.6 s: an encoding nobody knows
    ("/camera/color/camera_info", 24): "intrinsics are for 320x240 images",  # 0.8 s: another size
}
"""The camera messages damaged (topic, index: at 30 Hz, before the calibration touch's detections)
and what the refusal of each says."""

NAN_POSES = {120, 121, 122, 200, 201, 202, 203}
"""The hand poses (100 Hz) given a NaN position: 1.2 s, during the calibration touch's rest, and
2.0 s, in the first press."""


def damage_frames_and_poses(topic: str, index: int, _: float, message: Any) -> Any:
    if (topic, index) in BAD_FRAMES:
        if topic == "/camera/color/image_raw":
            message.height //= 2
            message.data = message.data[: message.step * message.height]
        elif topic == "/camera/color/camera_info":
            message.width, message.height = message.width // 2, message.height // 2
        elif index == 12:
            message.encoding, message.step = "rgb8", message.width * 3
            message.data = bytes(message.step * message.height)
        else:
            message.encoding = "bogus16"
    if topic == "/hand/pose" and index in NAN_POSES:
        message.pose.position.y = float("nan")
    return message


def test_frames_of_the_wrong_size_or_encoding_and_hand_poses_with_nan(palpation_session: Path,
                                                                      tmp_path: Path) -> None:
    """Four camera messages damaged (a colour frame half as tall as its depth, a depth frame as rgb8,
    one in an unknown encoding, a camera_info of another size) and seven hand poses with a NaN
    position (three in the calibration touch, four in a press). Each is refused alone where it is
    read (the remote process's camera, the hand process's replay), counted in the profile's refused
    column, and named in summary.json's input_damage (written in the haptic process: the damage of
    every process reaches it) and in the printed summary; the frames after them are streamed, the
    touch registers the tracker, the presses are touched, no NaN reaches the haptic loop, and the
    launcher exits 1 (damaged input)."""
    from coco_ros.palpation.summary import describe

    bag, output = tmp_path / "damaged", tmp_path / "out"
    damaged_copy(palpation_session, bag, damage_frames_and_poses)
    # The camera not looped: each damaged frame is read once (a looped one would be refused at each pass).
    result = run_app(bag, output, "camera_loop:=false")
    assert result.returncode == 1, result.stderr[-6000:]
    report = result.stdout
    assert profile_row(report, "remote", "camera_bag")["refused"] == len(BAD_FRAMES), report
    assert profile_row(report, "hand", "replay")["refused"] == len(NAN_POSES), report
    assert profile_row(report, "haptics", "device")["refused"] == 0, "a NaN pose reached the device"
    for process, component in (("remote", "camera"), ("hand", "replay"), ("haptics", "device"),
                               ("haptics", "renderer"), ("stream", "tree")):
        assert profile_row(report, process, component)["errors"] == 0, (process, component, report)

    summary = json.loads((output / "summary.json").read_text())
    damage = summary["input_damage"]
    frames = [line for line in damage if line.startswith("camera_bag: ")]
    poses = [line for line in damage if line.startswith("replay: ")]
    assert len(frames) == len(BAD_FRAMES) and len(poses) == len(NAN_POSES), damage
    for line, ((_, index), reason) in zip(frames, sorted(BAD_FRAMES.items(), key=lambda item: item[0][1])):
        assert f"message {index / 30:.3f} s into the bag" in line and reason in line, (line, reason)
    assert all("/hand/pose message" in line and "is not finite: not a pose" in line for line in poses), poses
    printed = describe(summary)
    assert printed.count("DAMAGED INPUT: ") == len(damage), printed
    # The app went on: frames after the damaged ones streamed and made touchable, the touch registered the
    # tracker, the device touched the body, and no NaN reached the haptic loop.
    assert summary["stream"]["frames"] >= 10 and summary["kdtree"]["updates"] >= 2, summary
    assert summary["registration_residual_mm"] is not None, "the touch did not register the tracker"
    assert summary["haptics"]["contact_time_s"] > 0, summary
    assert len(forces(output)) == summary["haptics"]["samples"]
