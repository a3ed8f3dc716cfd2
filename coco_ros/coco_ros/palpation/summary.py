"""``PalpationSummary``: what a remote palpation run is judged by, measured on the data that flowed.

It sits beside the haptic loop (in the haptic process, woken by the stream's frames and the cloud
structures, draining the haptic samples at each wake-up) and reads:

- ``samples`` (``HapticRenderer.sample``, a BUFFER connection): the haptic rate and the period error
  of the loop (from the samples' own ``perf_counter`` times: |interval - ``period``|), the time in
  contact, the deepest penetration and the largest force;
- ``structures`` (``KDTreeBuilder.structure``): how many cloud structures reached the haptic side,
  at what rate (arrival times here), how long each took to build (``build_seconds``), how many points;
- ``frames`` (``StreamingReceiver.rgbd``): the frames the stream delivered, and the frames the
  server sent that never arrived (gaps in the server's sequence numbers: dropped by ZeroMQ or
  superseded in the receiver);
- ``residual`` (``TouchRegistration.residual``): the calibration touch's RMS residual, or null when
  the touch never registered the hand tracker.

The JSON (``json`` attribute) is written at the stop; :func:`describe` puts it in a few lines
(``python -m coco_ros.palpation summary.json``, what ``scripts/run_app.sh palpation`` shows). Nothing
is estimated: a figure with no data behind it is null.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.ports import InputPort
from coco_core.stamps import Stamped, unstamped
from coco_mr_haptics.cloud import CloudStructure
from coco_mr_haptics.types import HapticSample


def _stats_ms(seconds: list[float]) -> dict[str, float | None]:
    """Median, 99th percentile and max of durations, in milliseconds (nulls when empty)."""
    if not seconds:
        return {"median": None, "p99": None, "max": None}
    values = np.asarray(seconds) * 1e3
    return {"median": float(np.median(values)), "p99": float(np.percentile(values, 99)), "max": float(values.max())}


class PalpationSummary(Component):
    """Measures the palpation run from its data flows and writes the JSON summary at the stop."""

    json = Attribute(Path, Path("out/palpation/summary.json"), "JSON summary written at the stop")
    period = Attribute(float, 0.001, "s: the haptic loop's nominal period (its period error is measured against it)",
                       min=1e-6)

    samples = InputPort(HapticSample, doc="HapticRenderer.sample, through a BUFFER connection")
    structures = InputPort(CloudStructure, event=True, doc="KDTreeBuilder.structure, through a BUFFER connection")
    frames = InputPort(Stamped, event=True, doc="StreamingReceiver.rgbd: frames stamped with the server's sequence numbers")
    residual = InputPort(float, doc="TouchRegistration.residual (m)")

    def on_config(self) -> None:
        self._times: list[float] = []
        self._contact: list[bool] = []
        self.max_penetration = 0.0
        self.max_force = 0.0
        self._arrivals: list[float] = []
        self._builds: list[float] = []
        self._points: list[int] = []
        self.frames_received = 0
        self.frames_missed = 0
        self._last_seq: int | None = None
        self.registration_residual: float | None = None

    def on_update(self) -> None:
        for sample in self.samples.read_all():
            self._times.append(sample.time)
            self._contact.append(bool(sample.contact))
            self.max_penetration = max(self.max_penetration, float(sample.depth))
            self.max_force = max(self.max_force, math.sqrt(sum(f * f for f in sample.force)))
        now = time.perf_counter()
        for structure in self.structures.read_all():
            self._arrivals.append(now)
            self._builds.append(float(structure.build_seconds))
            self._points.append(int(structure.valid or len(structure.points)))
        for value in self.frames.read_all():
            _, stamp = unstamped(value)
            self.frames_received += 1
            if stamp is not None and stamp.seq:
                if self._last_seq is not None and stamp.seq > self._last_seq:
                    self.frames_missed += stamp.seq - self._last_seq - 1
                self._last_seq = stamp.seq
        for residual in self.residual.read_all():
            self.registration_residual = float(residual)

    def report(self) -> dict[str, Any]:
        times = np.asarray(self._times)
        intervals = np.diff(times)
        contact = np.asarray(self._contact[1:], bool)
        haptic: dict[str, Any] = {
            "samples": len(times),
            "rate_hz": float((len(times) - 1) / (times[-1] - times[0])) if len(times) > 1 and times[-1] > times[0] else None,
            "period_error_ms": _stats_ms(list(np.abs(intervals - self.period))),
            "contact_time_s": float(intervals[contact].sum()) if len(intervals) else 0.0,
            "max_penetration_mm": 1e3 * self.max_penetration,
            "max_force_n": self.max_force,
        }
        arrivals = self._arrivals
        tree: dict[str, Any] = {
            "updates": len(arrivals),
            "rate_hz": (len(arrivals) - 1) / (arrivals[-1] - arrivals[0]) if len(arrivals) > 1 and arrivals[-1] > arrivals[0] else None,
            "build_ms": _stats_ms(self._builds),
            "points_median": int(np.median(self._points)) if self._points else None,
        }
        return {
            "haptics": haptic,
            "kdtree": tree,
            "stream": {"frames": self.frames_received, "dropped": self.frames_missed},
            "registration_residual_mm": None if self.registration_residual is None else 1e3 * self.registration_residual,
            "input_damage": list(self.app.damage) if self.app is not None else [],
        }

    def on_stop(self) -> None:
        self.on_update()
        report = self.report()
        self.json.parent.mkdir(parents=True, exist_ok=True)
        self.json.write_text(json.dumps(report, indent=2) + "\n")


def describe(summary: dict[str, Any]) -> str:
    """A few lines for a person."""

    def ms(stats: dict[str, Any], key: str) -> str:
        value = stats.get(key)
        return "-" if value is None else f"{value:.3f} ms"

    haptic, tree, stream = summary["haptics"], summary["kdtree"], summary["stream"]
    rate = "-" if haptic["rate_hz"] is None else f"{haptic['rate_hz']:.0f} Hz"
    tree_rate = "-" if tree["rate_hz"] is None else f"{tree['rate_hz']:.1f} Hz"
    residual = summary["registration_residual_mm"]
    lines = [
        f"haptic loop: {haptic['samples']} samples at {rate}, period error median {ms(haptic['period_error_ms'], 'median')}, "
        f"p99 {ms(haptic['period_error_ms'], 'p99')}",
        f"contact {haptic['contact_time_s']:.2f} s, max penetration {haptic['max_penetration_mm']:.2f} mm, "
        f"max force {haptic['max_force_n']:.2f} N",
        f"KD-tree: {tree['updates']} updates at {tree_rate}, build median {ms(tree['build_ms'], 'median')}, "
        f"p99 {ms(tree['build_ms'], 'p99')} ({tree['points_median'] or 0} points)",
        f"stream: {stream['frames']} frames received, {stream['dropped']} dropped",
        "registration: " + ("NOT REGISTERED (no calibration touch seen)" if residual is None
                            else f"residual {residual:.2f} mm RMS"),
    ]
    for damage in summary.get("input_damage") or ():
        lines.append(f"DAMAGED INPUT: {damage}")
    return "\n".join(lines)
