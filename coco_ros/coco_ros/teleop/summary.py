"""``TeleopSummary``: records the teleoperation distances to CSV and writes a JSON summary at the stop.

Inputs: ``distance`` (``Stamped[float]``, event), ``color`` (``Stamped[(r, g, b)]``), ``bag_time``
(``Stamped[float]``, ROS seconds), all written by :class:`~.distance.EndEffectorDistance` with one
shared :class:`Stamp` per sample (matched here by ``stamp.seq``); optional data ports ``bowl`` and
``target`` (:class:`FramePose` in one frame, optionally Stamped) for the final bowl-to-target distance;
optional ``display_latency`` (``Stamped[float]``, a GLManager's ``latency``: per rendered frame that
showed a new input, seconds from that input's emission to the frame's pixels).

CSV (``csv`` attribute): ``seq, time, distance, r, g, b, latency_ms`` — ``time`` is seconds after
``time_origin`` (the ROS time of session time 0; ``0``: the first sample's bag time), ``latency_ms``
the age of the sample's stamp when its row is written (also recorded for the profiler): with a
stamped replay and graph upstream, from the emission of the input that caused the sample.

JSON (``json`` attribute, at ``on_stop``, after the last rows are flushed): ``samples``,
``min_distance``, ``min_distance_time``, ``final_distance``, ``grasp_time`` (first time the
distance is below ``near``, or null), ``near``, ``time_origin``, ``final_bowl_target_distance``
(null without ``bowl``/``target``), ``latency_ms`` (mean, max), ``display_latency_ms`` (``frames``,
``mean``, ``median``, ``p90``, ``max``: sensor-to-display latency; nulls without a display),
``input_damage`` (the application's :attr:`~coco_core.application.Application.damage`: e.g. a
truncated bag, a message the replay could not convert; empty when the inputs were whole),
``input_refused`` (component -> input samples it refused as malformed, the profile's ``refused``
column, for the components of this process that refused any: a replay lists only its first refused
messages in ``input_damage``, this is the count).

:func:`describe` puts a JSON summary in a few lines: ``python -m coco_ros.teleop summary.json`` (what
``scripts/run_app.sh`` shows after the run).
"""

from __future__ import annotations

import csv
import json
import math
import time
from pathlib import Path
from typing import IO, Any

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.histogram import LogHistogram
from coco_core.policy import NEW_DATA
from coco_core.ports import InputPort
from coco_core.stamps import Stamped, unstamped
from coco_core.transforms.samples import FramePose

from .distance import frame_distance


def _finite(value: float) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


class TeleopSummary(Component):
    """CSV of every distance sample and a JSON summary at the stop; see the module docstring."""

    csv = Attribute(Path, Path("out/teleop/distance.csv"), "CSV file of the samples; its folder is created")
    json = Attribute(Path, Path("out/teleop/summary.json"), "JSON summary written at the stop")
    near = Attribute(float, 0.02, "grasp threshold (m): the grasp time is the first distance below it", min=0.0)
    time_origin = Attribute(float, 0.0, "ROS time (s) of time 0 in the outputs; 0: the first sample's")

    distance = InputPort(Stamped, event=True, doc="distance samples (m)")
    color = InputPort(Stamped, doc="colour of each distance sample")
    bag_time = InputPort(Stamped, doc="ROS time (s) of each distance sample")
    bowl = InputPort(FramePose | Stamped, doc="bowl pose, optional (final bowl-to-target distance)")
    target = InputPort(FramePose | Stamped, doc="target pose, optional (final bowl-to-target distance)")
    display_latency = InputPort(Stamped, doc="sensor-to-display latency (s) of each rendered frame, optional")

    def on_config(self) -> None:
        self.csv.parent.mkdir(parents=True, exist_ok=True)
        self.json.parent.mkdir(parents=True, exist_ok=True)
        self._file: IO[str] = self.csv.open("w", newline="")
        self._writer = csv.writer(self._file)
        self._writer.writerow(["seq", "time", "distance", "r", "g", "b", "latency_ms"])
        self._pending: list[Stamped] = []
        self._colors: dict[int, Any] = {}
        self._times: dict[int, float] = {}
        self._origin = self.time_origin or None
        self.rows = 0
        self._min = (math.inf, math.nan)
        self._final = math.nan
        self._grasp: float | None = None
        self._latency_total, self._latency_max = 0.0, -math.inf  # over self.rows samples
        self._display = LogHistogram()
        """Sensor-to-display latencies: a histogram, so that a run of any length keeps its size."""
        self._bowl: FramePose | None = None
        self._target: FramePose | None = None

    def on_update(self) -> None:
        self._drain(final=False)

    def _drain(self, final: bool) -> None:
        self._pending.extend(self.distance.read_all())
        for sample in self.color.read_all():
            self._colors[sample.stamp.seq] = sample.value
        for sample in self.bag_time.read_all():
            self._times[sample.stamp.seq] = sample.value
        for sample in self.display_latency.read_all():
            self._display.record(max(float(sample.value), 0.0))
        for port, attr in ((self.bowl, "_bowl"), (self.target, "_target")):
            status, value = port.read_newest()  # only the last pose matters; older ones count as dropped
            if status is NEW_DATA:
                setattr(self, attr, unstamped(value)[0])
        if not self._pending:
            return
        now = time.perf_counter()
        waiting = []
        for sample in self._pending:
            seq = sample.stamp.seq
            connected = (self.color.connected, self.bag_time.connected)
            ready = ((not connected[0] or seq in self._colors) and (not connected[1] or seq in self._times))
            if not ready and not final:
                waiting.append(sample)
                continue
            self._row(sample, self._colors.pop(seq, (math.nan,) * 3), self._times.pop(seq, math.nan), now)
        self._pending = waiting
        self._file.flush()

    def _row(self, sample: Stamped, color: Any, bag_time: float, now: float) -> None:
        if self._origin is None and math.isfinite(bag_time):
            self._origin = bag_time
        t = bag_time - self._origin if self._origin is not None else math.nan
        distance = float(sample.value)
        latency = now - sample.stamp.time
        self._writer.writerow([sample.stamp.seq, f"{t:.4f}", f"{distance:.6f}",
                               *(f"{c:.4f}" for c in color), f"{latency * 1e3:.3f}"])
        self.record_latency(sample.stamp)
        self._latency_total += latency
        self._latency_max = max(self._latency_max, latency)
        self.rows += 1
        self._final = distance
        if distance < self._min[0]:
            self._min = (distance, t)
        if self._grasp is None and distance < self.near:
            self._grasp = t

    def summary(self) -> dict[str, Any]:
        bowl_target = None
        if self._bowl is not None and self._target is not None:
            bowl_target = frame_distance(self._bowl, self._target)
        return {
            "samples": self.rows,
            "min_distance": _finite(self._min[0]),
            "min_distance_time": _finite(self._min[1]),
            "final_distance": _finite(self._final),
            "grasp_time": self._grasp,
            "near": self.near,
            "time_origin": self._origin,
            "final_bowl_target_distance": bowl_target,
            "latency_ms": {"mean": self._latency_total / self.rows * 1e3 if self.rows else None,
                           "max": self._latency_max * 1e3 if self.rows else None},
            "display_latency_ms": {"frames": self._display.count,
                                   "mean": None if self._display.mean is None else self._display.mean * 1e3,
                                   **self._display.milliseconds(median=0.5, p90=0.9)},
            "csv": str(self.csv),
            "input_damage": list(self.app.damage) if self.app is not None else [],
            "input_refused": {name: component.stats.refused for name, component in self.app.components.items()
                              if component.stats.refused} if self.app is not None else {},
        }

    def on_stop(self) -> None:
        self._drain(final=True)
        self._file.close()
        self.json.write_text(json.dumps(self.summary(), indent=2) + "\n")


def describe(summary: dict[str, Any]) -> str:
    """A few lines for a person: samples, closest approach, grasp, final distances, latency."""

    def metres(value: float | None) -> str:
        return "-" if value is None else f"{value:.3f} m"

    def seconds(value: float | None) -> str:
        return "-" if value is None else f"{value:.2f} s"

    lines = [f"{summary['samples']} distance samples in {summary['csv']}",
             f"closest approach {metres(summary['min_distance'])} at {seconds(summary['min_distance_time'])}; "
             + (f"within {summary['near']} m of the bowl from {seconds(summary['grasp_time'])}"
                if summary["grasp_time"] is not None else f"never within {summary['near']} m of the bowl"),
             f"final gripper-to-bowl distance {metres(summary['final_distance'])}"
             + (f"; bowl left {metres(summary['final_bowl_target_distance'])} from its target"
                if summary["final_bowl_target_distance"] is not None else "")]
    for damage in summary.get("input_damage") or ():
        lines.append(f"DAMAGED INPUT (the run used what was readable): {damage}")
    for name, count in (summary.get("input_refused") or {}).items():
        lines.append(f"REFUSED INPUT: {name} refused {count} malformed sample{'s' if count != 1 else ''} "
                     "(the profile's refused column)")
    latency = summary["latency_ms"]
    if latency["mean"] is not None:
        lines.append(f"latency, replay emission -> CSV row: mean {latency['mean']:.2f} ms, max {latency['max']:.2f} ms")
    display = summary.get("display_latency_ms") or {}
    if display.get("frames"):
        lines.append(f"latency, replay emission -> rendered frame: median {display['median']:.1f} ms, "
                     f"mean {display['mean']:.1f} ms, max {display['max']:.1f} ms ({display['frames']} frames)")
    return "\n".join(lines)
