"""Sensor-to-display latency: every frame GLManager renders carries the stamp of the oldest input it is
the first to show (a stamped port value, or the origin the graph keeps on an edge or robot), and the
frames that show a new input give their latency on ``latency`` and in the manager's profile."""

from __future__ import annotations

import time

import numpy as np

from coco_core import Application
from coco_core.component import Component
from coco_core.policy import BufferPolicy, ConnectionPolicy
from coco_core.ports import InputPort, OutputPort
from coco_core.stamps import Stamp, Stamped
from coco_core.transforms.interface import TransformationInterface
from coco_core.transforms.samples import FramePose, TransformSample
from coco_mr_display.camera import GLCameraManager
from coco_mr_display.entity import GLEntity
from coco_mr_display.manager import GLManager
from coco_mr_display.update_color import UpdateColor


class Inputs(Component):
    """What the teleop app feeds the view: a stamped colour, and a stamped pose for an entity."""

    color = OutputPort(Stamped)
    pose = OutputPort(Stamped)


class Collected(Component):
    frames = InputPort(Stamped)
    latency = InputPort(Stamped)


def scene(color_policy: ConnectionPolicy | None = None) -> tuple[Application, GLManager, Inputs, Collected]:
    app = Application("latency-test")
    manager = GLManager("display", width=64, height=48, stamped=True, world="base")
    manager.add_peer(GLCameraManager("camera", position=[0.0, -3.0, 0.0], look_at=[0.0, 0.0, 0.0]))
    bowl = GLEntity("bowl", mesh="sphere", frame="bowl")
    bowl.add_peer(UpdateColor("bowl_color"))
    manager.add_peer(bowl)
    manager.add_peer(GLEntity("marker", mesh="box", size=[0.1, 0.1, 0.1]))
    inputs, collected = Inputs("inputs"), Collected("collected")
    for component in (manager, inputs, collected):
        app.add(component)
    app.connect("inputs.color", "bowl_color.color", color_policy)
    app.connect("inputs.pose", "marker.pose")
    app.connect("display.color", "collected.frames")
    app.connect("display.latency", "collected.latency")
    app.transforms.add_frame("base")
    return app, manager, inputs, collected


def origin_of(stamp: Stamp) -> tuple[float, int, str]:
    """A frame stamp's origin and number, without the steps of its way (see the next test)."""
    return stamp.time, stamp.seq, stamp.source


def test_each_frame_is_stamped_with_the_oldest_input_it_shows_first():
    app, manager, inputs, collected = scene()
    graph = app.transforms
    assert manager.configure(), "GLManager failed to configure (see the log)"
    try:
        # Frame 1: the bowl's edge written with a known origin, and an older stamped colour.
        bowl_origin = Stamp.now(7, "/bowl/pose")
        graph.set_transform("base", "bowl", np.eye(4), 1.0, cause=bowl_origin)
        colour_origin = Stamp(bowl_origin.time - 0.010, 3, "distance")
        inputs.color.write(Stamped((0.0, 1.0, 0.0), colour_origin))
        manager.step()
        [frame] = collected.frames.read_all()
        assert origin_of(frame.stamp) == (colour_origin.time, 1, "distance")  # the older of the two
        [latency] = collected.latency.read_all()
        assert latency.stamp.steps[:-1] == frame.stamp.steps  # the same frame, then read back
        assert origin_of(latency.stamp) == origin_of(frame.stamp) and latency.value >= 0.010
        assert manager.stats.latency.count == 1

        # Frame 2: nothing new reaches the screen: stamped at render time, no latency recorded.
        before = time.perf_counter()
        manager.step()
        [frame] = collected.frames.read_all()
        assert frame.stamp.source == "display" and frame.stamp.seq == 2 and frame.stamp.time >= before
        assert collected.latency.read_all() == [] and manager.stats.latency.count == 1

        # Frame 3: a stamped pose of the marker, and the bowl moved again by a newer input.
        pose_origin = Stamp.now(11, "/marker")
        inputs.pose.write(Stamped(FramePose("base", "marker", np.eye(4), 2.0), pose_origin))
        moved = np.eye(4)
        moved[0, 3] = 0.1
        graph.set_transform("base", "bowl", moved, 2.0, cause=Stamp.now(8, "/bowl/pose"))
        manager.step()
        [frame] = collected.frames.read_all()
        assert origin_of(frame.stamp) == (pose_origin.time, 3, "/marker")
        assert manager.stats.latency.count == 2
    finally:
        manager.stop()


def test_a_frame_stamp_keeps_the_inputs_way_and_adds_frame_start_drawn_and_read_back():
    """The latency split by step: the input's steps (e.g. the stream's sent and received) are kept in
    the frame's stamp, followed by the frame's own, in time order."""
    app, manager, inputs, collected = scene()
    assert manager.configure(), "GLManager failed to configure (see the log)"
    try:
        origin = Stamp.now(3, "camera").step("sent").step("received")
        inputs.color.write(Stamped((0.0, 1.0, 0.0), origin))
        manager.step()
        [latency] = collected.latency.read_all()
    finally:
        manager.stop()
    stamp = latency.stamp
    assert (stamp.time, stamp.source) == (origin.time, "camera")
    assert [name for name, _ in stamp.steps] == ["sent", "received", "frame_start", "drawn", "read_back"]
    times = [stamp.time, *(at for _, at in stamp.steps)]
    assert times == sorted(times)
    assert latency.value >= stamp.steps[-1][1] - stamp.time
    [frame] = collected.frames.read_all()
    assert frame.stamp.steps == stamp.steps[:-1], "the image goes out before its read-back is stamped"


def test_a_display_reading_the_newest_counts_the_skipped_inputs_as_dropped():
    app, manager, inputs, collected = scene(ConnectionPolicy(BufferPolicy.BUFFER, size=16))
    assert manager.configure()
    try:
        for seq in range(5):
            inputs.color.write(Stamped((0.0, 1.0, 0.0), Stamp.now(seq, "distance")))
        manager.step()
    finally:
        manager.stop()
    connection = next(c for c in app.connections if c.sink is not None and c.sink.name == "color")
    assert connection.counters() == {"written": 5, "read": 1, "dropped": 4, "pending": 0}


class PlainInputs(Component):
    """A producer that writes plain values (no ``Stamped``): their message stamps are their origins."""

    color = OutputPort(tuple)
    pose = OutputPort(FramePose)


def test_a_plain_input_is_timed_from_its_message_stamp():
    """A colour and a pose written as plain values: the frame that first shows them is stamped with
    the older message's stamp (its write: time, number on its port, the writing port), and its
    latency reaches ``latency`` and the manager's profile, as a ``Stamped`` input's does."""
    app = Application("plain-latency-test")
    manager = GLManager("display", width=64, height=48, stamped=True, world="base")
    manager.add_peer(GLCameraManager("camera", position=[0.0, -3.0, 0.0], look_at=[0.0, 0.0, 0.0]))
    bowl = GLEntity("bowl", mesh="sphere")
    bowl.add_peer(UpdateColor("bowl_color"))
    manager.add_peer(bowl)
    manager.add_peer(GLEntity("marker", mesh="box", size=[0.1, 0.1, 0.1]))
    inputs, collected = PlainInputs("inputs"), Collected("collected")
    for component in (manager, inputs, collected):
        app.add(component)
    app.connect("inputs.color", "bowl_color.color")
    app.connect("inputs.pose", "marker.pose")
    app.connect("display.color", "collected.frames")
    app.connect("display.latency", "collected.latency")
    app.transforms.add_frame("base")
    assert manager.configure(), "GLManager failed to configure (see the log)"
    try:
        inputs.color.write((0.0, 1.0, 0.0))
        written = inputs.color.stamp
        inputs.pose.write(FramePose("base", "marker", np.eye(4), 2.0))
        assert written is not None and inputs.pose.stamp is not None and inputs.pose.stamp.time >= written.time
        manager.step()
        [frame] = collected.frames.read_all()
        assert (frame.stamp.time, frame.stamp.source) == (written.time, "inputs.color"), frame.stamp
        [latency] = collected.latency.read_all()
        assert latency.stamp.time == written.time and latency.value >= latency.stamp.steps[-1][1] - written.time
        assert manager.stats.latency.count == 1 and bowl.peers[0].stats.latency.count == 1

        manager.step()  # nothing new: no latency, as for stamped inputs
        assert collected.latency.read_all() == [] and manager.stats.latency.count == 1
    finally:
        manager.stop()


class PlainTransforms(Component):
    tf = OutputPort(TransformSample)


def test_a_plain_transform_into_the_graph_is_timed_from_its_message_stamp():
    """A plain TransformSample written to a TransformationInterface: the edge it changes keeps the
    sample's message stamp as its cause, and the frame that first shows the moved entity is stamped
    with it (latency-to-pixel through the graph, from the write in the producer)."""
    app, manager, inputs, collected = scene()
    feeder, interface = PlainTransforms("feeder"), TransformationInterface("interface")
    app.add(feeder)
    app.add(interface)
    app.connect("feeder.tf", "interface.transform")
    assert manager.configure(), "GLManager failed to configure (see the log)"
    try:
        feeder.tf.write(TransformSample("base", "bowl", np.eye(4), 1.0))
        written = feeder.tf.stamp
        interface.on_update()
        manager.step()
        [frame] = collected.frames.read_all()
        assert written is not None and (frame.stamp.time, frame.stamp.source) == (written.time, "feeder.tf")
        assert manager.stats.latency.count == 1
    finally:
        manager.stop()
