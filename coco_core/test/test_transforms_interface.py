"""TransformationInterface in a running application: samples and joint states arriving on its ports
update the graph; ``outputs`` publish FramePose on every change to components in other activities;
its ``lookup`` operation answers from any activity; a URDF given as attribute is driven by
JointSample messages.
"""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest

from coco_core import (
    AttributeValueError,
    BufferPolicy,
    CocoError,
    Component,
    ConnectionPolicy,
    InputPort,
    OutputPort,
    PeriodicActivity,
    TriggeredActivity,
    operation,
)
from coco_core.transforms import ExtrapolationError, TransformError, se3
from coco_core.transforms.interface import TransformationInterface, parse_output
from coco_core.transforms.samples import FramePose, JointSample, TransformSample
from geometry import rot_z, homogeneous

TOL = 1e-12
QUEUE = ConnectionPolicy(data=BufferPolicy.BUFFER, size=256)
"""Every sample and every pose must arrive: a buffer, not the default latest-value connection."""


class Source(Component):
    """Writes what the test hands it, from its own (triggered) activity."""

    tf = OutputPort(object)
    js = OutputPort(JointSample)

    def init(self) -> None:
        self.thread: int | None = None

    @operation
    def emit(self, port: str, value) -> None:
        self.thread = threading.get_ident()
        getattr(self, port).write(value)

    @operation
    def write_graph(self, parent: str, child: str, transform: np.ndarray, stamp: float) -> None:
        """Write the application's graph directly (not through the interface's ports)."""
        self.transform_graph.set_transform(parent, child, transform, stamp)


class Sink(Component):
    """Collects the FramePose values it receives, with the thread that received them."""

    pose = InputPort(FramePose, event=True)

    def init(self) -> None:
        self.received: list[FramePose] = []
        self.threads: set[int] = set()
        self.lock = threading.Lock()

    def _drain(self) -> None:
        for value in self.pose.read_all():
            with self.lock:
                self.received.append(value)
                self.threads.add(threading.get_ident())

    def on_update(self) -> None:
        self._drain()

    @operation
    def collected(self) -> list[FramePose]:
        """Everything received so far, including what waits on the port (read in the sink's thread)."""
        self._drain()
        with self.lock:
            return list(self.received)

    def count(self) -> int:
        with self.lock:
            return len(self.received)


class Client(Component):
    """Calls the interface's ``lookup`` from its first update (another, periodic activity)."""

    def init(self) -> None:
        self.request: tuple | None = None
        self.futures: list = []
        self.done = threading.Event()
        self.thread: int | None = None

    def on_update(self) -> None:
        if self.request is None or self.done.is_set():
            return
        self.thread = threading.get_ident()
        interface = self.find_component("tf")
        for args in self.request:
            self.futures.append(interface.operation("lookup")(*args))
        self.done.set()


def build(make_app, outputs=(), **attributes):
    """source (triggered) -> tf (triggered) -> sink (triggered), each in its own activity."""
    app = make_app("transforms")
    source = app.add(Source("source"), TriggeredActivity("source"))
    interface = app.add(TransformationInterface("tf", publish=list(outputs), **attributes), TriggeredActivity("tf"))
    sink = app.add(Sink("sink"), TriggeredActivity("sink"))
    app.connect("source.tf", "tf.transform", QUEUE)
    app.connect("source.js", "tf.joints", QUEUE)
    for spec in outputs:
        port = spec.partition("=")[0]
        app.connect(f"tf.{port}", "sink.pose", QUEUE)
    return app, source, interface, sink


def send(source: Source, port: str, value) -> None:
    source.call("emit", port, value).result(timeout=2.0)


def transform(x=0.0, y=0.0, z=0.0, yaw=0.0) -> np.ndarray:
    return homogeneous(rot_z(yaw), (x, y, z))


# --- the outputs attribute ------------------------------------------------------------------------------

def test_parse_output():
    assert parse_output("gripper=base:tool") == ("gripper", "base", "tool")
    assert parse_output(" gripper = base : left_tool ") == ("gripper", "base", "left_tool")
    for bad in ("gripper", "gripper=base", "=base:tool", "gripper=:tool", "gripper=base:", "base:tool"):
        with pytest.raises(ValueError, match="port=target:source"):
            parse_output(bad)


@pytest.mark.parametrize("value", [["gripper=base"], ["ok=a:b", "broken:a"], "gripper=base:tool nonsense"])
def test_invalid_outputs_spec_names_the_attribute(value):
    with pytest.raises(AttributeValueError) as raised:
        TransformationInterface("tf", publish=value)
    message = str(raised.value)
    assert "tf.publish" in message
    assert "port=target:source" in message
    interface = TransformationInterface("tf2")
    with pytest.raises(AttributeValueError, match="tf2.publish"):
        interface.set_attribute_now("publish", value)


def test_outputs_attribute_declares_output_ports(make_app):
    app = make_app("ports")
    interface = app.add(TransformationInterface("tf", publish="gripper=base:tool, camera=world:cam"))
    assert interface.call("get_attribute", "publish").result(0) == ["gripper=base:tool", "camera=world:cam"]
    gripper = interface.port("gripper")
    assert isinstance(gripper, OutputPort) and gripper.type is FramePose
    assert isinstance(interface.port("camera"), OutputPort)
    assert set(interface.inputs) == {"transform", "joints"}


def test_two_outputs_with_one_port_name_are_an_error(make_app):
    app = make_app("twice")
    with pytest.raises(CocoError, match="gripper"):
        app.add(TransformationInterface("tf", publish=["gripper=base:tool", "gripper=base:cam"]))


# --- data flow -------------------------------------------------------------------------------------------

def test_samples_update_the_graph_and_the_output_publishes_every_change(make_app, wait_until):
    app, source, interface, sink = build(make_app, outputs=["gripper=base:tool"])
    app.start()
    graph = app.transforms
    # the whole path in one message (a list of samples)
    base_arm, arm_tool = transform(1, 0, 0, yaw=math.pi / 2), transform(0, 2, 0)
    send(source, "tf", [TransformSample("base", "arm", base_arm, 1.0), TransformSample("arm", "tool", arm_tool, 1.0)])
    assert wait_until(lambda: sink.count() >= 1)
    expected = [base_arm @ arm_tool]
    for step in range(1, 6):
        arm_tool = transform(0, 2 + step, 0.1 * step, yaw=0.2 * step)
        send(source, "tf", TransformSample("arm", "tool", arm_tool, 1.0 + step))
        expected.append(base_arm @ arm_tool)
        assert wait_until(lambda: sink.count() >= len(expected))
    received = sink.call("collected").result(timeout=2.0)
    assert len(received) == len(expected), "one FramePose per change"
    for pose, value in zip(received, expected):
        assert (pose.target, pose.source) == ("base", "tool")
        np.testing.assert_allclose(pose.transform, value, atol=TOL)
    np.testing.assert_allclose(graph.lookup("base", "tool"), expected[-1], atol=TOL)
    # every sample went into the history (base->arm has one sample only, at 1.0)
    np.testing.assert_allclose(graph.lookup("arm", "tool", time=5.5), se3.interpolate(
        transform(0, 6, 0.4, yaw=0.8), transform(0, 7, 0.5, yaw=1.0), 0.5), atol=1e-12)
    np.testing.assert_allclose(graph.lookup("base", "tool", time=1.0), base_arm @ transform(0, 2, 0), atol=1e-12)
    assert sink.threads and threading.get_ident() not in sink.threads
    assert source.thread not in sink.threads


def test_output_for_a_path_that_appears_after_start(make_app, wait_until):
    app, source, interface, sink = build(make_app, outputs=["gripper=base:tool"])
    app.start()
    graph = app.transforms
    send(source, "tf", TransformSample("base", "arm", transform(1, 0, 0), 1.0))
    assert wait_until(lambda: "arm" in graph.frames)
    # the interface finished that update (a queued call runs between updates), and nothing came out
    with pytest.raises(TransformError, match="unknown frame 'tool'"):
        interface.call("lookup", "base", "tool").result(timeout=2.0)
    assert sink.call("collected").result(timeout=2.0) == []
    send(source, "tf", TransformSample("arm", "tool", transform(0, 0, 3), 2.0))
    assert wait_until(lambda: sink.count() >= 1)
    pose, = sink.call("collected").result(timeout=2.0)
    np.testing.assert_allclose(pose.transform, transform(1, 0, 3), atol=TOL)
    # and from then on every change
    send(source, "tf", TransformSample("base", "arm", transform(2, 0, 0), 3.0))
    assert wait_until(lambda: sink.count() >= 2)
    np.testing.assert_allclose(sink.call("collected").result(timeout=2.0)[1].transform, transform(2, 0, 3), atol=TOL)


def test_output_for_a_path_completed_by_another_writer_of_the_graph(make_app, wait_until):
    """Components may write the shared graph directly (a registration installs a static edge): an
    output whose path appears that way is published too, without waiting for data on the
    interface's own ports."""
    app, source, interface, sink = build(make_app, outputs=["gripper=base:tool"])
    app.start()
    send(source, "tf", TransformSample("base", "arm", transform(1, 0, 0), 1.0))
    assert wait_until(lambda: "arm" in app.transforms.frames)
    source.call("write_graph", "arm", "tool", transform(0, 1, 0), 2.0).result(timeout=2.0)
    assert wait_until(lambda: sink.count() >= 1, timeout=1.5), "the output never published"
    np.testing.assert_allclose(sink.call("collected").result(timeout=2.0)[0].transform, transform(1, 1, 0), atol=TOL)


def test_a_new_unrelated_frame_does_not_republish_an_output(make_app, wait_until):
    """Only changes on the output's path publish: a tracker that starts sending a new object must
    not make every output send its unchanged pose again."""
    app, source, interface, sink = build(make_app, outputs=["gripper=base:tool"])
    app.start()
    send(source, "tf", [TransformSample("base", "arm", transform(1, 0, 0), 1.0),
                        TransformSample("arm", "tool", transform(0, 1, 0), 1.0)])
    assert wait_until(lambda: sink.count() >= 1)
    send(source, "tf", TransformSample("camera", "marker", transform(0, 0, 1), 2.0))
    assert wait_until(lambda: "marker" in app.transforms.frames)
    send(source, "tf", TransformSample("arm", "tool", transform(0, 2, 0), 3.0))
    assert wait_until(lambda: sink.count() >= 2)
    interface.call("lookup", "base", "tool").result(timeout=2.0)  # the interface is past that update
    poses = sink.call("collected").result(timeout=2.0)
    assert [pose.transform[1, 3] for pose in poses] == [1.0, 2.0], "one pose per change on the path"


def test_joint_samples_drive_axis_edges_and_outputs(make_app, wait_until):
    app, source, interface, sink = build(make_app, outputs=["hand=base:hand"])
    graph = app.transforms
    graph.add_axis("base", "upper", "shoulder", "revolute", origin=transform(0, 0, 1))
    graph.add_axis("upper", "hand", "slide", "prismatic", axis=(1, 0, 0))
    app.start()
    # The path exists at start: its pose (both joints at 0) is published first.
    assert wait_until(lambda: sink.count() >= 1)
    np.testing.assert_allclose(sink.call("collected").result(timeout=2.0)[0].transform, transform(0, 0, 1), atol=TOL)
    send(source, "js", JointSample(("shoulder", "slide", "unknown"), np.array([0.5, 2.0, 9.0])))
    assert wait_until(lambda: sink.count() >= 2)
    poses = sink.call("collected").result(timeout=2.0)
    assert len(poses) == 2
    expected = transform(0, 0, 1) @ homogeneous(rot_z(0.5)) @ transform(2, 0, 0)
    np.testing.assert_allclose(poses[-1].transform, expected, atol=TOL)
    np.testing.assert_allclose(poses[-1].transform[:3, 3], [2 * math.cos(0.5), 2 * math.sin(0.5), 1.0], atol=TOL)
    # one JointState changing both joints is one change
    send(source, "js", JointSample(("shoulder", "slide"), np.array([-0.5, 1.0])))
    assert wait_until(lambda: sink.count() >= len(poses) + 1)
    after = sink.call("collected").result(timeout=2.0)
    assert len(after) == len(poses) + 1
    np.testing.assert_allclose(after[-1].transform[:3, 3], [math.cos(-0.5), math.sin(-0.5), 1.0], atol=TOL)


# --- the lookup operation ----------------------------------------------------------------------------------

def test_lookup_operation_from_another_activity(make_app, wait_until):
    app, source, interface, sink = build(make_app)
    client = app.add(Client("client"), PeriodicActivity("client", 0.005))
    app.transforms.add_static("base", "arm", transform(1, 2, 3, yaw=0.3))
    send_later = [TransformSample("arm", "tool", transform(0, 0, 1), 10.0),
                  TransformSample("arm", "tool", transform(0, 0, 3), 12.0)]
    app.start()
    send(source, "tf", send_later)
    assert wait_until(lambda: "tool" in app.transforms.frames and
                      app.transforms.edge("arm", "tool").time_range == (10.0, 12.0))
    client.request = [("base", "tool"), ("tool", "base"), ("base", "tool", 11.0), ("base", "nowhere"),
                      ("base", "tool", 99.0)]
    assert client.done.wait(2.0)
    results = [future.exception(timeout=2.0) or future.result() for future in client.futures]
    base_tool = transform(1, 2, 3, yaw=0.3) @ transform(0, 0, 3)
    np.testing.assert_allclose(results[0], base_tool, atol=TOL)
    np.testing.assert_allclose(results[1], np.linalg.inv(base_tool), atol=TOL)
    np.testing.assert_allclose(results[2], transform(1, 2, 3, yaw=0.3) @ transform(0, 0, 2), atol=TOL)
    assert isinstance(results[3], TransformError) and "nowhere" in str(results[3])
    assert isinstance(results[4], ExtrapolationError) and "arm->tool" in str(results[4])
    assert client.thread is not None and client.thread != threading.get_ident()


def test_lookup_operation_from_many_threads_while_samples_arrive(make_app, wait_until):
    """Concurrent callers (outside any activity: queued to the interface) while a source streams
    samples: every answer is a sample that was written (translation (k, 0, 0) at step k)."""
    app, source, interface, sink = build(make_app)
    app.start()
    send(source, "tf", TransformSample("world", "object", transform(0, 0, 0), 0.0))
    assert wait_until(lambda: "object" in app.transforms.frames)
    problems: list[str] = []
    stop = threading.Event()

    def caller() -> None:
        while not stop.is_set():
            value = interface.call("lookup", "world", "object").result(timeout=2.0)
            x = value[0, 3]
            if x != round(x) or not np.array_equal(value[:3, :3], np.eye(3)):
                problems.append(repr(value))

    callers = [threading.Thread(target=caller, daemon=True) for _ in range(3)]
    for thread in callers:
        thread.start()
    for k in range(1, 60):
        source.call("emit", "tf", TransformSample("world", "object", transform(k, 0, 0), float(k)))
    assert wait_until(lambda: app.transforms.lookup("world", "object")[0, 3] == 59.0)
    stop.set()
    for thread in callers:
        thread.join(3.0)
        assert not thread.is_alive()
    assert problems == []


# --- URDF ----------------------------------------------------------------------------------------------------

ARM_URDF = """<?xml version="1.0"?>
<robot name="arm">
  <link name="base"/><link name="upper"/><link name="tool"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.5"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <joint name="flange" type="fixed">
    <parent link="upper"/><child link="tool"/><origin xyz="1 0 0"/>
  </joint>
</robot>
"""


def test_urdf_attribute_and_joint_samples_move_the_published_pose(make_app, wait_until, tmp_path):
    pytest.importorskip("pinocchio")
    path = tmp_path / "arm.urdf"
    path.write_text(ARM_URDF)
    app, source, interface, sink = build(make_app, outputs=["tip=r_base:r_tool"], urdf=str(path), prefix="r_")
    assert "r_tool" in app.transforms.frames, "the URDF is loaded when the component is added"
    app.start()
    # The pose known at start (every joint at 0) is published first, before anything moves.
    assert wait_until(lambda: sink.count() >= 1)
    initial = sink.call("collected").result(timeout=2.0)[0]
    np.testing.assert_allclose(initial.transform[:3, 3], [1.0, 0.0, 0.5], atol=1e-9)
    for count, q in enumerate((0.3, 0.7, -1.9), start=2):
        send(source, "js", JointSample(("shoulder",), np.array([q])))
        assert wait_until(lambda: sink.count() >= count)
        pose = sink.call("collected").result(timeout=2.0)[-1]
        assert (pose.target, pose.source) == ("r_base", "r_tool")
        np.testing.assert_allclose(pose.transform[:3, 3], [math.cos(q), math.sin(q), 0.5], atol=1e-9)
        np.testing.assert_allclose(pose.transform[:3, :3], rot_z(q), atol=1e-9)


def test_urdf_attribute_with_the_lookup_operation(make_app, wait_until, tmp_path):
    pytest.importorskip("pinocchio")
    path = tmp_path / "arm.urdf"
    path.write_text(ARM_URDF)
    app, source, interface, sink = build(make_app, urdf=str(path))
    app.start()
    send(source, "js", JointSample(("shoulder",), np.array([1.2])))
    assert wait_until(lambda: interface.model.positions["shoulder"] == 1.2)
    value = interface.call("lookup", "base", "tool").result(timeout=2.0)
    np.testing.assert_allclose(value, homogeneous(rot_z(1.2), (math.cos(1.2), math.sin(1.2), 0.5)), atol=1e-9)


# --- malformed samples (issue 14) ------------------------------------------------------------------

def test_a_refused_sample_does_not_discard_the_rest_of_its_cycle(make_app, wait_until):
    """Ten joint samples read in one cycle, the second bad (inf, then too few positions, then too
    many): the bad ones are refused and counted, the other eight are all applied in order."""
    app, source, interface, sink = build(make_app, outputs=["hand=base:hand"])
    app.transforms.add_axis("base", "hand", "shoulder", "revolute")
    app.start()
    assert wait_until(lambda: sink.count() >= 1)
    samples = [JointSample(("shoulder",), np.array([0.1 * i])) for i in range(10)]
    samples[1] = JointSample(("shoulder",), np.array([math.inf]))
    samples[4] = JointSample(("shoulder", "elbow"), np.array([0.3]))
    samples[6] = JointSample(("shoulder",), np.array([0.3, 0.4]))
    gate = threading.Event()
    app.activities["tf"].enqueue(lambda: gate.wait(5.0))  # hold the interface: one cycle reads all ten
    for sample in samples:
        send(source, "js", sample)
    gate.set()
    applied = [0.1 * i for i in range(10) if i not in (1, 4, 6)]
    assert wait_until(lambda: sink.count() >= len(applied))  # the first (0.0) changes nothing
    poses = sink.call("collected").result(timeout=2.0)[1:]
    angles = [math.atan2(p.transform[1, 0], p.transform[0, 0]) for p in poses]
    assert angles == pytest.approx(applied[1:])  # the first (0.0) leaves the zero pose as it was
    assert interface.stats.refused == 3
    connection = next(c for c in app.connections if c.sink is interface.joints)
    assert connection.counters()["read"] == 10 and connection.counters()["dropped"] == 0


def test_a_refused_joint_sample_makes_the_launch_fail(make_app, wait_until):
    """A NaN joint value refused by the interface (the Baxter replay's ``tf``) is damaged input: the
    launcher's exit status is 1, as the README says of refused input (it was counted, and exited 0)."""
    from coco_core.launcher import stopped_by_a_failure

    app, source, interface, _ = build(make_app, outputs=["hand=base:hand"])
    app.transforms.add_axis("base", "hand", "shoulder", "revolute")
    app.start()
    send(source, "js", JointSample(("shoulder",), np.array([math.nan])))
    assert wait_until(lambda: interface.stats.refused == 1)
    app.request_stop("test")
    assert app.stop()
    assert not app.damage and stopped_by_a_failure(app)


def test_non_finite_transform_samples_are_refused_and_counted(make_app, wait_until):
    app, source, interface, sink = build(make_app, outputs=["obj=world:obj"])
    app.start()
    good = TransformSample("world", "obj", transform(x=1.0), 1.0)
    nan_stamp = TransformSample("world", "obj", transform(x=2.0), math.nan)
    inf_matrix = TransformSample("world", "obj", transform(x=math.inf), 2.0)
    later = TransformSample("world", "obj", transform(x=3.0), 3.0)
    send(source, "tf", [good, nan_stamp, inf_matrix, later])
    assert wait_until(lambda: interface.stats.refused == 2 and sink.count() >= 2)
    assert app.transforms.edge("world", "obj").time_range == (1.0, 3.0)
    np.testing.assert_allclose(app.transforms.lookup("world", "obj")[:3, 3], [3.0, 0.0, 0.0])
