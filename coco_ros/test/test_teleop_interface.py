"""TransformationInterface as the teleop app uses it: FramePose values on its ``transform`` input (target=parent,
source=child), ``wait_for_joints``, and ``stamped`` lookups carrying the stamp of their cause."""

from __future__ import annotations

import time

import numpy as np
from coco_core.activity import TriggeredActivity
from coco_core.application import Application
from coco_core.component import Component
from coco_core.policy import BufferPolicy, ConnectionPolicy
from coco_core.ports import InputPort, OutputPort
from coco_core.stamps import Stamp, Stamped
from coco_core.transforms.interface import TransformationInterface
from coco_core.transforms.samples import FramePose, JointSample


class Source(Component):
    out = OutputPort(object)


def test_frame_pose_becomes_an_edge_and_unnamed_one_is_ignored():
    app = Application("fp")
    source = app.add(Source("source"))
    tf = app.add(TransformationInterface("tf", publish=["bowl=base:bowl"]), TriggeredActivity("tf"))
    app.connect("source.out", "tf.transform")
    T = np.eye(4)
    T[:3, 3] = (0.7, 0.2, -0.15)
    app.start()
    try:
        source.out.write(FramePose("base", "", np.eye(4), 1.0))  # no child frame: logged, ignored
        source.out.write(FramePose("base", "bowl", T, 2.0))
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and "bowl" not in app.transforms.frames:
            time.sleep(0.01)
        np.testing.assert_allclose(app.transforms.lookup("base", "bowl"), T)
        assert "" not in app.transforms.frames
    finally:
        app.stop()



BAXTER = "package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"
QUEUE = ConnectionPolicy(BufferPolicy.BUFFER, size=64)


class StampedSource(Component):
    out = OutputPort(Stamped)


class Collector(Component):
    """Collects what arrives on its port, in its own activity."""

    values = InputPort(object, event=True)

    def init(self) -> None:
        self.got: list = []

    def on_update(self) -> None:
        self.got.extend(self.values.read_all())


def wait(condition, timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not condition():
        time.sleep(0.01)
    assert condition(), "timed out"


def test_wait_for_joints_publishes_no_zero_joint_pose_and_stamps_travel_through_the_graph():
    """The teleop app's interface: no gripper pose before the first joint state (a static lookup is
    published at start), and each published lookup carries the Stamp and ROS time of its cause."""
    app = Application("wait")
    app.transforms.add_static("base", "bowl", np.eye(4))
    source = app.add(StampedSource("source"))
    app.add(TransformationInterface("tf", urdf=BAXTER, publish=["gripper=base:left_gripper", "bowl=base:bowl"],
                                    stamped=True, wait_for_joints=True), TriggeredActivity("tf"))
    grippers = app.add(Collector("grippers"), TriggeredActivity("grippers"))
    bowls = app.add(Collector("bowls"), TriggeredActivity("bowls"))
    app.connect("source.out", "tf.joints", QUEUE)
    app.connect("tf.gripper", "grippers.values", QUEUE)
    app.connect("tf.bowl", "bowls.values", QUEUE)
    app.start()
    try:
        wait(lambda: bowls.got)
        time.sleep(0.2)
        assert grippers.got == [], "the URDF's zero-joint pose was published before any joint state"
        [bowl] = bowls.got
        assert isinstance(bowl, Stamped) and bowl.value.stamp is None  # known at start, caused by no input
        origin = Stamp.now(7, "/robot/joint_states")
        source.out.write(Stamped(JointSample(("left_s0",), np.array([0.3]), 1_700_000_000.5), origin))
        wait(lambda: grippers.got)
        expected = app.transforms.lookup("base", "left_gripper")
    finally:
        app.stop()
    [gripper] = grippers.got
    assert gripper.stamp == origin and gripper.value.stamp == 1_700_000_000.5
    np.testing.assert_allclose(gripper.value.transform, expected, atol=1e-12)
