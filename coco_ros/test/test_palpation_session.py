"""The generated remote palpation session: topics and rates, depth as a structured-light sensor
delivers it, the marker where the scene put it, the hand's touch on the marker, the same bytes twice."""

from __future__ import annotations

import numpy as np
import pytest

from coco_core.policy import BufferPolicy, ConnectionPolicy
from coco_core.transforms import se3
from coco_ros.bag import BagReader
from coco_ros.palpation.session import (DEPTH_STEP, MARKER_DICTIONARY, MARKER_ID, MARKER_LENGTH, PRESS_DEPTH,
                                        belly_height, generate_session, hand_at, hand_plan, main)

DURATION = 4.5
"""The shortest session (half the nominal length): every phase, in a short test."""


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    folder = tmp_path_factory.mktemp("palpation") / "session"
    info = generate_session(folder, seed=3, duration=DURATION)
    return info, BagReader(folder)


def stamp(message) -> float:
    return message.header.stamp.sec + message.header.stamp.nanosec * 1e-9


def image(message) -> np.ndarray:
    dtype = np.uint16 if message.encoding == "16UC1" else np.uint8
    return np.frombuffer(bytes(message.data), dtype).reshape(message.height, message.width, -1).squeeze()


def project(info, point_in_table) -> tuple[int, int, float]:
    """Pixel (column, row) and depth of a point of the table's frame in the session's camera."""
    fx, fy, cx, cy = info.intrinsics
    p = se3.inverse(info.camera) @ np.append(point_in_table, 1.0)
    return int(round(fx * p[0] / p[2] + cx)), int(round(fy * p[1] / p[2] + cy)), float(p[2])


def test_topics_rates_and_encodings(session):
    info, reader = session
    counts = {topic: sum(1 for _ in reader.messages(topic)) for topic in reader.topics}
    assert counts == {"/camera/color/image_raw": 136, "/camera/depth/image_raw": 136,
                      "/camera/color/camera_info": 136, "/hand/pose": 451}
    color = next(iter(reader.messages("/camera/color/image_raw"))).message
    depth = next(iter(reader.messages("/camera/depth/image_raw"))).message
    assert (color.encoding, color.width, color.height, color.header.frame_id) == ("rgb8", 640, 480, "camera")
    assert (depth.encoding, depth.step) == ("16UC1", 1280)
    hands = [m.message for m in reader.messages("/hand/pose")]
    assert {h.header.frame_id for h in hands} == {"hand_tracker"}
    assert np.allclose(np.diff([stamp(h) for h in hands]), 0.01, atol=1e-6)
    frames = [stamp(m.message) for m in reader.messages("/camera/depth/image_raw")]
    assert np.allclose(np.diff(frames), 1 / 30, atol=1e-6)


def test_depth_is_quantised_with_holes_at_the_edges(session):
    info, reader = session
    depths = [image(m.message) for m in reader.messages("/camera/depth/image_raw")]
    first = depths[0].astype(float)
    # The marker's centre at its true distance, within a step and the noise.
    column, row, distance = project(info, info.marker[:3, 3])
    assert abs(first[row, column] / 1000.0 - distance) < 2.5 * DEPTH_STEP * distance**2
    # Depth in disparity steps: at ~1 m the values present are ~3.7 mm apart, not every millimetre.
    near = np.unique(first[(first > 950) & (first < 1050)])
    assert 3.0 <= np.median(np.diff(near)) <= 4.5
    # No depth along the body's silhouette (a jump of the depth), little elsewhere.
    missing = first == 0
    assert 0.005 < missing[100:, :].mean() < 0.15
    torso_edge_row = next(r for r in range(row, 480) if first[r, column] > 0 and first[r + 3, column] > first[r, column] + 40)
    assert missing[torso_edge_row - 2:torso_edge_row + 5, column].any()
    # The noise changes from frame to frame; the scene does not.
    assert not np.array_equal(depths[0], depths[1])
    both = (depths[0] > 0) & (depths[1] > 0)
    assert np.median(np.abs(depths[0][both].astype(int) - depths[1][both].astype(int))) <= 4


def test_the_marker_is_where_the_scene_put_it(session):
    from coco_mr_vision.image import CameraIntrinsics, Image, ImageFormat
    from coco_mr_vision.marker_tracker import MarkerTracker

    info, reader = session
    color = next(iter(reader.messages("/camera/color/image_raw"))).message
    fx, fy, cx, cy = info.intrinsics
    tracker = MarkerTracker("tracker", dictionary=MARKER_DICTIONARY, marker_length=MARKER_LENGTH, publish=False)
    tracker.configure()
    found = tracker.detect(Image(image(color).copy(), ImageFormat.RGB8, 0.0, "camera",
                                 CameraIntrinsics(640, 480, fx, fy, cx, cy)))
    assert found.ids.tolist() == [MARKER_ID]
    truth = se3.inverse(info.camera) @ info.marker
    pose = found.pose(MARKER_ID)
    # Across the view within millimetres; along it within 2 % (a 40-pixel marker's size, to half a pixel).
    error = pose[:3, 3] - truth[:3, 3]
    assert np.linalg.norm(error[:2]) < 3e-3 and abs(error[2]) < 0.02 * truth[2, 3]
    assert np.degrees(np.arccos(np.clip(pose[:3, 2] @ truth[:3, 2], -1, 1))) < 5, "its face up, towards the camera"


def test_the_hand_touches_the_marker_then_presses_the_belly(session):
    info, reader = session
    start = info.start_ns * 1e-9
    hands = [(stamp(m.message) - start, m.message.pose) for m in reader.messages("/hand/pose")]

    def in_table(pose) -> np.ndarray:
        q = pose.orientation
        return info.tracker @ se3.from_pose((pose.position.x, pose.position.y, pose.position.z), (q.x, q.y, q.z, q.w))

    touch = next(p for p in info.phases if p[0] == "calibration_touch")
    held = [in_table(pose) for t, pose in hands if touch[1] <= t < touch[2]]
    assert len(held) >= 40
    offsets = np.array([h[:3, 3] - info.marker[:3, 3] for h in held])
    assert np.linalg.norm(offsets.mean(axis=0)) < 3e-4 and offsets.std(axis=0).max() < 6e-4
    assert np.allclose(held[0][:3, :3], info.marker[:3, :3], atol=1e-9), "palm aligned with the marker"
    plan = hand_plan(DURATION)
    deepest = {}
    for name, begin, end, *_ in plan:
        if name.startswith("press"):
            points = [hand_at(plan, t) for t in np.linspace(begin, end, 200)]
            deepest[name] = max(belly_height(p[0], p[1]) - p[2] for p in points)
    assert deepest and all(d == pytest.approx(PRESS_DEPTH, abs=1e-4) for d in deepest.values())
    last = in_table(hands[-1][1])[:3, 3]
    assert last[2] - belly_height(last[0], last[1]) > 0.15, "lifted off at the end"


def test_the_same_bytes_every_time(session, tmp_path, capsys):
    info, _ = session
    again = tmp_path / "session"  # the same name: the bag's metadata names its file
    assert main([str(again), "--seed", "3", "--duration", str(DURATION), "--quiet"]) == 0
    assert (again / "session_0.mcap").read_bytes() == (info.folder / "session_0.mcap").read_bytes()
    assert main([str(tmp_path / "short"), "--duration", "1", "--quiet"]) == 1
    assert "duration must be at least" in capsys.readouterr().err


def test_the_touch_on_the_marker_registers_the_hand_tracker(session, tmp_path):
    """The session's colour frames through MarkerTracker and its hand poses, in log order, into
    TouchRegistration: camera -> hand_tracker is installed during the touch, near the scene's truth,
    with a small residual; an application that stops before a touch records the damage."""
    import json

    from coco_core.application import Application
    from coco_core.component import Component
    from coco_core.ports import OutputPort
    from coco_core.transforms.samples import FramePose
    from coco_mr_vision.image import CameraIntrinsics, Image, ImageFormat
    from coco_mr_vision.marker_tracker import MarkerTracker
    from coco_mr_vision.touch_registration import TouchRegistration

    class Sources(Component):
        markers = OutputPort(object)
        hand = OutputPort(object)

    info, reader = session
    app = Application("touch")
    sources = app.add(Sources("sources"))
    registration = app.add(TouchRegistration("registration", marker_id=MARKER_ID, output=tmp_path / "touch.json"))
    app.connect("sources.markers", "registration.markers", ConnectionPolicy(BufferPolicy.BUFFER, size=10))
    app.connect("sources.hand", "registration.hand", ConnectionPolicy(BufferPolicy.BUFFER, size=10))
    registration.configure()
    fx, fy, cx, cy = info.intrinsics
    tracker = MarkerTracker("tracker", dictionary=MARKER_DICTIONARY, marker_length=MARKER_LENGTH, publish=False)
    tracker.configure()
    touch = next(p for p in info.phases if p[0] == "calibration_touch")
    start = info.start_ns * 1e-9
    for message in reader.messages(["/camera/color/image_raw", "/hand/pose"]):
        m = message.message
        if message.topic == "/hand/pose":
            q, p = m.pose.orientation, m.pose.position
            sources.hand.write(FramePose("hand_tracker", "hand", se3.from_pose((p.x, p.y, p.z), (q.x, q.y, q.z, q.w)),
                                         stamp(m)))
        else:
            sources.markers.write(tracker.detect(Image(image(m).copy(), ImageFormat.RGB8, stamp(m), "camera",
                                                       CameraIntrinsics(640, 480, fx, fy, cx, cy))))
        registration.step()
        if registration.installed is not None:
            installed_at = stamp(m) - start
            break
    assert registration.installed is not None
    assert touch[1] < installed_at <= touch[2] + 0.1, "during the touch, once the hand has rested"
    truth = se3.inverse(info.camera) @ info.tracker
    assert np.allclose(app.transforms.lookup("camera", "hand_tracker"), registration.installed)
    # The residual (the marker against the touch point mapped) is the noise of the detections; the
    # error against the truth is bounded by the marker's depth error (2 % of 1 m, see above).
    assert registration.rms < 3e-3
    assert np.linalg.norm(registration.installed[:3, 3] - truth[:3, 3]) < 0.025
    report = json.loads((tmp_path / "touch.json").read_text())
    assert report["residual_m"] == pytest.approx(registration.rms)
    # When, in the recording's time: the newest detection sampled, once the hand had rested, at the
    # latest the message that completed the samples.
    assert report["stamp"] == registration.installed_stamp
    assert start + touch[1] + registration.still_time <= report["stamp"] <= start + installed_at + 1e-6
    never = TouchRegistration("never", marker_id=MARKER_ID)
    app.add(never)
    never.configure()
    never.stop()
    assert any("nothing registered" in damage for damage in app.damage)


def test_the_hand_never_jumps():
    """Each phase starts where the last one left the hand: a press ended 2 cm over its point but the
    next press (and the stroke) started from the previous press's bottom, 8 mm inside the body, so
    the hand jumped 3 cm down and slid inside the body from one press to the next (the palpation
    app's device then slid over the belly between the presses instead of lifting)."""
    plan = hand_plan(DURATION)
    times = np.arange(0.0, DURATION, 1e-3)
    path = np.array([hand_at(plan, t) for t in times])
    steps = np.linalg.norm(np.diff(path, axis=0), axis=1)
    assert steps.max() < 2e-3, f"a jump of {steps.max() * 1e3:.1f} mm at {times[int(np.argmax(steps))]:.3f} s"
    for name, start, end, *_ in plan:
        if name.startswith("press"):  # lifted off the body between two presses
            at = hand_at(plan, start)
            assert at[2] > belly_height(at[0], at[1]) + 0.01, (name, at)
