"""EndEffectorDistance (UpdateColorCalc) and TeleopSummary, unit and in-process application tests."""

from __future__ import annotations

import csv
import json
import math
import time

import numpy as np
import pytest
from coco_core.activity import PeriodicActivity
from coco_core.application import Application
from coco_core.component import Component
from coco_core.policy import BufferPolicy, ConnectionPolicy
from coco_core.ports import InputPort, OutputPort
from coco_core.stamps import Stamp, Stamped
from coco_core.transforms.samples import FramePose

from coco_ros.teleop import EndEffectorDistance, TeleopSummary, distance_color
from coco_ros.teleop.distance import frame_distance

BUFFER = ConnectionPolicy(BufferPolicy.BUFFER, size=1000)


def pose(x: float, y: float = 0.0, z: float = 0.0, stamp: float | None = None, source: str = "") -> FramePose:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return FramePose("base", source, T, stamp)


@pytest.mark.parametrize("d, rgb", [
    (0.0, (0.0, 1.0, 0.0)), (0.02, (0.0, 1.0, 0.0)), (0.26, (1.0, 1.0, 0.0)),
    (0.5, (1.0, 0.0, 0.0)), (3.0, (1.0, 0.0, 0.0)), (0.14, (0.5, 1.0, 0.0)), (0.38, (1.0, 0.5, 0.0)),
])
def test_color_map_green_yellow_red(d, rgb):
    np.testing.assert_allclose(distance_color(d), rgb, atol=1e-12)


def test_color_map_is_monotonic_and_custom_thresholds():
    ds = np.linspace(0, 1, 201)
    reds = [distance_color(d, 0.1, 0.9)[0] for d in ds]
    greens = [distance_color(d, 0.1, 0.9)[1] for d in ds]
    assert reds == sorted(reds) and greens == sorted(greens, reverse=True)
    assert distance_color(0.1, 0.1, 0.9) == (0.0, 1.0, 0.0)
    assert distance_color(0.5, 0.1, 0.9) == (1.0, 1.0, 0.0)
    assert distance_color(math.nan) == (1.0, 0.0, 0.0)
    with pytest.raises(ValueError):
        distance_color(0.1, 0.5, 0.5)


def test_frame_distance_uses_translations_only():
    a = pose(0.3, 0.4)
    b = FramePose("base", "bowl", np.diag([-1.0, -1.0, 1.0, 1.0]))  # rotated, at the origin
    assert frame_distance(a, b) == pytest.approx(0.5)


class Feeder(Component):
    """Writes (gripper, bowl) pairs, one per update, then asks the application to stop."""

    gripper = OutputPort(FramePose)
    bowl = OutputPort(FramePose)

    def init(self) -> None:
        self.steps = [(pose(0.1 * (10 - i), stamp=100.0 + i), pose(0.0, stamp=100.0 + i, source="bowl"))
                      for i in range(11)]
        self.i = 0

    def on_update(self) -> None:
        if self.i < len(self.steps):
            gripper, bowl = self.steps[self.i]
            self.gripper.write(gripper)
            self.bowl.write(bowl)
            self.i += 1
        elif self.i == len(self.steps) + 20 and self.app is not None:
            self.app.request_stop("fed")
        else:
            self.i += 1


def test_distance_and_summary_in_an_application(tmp_path):
    app = Application("teleop")
    feeder = app.add(Feeder("feeder"))
    distance = app.add(EndEffectorDistance("distance", near=0.05))
    summary = app.add(TeleopSummary("summary", csv=tmp_path / "d.csv", json=tmp_path / "s.json", near=0.05,
                                    time_origin=100.0))
    app.connect("feeder.gripper", "distance.gripper", BUFFER)
    app.connect("feeder.bowl", "distance.bowl", BUFFER)
    for port in ("distance", "color", "bag_time"):
        app.connect(f"distance.{port}", f"summary.{port}", BUFFER)
    app.connect("feeder.bowl", "summary.bowl")
    app.connect("feeder.gripper", "summary.target")
    activity = PeriodicActivity("loop", 0.005)
    for component in (feeder, distance, summary):
        app.schedule(component, activity)
    app.run(duration=10)
    assert app.stop_reason.endswith("fed"), app.stop_reason
    with (tmp_path / "d.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 11
    assert [float(r["distance"]) for r in rows] == pytest.approx([0.1 * (10 - i) for i in range(11)])
    assert [float(r["time"]) for r in rows] == pytest.approx(list(range(11)))
    assert (float(rows[-1]["r"]), float(rows[-1]["g"])) == (0.0, 1.0)
    assert all(float(r["latency_ms"]) >= 0 for r in rows)
    result = json.loads((tmp_path / "s.json").read_text())
    assert result["samples"] == 11
    assert result["min_distance"] == pytest.approx(0.0, abs=1e-12)
    assert result["min_distance_time"] == pytest.approx(10.0)
    assert result["grasp_time"] == pytest.approx(10.0)  # first distance below 0.05
    assert result["final_distance"] == pytest.approx(0.0, abs=1e-12)
    assert result["final_bowl_target_distance"] == pytest.approx(0.0, abs=1e-12)
    assert distance.stats.latency.count == 11 and summary.stats.latency.count == 11


class StampedSink(Component):
    values = InputPort(Stamped)

    def init(self) -> None:
        self.got: list = []

    def on_update(self) -> None:
        self.got.extend(self.values.read_all())


class StampedFeeder(Component):
    """Writes one gripper and one bowl pose, each Stamped at an origin upstream, once."""

    gripper = OutputPort(Stamped)
    bowl = OutputPort(Stamped)

    def init(self) -> None:
        self.origins = (Stamp.now(41, "/robot/joint_states"), Stamp.now(42, "/bowl/pose"))
        self.done = False

    def on_update(self) -> None:
        if not self.done:
            self.done = True
            self.gripper.write(Stamped(pose(0.3, stamp=100.0), self.origins[0]))
            self.bowl.write(Stamped(pose(0.0, stamp=100.5, source="bowl"), self.origins[1]))


def test_stamped_inputs_give_the_latency_from_their_origin():
    app = Application("stamped")
    feeder = app.add(StampedFeeder("feeder"))
    distance = app.add(EndEffectorDistance("distance"))
    sink = app.add(StampedSink("sink"))
    app.connect("feeder.gripper", "distance.gripper", BUFFER)
    app.connect("feeder.bowl", "distance.bowl", BUFFER)
    app.connect("distance.bag_time", "sink.values", BUFFER)
    activity = PeriodicActivity("loop", 0.005)
    for component in (feeder, distance, sink):
        app.schedule(component, activity)
    time.sleep(0.05)  # the origins are older than the application's start
    app.start()
    try:
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and not sink.got:
            time.sleep(0.01)
    finally:
        app.stop()
    [sample] = sink.got
    oldest = feeder.origins[0]
    assert sample.value == 100.5  # the newest ROS stamp of the poses
    assert (sample.stamp.time, sample.stamp.seq, sample.stamp.source) == (oldest.time, 1, "/robot/joint_states")
    assert distance.stats.latency.count == 1 and distance.stats.latency.mean >= 0.05


class BurstFeeder(Component):
    """Writes a bowl pose and a burst of gripper poses (one of them a repeat) in a single update, as a
    replay at full speed does, so the distance finds them all waiting at once."""

    gripper = OutputPort(Stamped)
    bowl = OutputPort(Stamped)
    xs = (0.5, 0.4, 0.4, 0.3, 0.2)

    def init(self) -> None:
        self.done = False

    def on_update(self) -> None:
        if not self.done:
            self.done = True
            self.bowl.write(Stamped(pose(0.0, source="bowl"), Stamp.now(1, "/bowl/pose")))
            for seq, x in enumerate(self.xs, start=2):
                self.gripper.write(Stamped(pose(x, source="gripper"), Stamp.now(seq, "/robot/joint_states")))


def test_every_pose_that_changed_gives_one_sample_even_when_they_wait_together():
    app = Application("burst")
    feeder = app.add(BurstFeeder("feeder"))
    distance = app.add(EndEffectorDistance("distance"))
    sink = app.add(StampedSink("sink"))
    gripper = app.connect("feeder.gripper", "distance.gripper", BUFFER)
    app.connect("feeder.bowl", "distance.bowl", BUFFER)
    app.connect("distance.distance", "sink.values", BUFFER)
    activity = PeriodicActivity("loop", 0.005)
    for component in (feeder, distance, sink):
        app.schedule(component, activity)
    app.start()
    try:
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and len(sink.got) < 4:
            time.sleep(0.01)
        time.sleep(0.05)
    finally:
        app.stop()
    # The repeated 0.4 changed nothing: four samples, in order, each stamped by the pose that made it.
    assert [sample.value for sample in sink.got] == pytest.approx([0.5, 0.4, 0.3, 0.2])
    assert [sample.stamp.seq for sample in sink.got] == [1, 2, 3, 4]
    assert gripper.counters() == {"written": 5, "read": 5, "dropped": 0, "pending": 0}


class LateBowlFeeder(Component):
    """Writes gripper poses and then a bowl pose stamped after them (a bowl pose published at the
    configuration by a reader configured after the replay began): only the last gripper pose can
    reach the first sample."""

    gripper = OutputPort(Stamped)
    bowl = OutputPort(Stamped)
    xs = (0.5, 0.4, 0.3, 0.2)

    def init(self) -> None:
        self.done = False

    def on_update(self) -> None:
        if not self.done:
            self.done = True
            for seq, x in enumerate(self.xs, start=1):
                self.gripper.write(Stamped(pose(x, source="gripper"), Stamp.now(seq, "/robot/joint_states")))
            self.bowl.write(Stamped(pose(0.0, source="bowl"), Stamp.now(0, "tf")))


def test_poses_superseded_before_a_sample_are_counted_as_merged_in_the_profile():
    from coco_core.report import profile_report

    app = Application("late_bowl")
    feeder = app.add(LateBowlFeeder("feeder"))
    distance = app.add(EndEffectorDistance("distance"))
    sink = app.add(StampedSink("sink"))
    app.connect("feeder.gripper", "distance.gripper", BUFFER)
    app.connect("feeder.bowl", "distance.bowl", BUFFER)
    app.connect("distance.distance", "sink.values", BUFFER)
    activity = PeriodicActivity("loop", 0.005)
    for component in (feeder, distance, sink):
        app.schedule(component, activity)
    app.start()
    try:
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and not sink.got:
            time.sleep(0.01)
    finally:
        app.stop()
    assert [sample.value for sample in sink.got] == pytest.approx([0.2])
    assert distance.stats.merged == 3  # 0.5, 0.4 and 0.3: read, never shown; four poses, one row
    report = profile_report(app).splitlines()
    header = next(line for line in report if line.startswith("component "))
    row = next(line for line in report if line.startswith("distance "))
    column = header.index(" merged ") + 1
    assert row[column:].split()[0] == "3"


class SampleSource(Component):
    """Writes what EndEffectorDistance writes for one sample, and a display latency, per call."""

    distance = OutputPort(Stamped)
    color = OutputPort(Stamped)
    bag_time = OutputPort(Stamped)
    latency = OutputPort(Stamped)

    def init(self) -> None:
        self.seq = 0

    def emit(self) -> None:
        self.seq += 1
        stamp = Stamp.now(self.seq, "/robot/joint_states")
        self.distance.write(Stamped(0.1 + 1e-6 * self.seq, stamp))
        self.color.write(Stamped((1.0, 0.0, 0.0), stamp))
        self.bag_time.write(Stamped(100.0 + 1e-3 * self.seq, stamp))
        self.latency.write(Stamped(0.02 + 1e-7 * self.seq, stamp))


def test_the_summary_keeps_its_size_however_long_the_run(tmp_path):
    """Issue 23: the Baxter app looped for ten minutes grew by megabytes a minute, the summary's lists
    of every latency (and the pages they pinned). Its memory no longer grows with the samples."""
    import tracemalloc

    app = Application("long")
    source = app.add(SampleSource("source"))
    summary = app.add(TeleopSummary("summary", csv=tmp_path / "d.csv", json=tmp_path / "s.json"))
    for port in ("distance", "color", "bag_time"):
        app.connect(f"source.{port}", f"summary.{port}", BUFFER)
    app.connect("source.latency", "summary.display_latency", BUFFER)
    summary.configure()

    def run(samples: int) -> None:
        for _ in range(samples):
            source.emit()
            summary.on_update()

    run(2_000)  # the CSV writer's buffers, the histogram, the first latencies
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        run(10_000)
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    summary.stop()
    assert grown < 100_000, f"{grown} bytes more after 10,000 samples"  # a list of them: 320 kB or more
    result = json.loads((tmp_path / "s.json").read_text())
    assert result["samples"] == 12_000 and result["display_latency_ms"]["frames"] == 12_000
    assert result["display_latency_ms"]["median"] == pytest.approx(20 + 1e-4 * 6_000, rel=0.005)
