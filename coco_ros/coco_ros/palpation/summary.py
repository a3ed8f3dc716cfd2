"""``PalpationSummary``: what a remote palpation run is judged by, measured on the data that flowed.

It sits beside the haptic loop (in the haptic process, woken by the stream's frames and the cloud
structures, draining the haptic samples at each wake-up) and reads:

- ``samples`` (``HapticRenderer.sample``, a BUFFER connection): the haptic rate and the period error
  of the loop (from the samples' own ``perf_counter`` times: |interval - ``period``|), the time in
  contact, the deepest penetration and the largest force;
- ``structures`` (``KDTreeBuilder.structure``): how many cloud structures reached the haptic side,
  at what rate (arrival times here), how long each took to build (``build_seconds``), how many points,
  and, for those built from a streamed frame, the sensor-to-touchable latency (acquisition to the
  structure built) split by the steps its stamp passed: ``sent`` (taken by the remote server,
  before its encoding), ``received`` (decoded by the receiver), ``built`` (the steps it carries: a
  structure built from a mesh has a ``meshed`` step before it);
- ``frames`` (``StreamingReceiver.rgbd``): the frames the stream delivered, and the frames the
  server sent that never arrived (gaps in the server's sequence numbers: dropped by ZeroMQ or
  superseded in the receiver); its stalls: gaps longer than ``stall`` between the acquisition
  stamps of the frames delivered, or from the last one to the stop (a remote camera or link that
  stopped: the local side had no newer scene for that long), and the contact the
  haptic loop rendered after the last frame (on the last structure it had);
- ``residual`` (``TouchRegistration.residual``): the calibration touch's RMS residual, or null when
  the touch never registered the hand tracker (or the ``registration`` is ``fixed``: none to make);
- ``display_latency`` (``GLManager.latency``, optional): per rendered frame that showed a new input,
  seconds from that input's origin to the frame's pixels, by the origin's source: the remote
  camera's frames (stamped at acquisition, through the stream) give the paper's sensor-to-display
  latency, the hand's poses the tracker-to-display one; each split by the steps the frame's stamp
  passed (the camera's: ``sent``, ``received``, then the view's ``frame_start``: its update began
  and the scene read the frame, ``drawn``, ``read_back``), each step the time from the one before.

Each split also gives every step's *share* of its frame's path (``step_shares``,
``display_step_shares``: the median over frames of step / that frame's acquisition-to-end time),
which is what "bound by" means: the step medians do not add up to the path's median (each is a
median of its own), so a share of their sum explains no figure.

``cpu`` (at the stop): each process of the application on this host (the launcher and its children),
its CPU time over the time it lived, in cores (:mod:`coco_core.cpu`), and all of them together: the
machine's cores are the budget, and this says who spends it.

On several hosts (``<host>``), the stamps are on the first host's clock; ``clock`` in the JSON says
this host's offset to it and how well it is known (``exchanges`` 0: this is the first host).

The JSON (``json`` attribute) is written at the stop; :func:`describe` puts it in a few lines
(``python -m coco_ros.palpation summary.json``, what ``scripts/run_app.sh palpation`` shows). Nothing
is estimated: a figure with no data behind it is null. Besides: ``input_damage`` (the application's
:attr:`~coco_core.application.Application.damage`, every process's: a camera frame or a hand pose
the readers refused, a workspace never joined; the launcher exits 1) and ``input_refused``
(component -> malformed input samples it refused, the profile's ``refused`` column, for the
components of the summary's own process: in the palpation app the ``local`` process's receiver,
mesh and tree).

A stall is not damaged input: the stream's frames that came were sound, and the haptic loop goes on
with the last structure it had (or zero force before the first), so it does not change the exit
status; the summary counts it.
"""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import Any

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.cpu import application_cpu
from coco_core.histogram import LogHistogram
from coco_core.ports import InputPort
from coco_core.stamps import Stamp, Stamped, unstamped
from coco_mr_haptics.cloud import CloudStructure
from coco_mr_haptics.types import HapticSample


QUANTILES = {"median": 0.5, "p99": 0.99}
"""The quantiles of every duration the summary reports (with the max, which ``milliseconds`` adds)."""


def _record_steps(steps: dict[str, LogHistogram], stamp: Stamp) -> None:
    """Each step of ``stamp``'s way, from the one before (clamped at 0: a display update may begin a
    moment before the frame it shows was received, and still read it)."""
    for name, seconds in stamp.intervals():
        steps.setdefault(name, LogHistogram()).record(max(seconds, 0.0))


def _record_shares(shares: dict[str, LogHistogram], stamp: Stamp) -> None:
    """Each step's share of this frame's path (acquisition to its last step), when the path took time."""
    intervals = stamp.intervals()
    path = sum(seconds for _, seconds in intervals)
    if path <= 0:
        return
    for name, seconds in intervals:
        shares.setdefault(name, LogHistogram(lowest=1e-4, highest=10.0)).record(max(seconds, 0.0) / path)


def _steps_ms(steps: dict[str, LogHistogram]) -> dict[str, Any]:
    return {name: histogram.milliseconds(**QUANTILES) for name, histogram in steps.items()}


def _shares(shares: dict[str, LogHistogram]) -> dict[str, float]:
    """The median share of each step (0..1)."""
    return {name: histogram.quantile(0.5) for name, histogram in shares.items()}


def _rate(count: int, first: float, last: float) -> float | None:
    """Events a second from the first to the last of ``count``; None without two at distinct times."""
    return (count - 1) / (last - first) if count > 1 and last > first else None


class PalpationSummary(Component):
    """Measures the palpation run from its data flows and writes the JSON summary at the stop."""

    json = Attribute(Path, Path("out/palpation/summary.json"), "JSON summary written at the stop")
    registration = Attribute(str, "touch", "how the hand tracker is joined to the camera: touch (TouchRegistration, "
                             "whose residual arrives on residual) or fixed (a transform the application gives)",
                             choices=("touch", "fixed"))
    period = Attribute(float, 0.001, "s: the haptic loop's nominal period (its period error is measured against it)",
                       min=1e-6)
    stall = Attribute(float, 1.0, "s without a newer stream frame (by the frames' acquisition stamps, or from the "
                      "last one to the stop) counted as a stall of the stream (30 frames of a 30 Hz camera)", min=0.0)

    samples = InputPort(HapticSample, doc="HapticRenderer.sample, through a BUFFER connection")
    structures = InputPort(CloudStructure, event=True, doc="KDTreeBuilder.structure, through a BUFFER connection")
    frames = InputPort(Stamped, event=True, doc="StreamingReceiver.rgbd: frames stamped with the server's sequence numbers")
    residual = InputPort(float, doc="TouchRegistration.residual (m)")
    display_latency = InputPort(Stamped, doc="GLManager.latency: seconds from an input's origin to the frame "
                                             "that first shows it, stamped with that origin (optional)")

    def on_config(self) -> None:
        # Running figures and histograms, not lists of every sample: a run at 1 kHz keeps its size
        # however long it lasts (issue 23).
        self.haptic_samples = 0
        self._first_time = self._last_time = math.nan
        self._period_errors = LogHistogram()
        self.contact_time = 0.0
        self.max_penetration = 0.0
        self.max_force = 0.0
        self.tree_updates = 0
        self._first_arrival = self._last_arrival = math.nan
        self._builds = LogHistogram()
        self._points = LogHistogram(lowest=1.0, highest=1e9)
        self._touchable = LogHistogram()
        """Acquisition of a streamed frame to its structure built (sensor-to-touchable)."""
        self._touchable_steps: dict[str, LogHistogram] = {}
        self._touchable_shares: dict[str, LogHistogram] = {}
        """Each step's share of its frame's sensor-to-touchable path."""
        self.frames_received = 0
        self.frames_missed = 0
        self._last_seq: int | None = None
        self.stalls = 0
        self.longest_gap = 0.0
        self._newest_frame: float | None = None
        """The acquisition stamp (perf_counter, shared by the processes of a host) of the newest frame."""
        self.contact_after_frame = 0.0
        """Contact time rendered after the newest frame's acquisition (on the last structure)."""
        self._stopped_at: float | None = None
        self.registration_residual: float | None = None
        self._display: dict[str, LogHistogram] = {}
        """Sensor-to-display latencies by the source of the input a frame showed first."""
        self._display_steps: dict[str, dict[str, LogHistogram]] = {}
        """The same split by the steps of the way, by source."""
        self._display_shares: dict[str, dict[str, LogHistogram]] = {}
        """Each step's share of its frame's path, by source."""
        self._cpu: dict[str, float] = {}
        """Process name -> cores, read at the stop."""

    def on_update(self) -> None:
        for value in self.frames.read_all():  # first: the samples after the newest frame are told apart
            _, stamp = unstamped(value)
            self.frames_received += 1
            if stamp is not None and stamp.seq:
                if self._last_seq is not None and stamp.seq > self._last_seq:
                    self.frames_missed += stamp.seq - self._last_seq - 1
                self._last_seq = stamp.seq
            if stamp is not None and (self._newest_frame is None or stamp.time > self._newest_frame):
                if self._newest_frame is not None:
                    self._gap(stamp.time - self._newest_frame)
                self._newest_frame, self.contact_after_frame = stamp.time, 0.0
        for sample in self.samples.read_all():
            if self.haptic_samples:
                interval = sample.time - self._last_time
                self._period_errors.record(abs(interval - self.period))
                if sample.contact:
                    self.contact_time += interval
                    if self._newest_frame is not None and sample.time > self._newest_frame:
                        self.contact_after_frame += interval
            else:
                self._first_time = sample.time
            self._last_time = sample.time
            self.haptic_samples += 1
            self.max_penetration = max(self.max_penetration, float(sample.depth))
            self.max_force = max(self.max_force, math.sqrt(sum(f * f for f in sample.force)))
        now = time.perf_counter()
        for structure in self.structures.read_all():
            if not self.tree_updates:
                self._first_arrival = now
            self._last_arrival = now
            self.tree_updates += 1
            self._builds.record(float(structure.build_seconds))
            self._points.record(int(structure.valid or len(structure.points)))
            origin = structure.origin
            if origin is not None and origin.steps:
                self._touchable.record(max(origin.steps[-1][1] - origin.time, 0.0))
                _record_steps(self._touchable_steps, origin)
                _record_shares(self._touchable_shares, origin)
        for residual in self.residual.read_all():
            self.registration_residual = float(residual)
        for latency in self.display_latency.read_all():
            source = latency.stamp.source or "?"
            self._display.setdefault(source, LogHistogram()).record(max(float(latency.value), 0.0))
            _record_steps(self._display_steps.setdefault(source, {}), latency.stamp)
            _record_shares(self._display_shares.setdefault(source, {}), latency.stamp)

    def _gap(self, seconds: float) -> None:
        """A time without a newer frame: a stall when longer than ``stall``."""
        self.longest_gap = max(self.longest_gap, seconds)
        if seconds > self.stall:
            self.stalls += 1

    def report(self) -> dict[str, Any]:
        haptic: dict[str, Any] = {
            "samples": self.haptic_samples,
            "rate_hz": _rate(self.haptic_samples, self._first_time, self._last_time),
            "period_error_ms": self._period_errors.milliseconds(**QUANTILES),
            "contact_time_s": self.contact_time,
            "max_penetration_mm": 1e3 * self.max_penetration,
            "max_force_n": self.max_force,
            "contact_after_last_frame_s": self.contact_after_frame,
        }
        tree: dict[str, Any] = {
            "updates": self.tree_updates,
            "rate_hz": _rate(self.tree_updates, self._first_arrival, self._last_arrival),
            "build_ms": self._builds.milliseconds(**QUANTILES),
            "points_median": round(self._points.quantile(0.5)) if self._points.count else None,
            "latency_ms": self._touchable.milliseconds(**QUANTILES),
            "steps_ms": _steps_ms(self._touchable_steps),
            "step_shares": _shares(self._touchable_shares),
        }
        return {
            "haptics": haptic,
            "kdtree": tree,
            "stream": {"frames": self.frames_received, "dropped": self.frames_missed, "stalls": self.stalls,
                       "stall_s": self.stall, "longest_gap_s": None if self._newest_frame is None else self.longest_gap,
                       "silent_at_end_s": self._silent_at_end()},
            "registration": self.registration,
            "registration_residual_mm": None if self.registration_residual is None else 1e3 * self.registration_residual,
            "display_latency_ms": {source: {"frames": latencies.count, **latencies.milliseconds(**QUANTILES)}
                                   for source, latencies in sorted(self._display.items())},
            "display_steps_ms": {source: _steps_ms(steps) for source, steps in sorted(self._display_steps.items())},
            "display_step_shares": {source: _shares(shares) for source, shares in sorted(self._display_shares.items())},
            "cpu": {"cores": self._cpu, "total_cores": sum(self._cpu.values()) if self._cpu else None,
                    "machine_cores": os.cpu_count()},
            "clock": {"offset_ms": 1e3 * self.host_clock.offset, "uncertainty_ms": 1e3 * self.host_clock.uncertainty,
                      "exchanges": self.host_clock.exchanges},
            "input_damage": list(self.app.damage) if self.app is not None else [],
            "input_refused": {name: component.stats.refused for name, component in self.app.components.items()
                              if component.stats.refused} if self.app is not None else {},
        }

    def _silent_at_end(self) -> float | None:
        """Seconds from the newest frame's acquisition to the stop; None without a frame or before the stop."""
        if self._newest_frame is None or self._stopped_at is None:
            return None
        return max(self._stopped_at - self._newest_frame, 0.0)

    def on_stop(self) -> None:
        self.on_update()
        self._stopped_at = time.perf_counter()
        # The launcher: this process, or its parent when this is one of the process level's children.
        if self.app is not None:
            names = {activity.process for activity in self.app.activities.values() if activity.process}
            self._cpu = application_cpu(os.getppid() if self.app.process else os.getpid(), names)
        else:
            self._cpu = application_cpu(os.getpid())
        silent = self._silent_at_end()
        if silent is not None:
            self._gap(silent)
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
        f"stream: {stream['frames']} frames received, {stream['dropped']} dropped"
        + ("" if stream.get("longest_gap_s") is None else f", longest gap {stream['longest_gap_s']:.2f} s"),
        "registration: " + ("fixed (given by the application, no calibration touch)"
                            if summary.get("registration") == "fixed"
                            else "NOT REGISTERED (no calibration touch seen)" if residual is None
                            else f"residual {residual:.2f} mm RMS"),
    ]
    def steps(split: dict[str, Any]) -> str:
        return ", ".join(f"{name} +{ms(stats, 'median')}" for name, stats in split.items())

    if tree.get("steps_ms"):
        lines.append(f"sensor to touchable: median {ms(tree['latency_ms'], 'median')}, p99 "
                     f"{ms(tree['latency_ms'], 'p99')}; step medians: {steps(tree['steps_ms'])}")
    clock = summary.get("clock") or {}
    on_clock = (f" (on the first host's clock, this host's offset known to +- {clock['uncertainty_ms']:.3f} ms)"
                if clock.get("exchanges") else "")
    for source, latency in (summary.get("display_latency_ms") or {}).items():
        lines.append(f"display latency from {source}: median {ms(latency, 'median')}, p99 {ms(latency, 'p99')} "
                     f"({latency['frames']} frames){on_clock}")
        split = (summary.get("display_steps_ms") or {}).get(source)
        if split:
            lines.append(f"  step medians: {steps(split)}")
    cpu = summary.get("cpu") or {}
    if cpu.get("cores"):
        lines.append("CPU (cores, CPU time / time lived): "
                     + ", ".join(f"{name} {cores:.2f}" for name, cores in cpu["cores"].items())
                     + f"; all {cpu['total_cores']:.2f} of the machine's {cpu['machine_cores']}")
    if stream.get("stalls"):
        silent = stream.get("silent_at_end_s")
        lines.append(f"STREAM STALLED {stream['stalls']} time{'s' if stream['stalls'] != 1 else ''} (no newer frame "
                     f"for over {stream['stall_s']:g} s); the last frame {silent or 0.0:.2f} s before the stop, "
                     f"{haptic.get('contact_after_last_frame_s', 0.0):.2f} s of contact rendered after it "
                     "(on the last structure)")
    for damage in summary.get("input_damage") or ():
        lines.append(f"DAMAGED INPUT: {damage}")
    for name, count in (summary.get("input_refused") or {}).items():
        lines.append(f"REFUSED INPUT: {name} refused {count} malformed sample{'s' if count != 1 else ''} "
                     "(the profile's refused column)")
    return "\n".join(lines)
