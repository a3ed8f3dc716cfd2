"""Components of ``bench_hosts.py``: a source of samples that carry the time of their writing, and a
sink that records when each arrived. Imported by ``module:Class`` in every host's launcher and its
child processes (the benchmark puts this folder on PYTHONPATH).

The write time travels inside the payload itself (the first number of a small sample, the images'
own stamp of a frame), so the latency needs nothing from the connection but the value: the same
figure for a connection between hosts, between processes, and for the plain rclpy anchor
(``_hosts_rclpy.py``). The hosts of the benchmark are network namespaces of one machine: the
monotonic clock is one clock for all of them.

Two phases: *latency*, ``latency`` samples one per update at the activity's period (the link never
saturated), then *burst*, ``burst`` samples written back to back in one update (throughput).
"""

from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from coco_core import Attribute, Component, InputPort, OutputPort

SMALL = 19
"""Numbers in a small sample: a 19-joint state, as ``sensor_msgs/JointState`` of the anchor."""
REDWOOD = Path(__file__).resolve().parents[2] / "shared" / "data" / "rgbd" / "redwood"
LATENCY, BURST = 0, 1


def redwood_frame() -> Any:
    """A real 640x480 RGB-D frame (JPEG and Zstandard see real content, not noise or zeros)."""
    from coco_mr_vision.image import CameraIntrinsics
    from coco_mr_vision.rgbd import RGBDFrame

    return RGBDFrame.load(REDWOOD / "color" / "00000.jpg", REDWOOD / "depth" / "00000.png",
                          CameraIntrinsics.from_json(REDWOOD / "camera_primesense.json"))


class Source(Component):
    """Writes the latency phase (one sample per update), then the burst (all in one update)."""

    kind = Attribute(str, "small", "small: 19 float64; frame: a 640x480 RGB-D frame", choices=("small", "frame"))
    latency = Attribute(int, 200, "samples of the latency phase, one per update", min=0)
    burst = Attribute(int, 500, "samples of the burst, back to back in one update", min=0)

    out = OutputPort(object, "the samples")

    def init(self) -> None:
        self.written = 0
        self.frame = redwood_frame() if self.kind == "frame" else None

    def on_update(self) -> None:
        if self.written < self.latency:
            self._write(LATENCY)
        elif self.written == self.latency:
            for _ in range(self.burst):
                self._write(BURST)

    def _write(self, phase: int) -> None:
        now = time.perf_counter()
        if self.frame is None:
            value: Any = np.zeros(SMALL)
            value[:3] = now, self.written, phase
        else:
            tag = f"{phase}:{self.written}"
            value = replace(self.frame, color=replace(self.frame.color, stamp=now, frame_id=tag),
                            depth=replace(self.frame.depth, stamp=now, frame_id=tag))
        self.out.write(value)
        self.written += 1


class Sink(Component):
    """Records (number, phase, written, received) of every sample; stops the application once the
    last one came, and writes the record to ``path`` when it stops."""

    path = Attribute(str, "record.json", "where the record goes (JSON)")
    last = Attribute(int, 0, "the number of the last sample: the application stops when it arrives", min=0)

    sample = InputPort(object, event=True, doc="the samples")

    def init(self) -> None:
        self.records: list[tuple[int, int, float, float]] = []

    def on_update(self) -> None:
        received = time.perf_counter()
        for value in self.sample.read_all():
            if isinstance(value, np.ndarray):
                written, number, phase = float(value[0]), int(value[1]), int(value[2])
            else:
                phase, number = (int(part) for part in value.depth.frame_id.split(":"))
                written = float(value.depth.stamp)
            self.records.append((number, phase, written, received))
            if number == self.last and self.app is not None:
                self.app.request_stop(f"{self.name}: the last sample came")

    def on_stop(self) -> None:
        Path(self.path).write_text(json.dumps(self.records))
