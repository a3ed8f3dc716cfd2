"""JointSequence: poses from a CSV file, each held for ``hold`` seconds and written every update;
file errors name the file and line; the end holds the last pose or stops the application."""

from __future__ import annotations

import time

import numpy as np
import pytest

from coco_core import Application, BufferPolicy, Component, ConnectionPolicy, InputPort, OutputPort, SyncPolicy
from coco_core.errors import ConfigError
from coco_core.transforms.joint_sequence import JointSequence, read_poses
from coco_core.transforms.samples import JointSample


class Joints(Component):
    joints = InputPort(JointSample)


def test_read_poses_skips_comments(tmp_path):
    path = tmp_path / "poses.csv"
    path.write_text("# two poses\nleft_s0, left_e1\n0.1,0.2\n# between\n0.3,0.4\n")
    names, values = read_poses(path)
    assert names == ("left_s0", "left_e1")
    np.testing.assert_array_equal(values, [[0.1, 0.2], [0.3, 0.4]])


@pytest.mark.parametrize("text, line, message", [
    ("a,b\n0.1,x\n", 2, r"expected 2 finite numbers \(a, b\), got 0.1, x"),
    ("a,b\n0.1\n", 2, "expected 2 finite numbers"),
    ("a,b\n0.1,nan\n", 2, "expected 2 finite numbers"),
    ("a,a\n0.1,0.2\n", 1, "the header must name each joint once"),
    ("a,b\n", 1, "has a header but no pose"),
    ("# nothing\n", 1, "needs a header of joint names"),
])
def test_bad_files_name_file_and_line(tmp_path, text, line, message):
    path = tmp_path / "poses.csv"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message) as raised:
        read_poses(path)
    assert raised.value.location is not None and (raised.value.location.file, raised.value.location.line) == \
        (str(path), line)


def test_each_pose_is_held_then_the_application_stops(tmp_path):
    path = tmp_path / "poses.csv"
    path.write_text("j1,j2\n1,2\n3,4\n")
    app = Application("sequence")
    arm = app.add(JointSequence("arm", poses=str(path), hold=0.2, stop_at_end=True))
    sink = app.add(Joints("sink"))
    app.connect(arm.joints, sink.joints)
    seen = []
    deadline = time.monotonic() + 5
    while not app.stop_reason and time.monotonic() < deadline:
        arm.on_update()
        status, sample = sink.joints.read()
        if status:
            seen.append(tuple(sample.positions))
        time.sleep(0.02)
    assert "the last of 2 poses was held" in app.stop_reason
    assert seen[0] == (1.0, 2.0) and seen[-1] == (3.0, 4.0)
    assert seen.count((1.0, 2.0)) >= 3 and set(seen) == {(1.0, 2.0), (3.0, 4.0)}, "written every update"


def test_empty_poses_attribute_is_an_error():
    with pytest.raises(ConfigError, match="the poses attribute is empty"):
        Application("x").add(JointSequence("arm"))


def test_poses_that_are_no_regular_file_are_refused_naming_the_attribute():
    from coco_core.errors import AttributeValueError

    with pytest.raises(AttributeValueError) as raised:
        JointSequence("arm", poses="/dev/zero")
    assert str(raised.value) == ("attribute arm.poses (file): file /dev/zero is a character device, not a regular "
                                 "file; expected a CSV file: a header of joint names, one pose per row")


class Measurement(Component):
    """What measures the poses: one value per call of ``measure`` (a tracker's detections)."""

    out = OutputPort(object)

    def measure(self) -> None:
        self.out.write("detections")


def test_with_frames_a_pose_waits_for_the_measurement_however_long_the_clock_says(tmp_path):
    """A loaded machine: the measurement lags far behind the clock; each pose is still held until it
    was measured ``frames`` times (and for ``hold`` seconds)."""
    path = tmp_path / "poses.csv"
    path.write_text("j1\n1\n2\n")
    app = Application("paced")
    arm = app.add(JointSequence("arm", poses=str(path), hold=0.01, frames=3, stop_at_end=True))
    sink = app.add(Joints("sink"))
    camera = app.add(Measurement("camera"))
    app.connect(arm.joints, sink.joints)
    app.connect(camera.out, arm.seen, ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 16))
    poses = []
    for cycle in range(40):  # the clock alone would have ended the sequence long before
        if cycle % 5 == 4:
            camera.measure()  # one measurement every five updates
        time.sleep(0.012)
        arm.on_update()
        poses.append(arm.pose)
        if app.stop_reason:
            break
    assert "the last of 2 poses was held" in app.stop_reason
    # Pose 0 for the first three measurements (15 updates), pose 1 for the next three.
    assert poses.count(0) >= 14 and poses.count(1) >= 14, poses
