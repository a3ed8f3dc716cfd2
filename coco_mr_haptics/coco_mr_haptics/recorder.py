"""HapticRecorder: every haptic cycle into a CSV, and a summary of the run.

It drains a buffered connection from ``HapticRenderer.sample`` in a slow activity of its own, so
that no file is touched by the 1 kHz loop. The summary (JSON, written at the stop and printed to the
log) answers what a haptics run is judged by: the rate achieved, the deepest penetration, and the
energy that went into and came out of the contacts.

Energy: with the force ``F_k`` held over the step from ``x_k`` to ``x_k+1`` (as a device holds it),
the contacts do the work ``F_k . (x_k+1 - x_k)`` on the device. Summed where it is negative, that is
the energy the contacts absorbed (``energy_in``); where positive, the energy they gave back
(``energy_out``). A passive contact never gives back more than it absorbed.

``force_faults`` counts the cycles in which the renderer replaced a non-finite force by zero (see
:mod:`coco_mr_haptics.renderer`): a run with faults is not a run to judge by its energy.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.ports import InputPort

from .types import HapticSample

log = logging.getLogger("coco")

HEADER = ("time,device_x,device_y,device_z,proxy_x,proxy_y,proxy_z,force_x,force_y,force_z,"
          "contact,renderer,depth\n")


class HapticRecorder(Component):
    """Writes the renderer's samples to ``path`` (CSV) and the run's summary to ``summary``."""

    path = Attribute(str, "out/haptics/haptic.csv", "CSV file, one row per haptic cycle")
    summary = Attribute(str, "out/haptics/summary.json", "JSON summary written at the stop (\"\": none)")

    samples = InputPort(HapticSample, doc="HapticRenderer.sample, through a BUFFER connection")

    def on_config(self) -> None:
        Path(self.path).parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "w", buffering=1 << 16)
        self._file.write(HEADER)
        self.rows = 0
        self.contact_rows = 0
        self.force_faults = 0
        self.first_time = self.last_time = 0.0
        self.max_depth = 0.0
        self.max_force = 0.0
        self.energy_in = self.energy_out = 0.0
        self._previous: HapticSample | None = None
        self.renderers: dict[str, int] = {}
        self.unready: dict[str, int] = {}
        """Samples in which each renderer had no surface (see HapticSample.unready)."""

    def on_update(self) -> None:
        lines = []
        for sample in self.samples.read_all():
            self._account(sample)
            d, p, f = sample.device, sample.proxy, sample.force
            lines.append(f"{sample.time:.6f},{d[0]:.7g},{d[1]:.7g},{d[2]:.7g},{p[0]:.7g},{p[1]:.7g},"
                         f"{p[2]:.7g},{f[0]:.6g},{f[1]:.6g},{f[2]:.6g},{int(sample.contact)},"
                         f"{sample.renderer},{sample.depth:.6g}\n")
        if lines:
            self._file.write("".join(lines))

    def _account(self, sample: HapticSample) -> None:
        if self.rows == 0:
            self.first_time = sample.time
        self.rows += 1
        self.last_time = sample.time
        if sample.contact:
            self.contact_rows += 1
            self.renderers[sample.renderer] = self.renderers.get(sample.renderer, 0) + 1
        self.force_faults += sample.fault
        if sample.unready:
            for name in sample.unready.split(","):
                self.unready[name] = self.unready.get(name, 0) + 1
        self.max_depth = max(self.max_depth, sample.depth)
        fx, fy, fz = sample.force
        self.max_force = max(self.max_force, (fx * fx + fy * fy + fz * fz) ** 0.5)
        previous = self._previous
        if previous is not None:
            px, py, pz = previous.force
            work = (px * (sample.device[0] - previous.device[0]) + py * (sample.device[1] - previous.device[1])
                    + pz * (sample.device[2] - previous.device[2]))
            if work < 0.0:
                self.energy_in -= work
            else:
                self.energy_out += work
        self._previous = sample

    def report(self) -> dict[str, object]:
        span = self.last_time - self.first_time
        return {
            "samples": self.rows,
            "duration_s": span,
            "rate_hz": (self.rows - 1) / span if span > 0 else 0.0,
            "contact_samples": self.contact_rows,
            "contacts_by_renderer": self.renderers,
            "max_penetration_m": self.max_depth,
            "max_force_n": self.max_force,
            "energy_in_j": self.energy_in,
            "energy_out_j": self.energy_out,
            "passive": self.energy_out <= self.energy_in,
            "force_faults": self.force_faults,
            "samples_without_surface": self.unready,
            "surfaces_ready": not any(count == self.rows for count in self.unready.values()) and self.rows > 0,
            "csv": self.path,
        }

    def on_stop(self) -> None:
        self.on_update()
        self._file.close()
        report = self.report()
        log.info("%s: %d haptic samples at %.1f Hz, max penetration %.2f mm, energy in %.4f J, out %.4f J",
                 self.name, report["samples"], report["rate_hz"], 1e3 * self.max_depth, self.energy_in,
                 self.energy_out)
        if self.force_faults:
            log.error("%s: %d haptic cycles had a non-finite force (zero force sent instead)", self.name,
                      self.force_faults)
        for name, count in self.unready.items():
            log.warning("%s: renderer %s had no surface in %d of %d samples%s", self.name, name, count,
                        self.rows, " (never had one: this run touched nothing)" if count == self.rows else "")
        if self.summary:
            Path(self.summary).parent.mkdir(parents=True, exist_ok=True)
            Path(self.summary).write_text(json.dumps(report, indent=2) + "\n")

