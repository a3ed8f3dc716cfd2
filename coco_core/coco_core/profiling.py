"""Per-component and per-activity timing, cheap enough to stay on in production.

A component records, for every execution, its *compute time* (how long ``on_update`` took) and its
*service time* (the time since its previous activation), as count, total, mean and variance with
Welford's running update: no samples are stored. An activity records its period error (actual wake
time minus deadline) into a fixed ring, from which percentiles are computed on demand.
"""

from __future__ import annotations

import math
import threading
from array import array
from dataclasses import dataclass


class RunningStats:
    """Count, total, mean and variance of a stream of numbers (Welford), in O(1) memory."""

    __slots__ = ("count", "total", "mean", "_m2", "max")

    def __init__(self) -> None:
        self.count = 0
        self.total = 0.0
        self.mean = 0.0
        self._m2 = 0.0
        self.max = 0.0

    def add(self, value: float) -> None:
        self.count += 1
        self.total += value
        delta = value - self.mean
        self.mean += delta / self.count
        self._m2 += delta * (value - self.mean)
        if value > self.max:
            self.max = value

    @property
    def variance(self) -> float:
        return self._m2 / (self.count - 1) if self.count > 1 else 0.0

    @property
    def std(self) -> float:
        return math.sqrt(self.variance)


class ComponentStats:
    """Execution profile of one component."""

    __slots__ = ("compute", "service", "latency", "errors", "refused", "merged", "_last_start")

    def __init__(self) -> None:
        self.compute = RunningStats()
        self.service = RunningStats()
        self.latency = RunningStats()
        """Stamp-to-output latency, fed by the component (:meth:`Component.record_latency`), from
        its inputs' origins (:attr:`InputPort.origin <coco_core.ports.InputPort.origin>`): a
        ``Stamped`` value's acquisition, a plain value's message stamp (its write)."""
        self.errors = 0
        self.refused = 0
        """Input samples the component read and refused (malformed values), see
        :meth:`Component.record_refusal`: the connection counts them as read, so they are shown here."""
        self.merged = 0
        """Input samples the component read and folded into a later output instead of giving one of
        their own (superseded, or merged with the next), see :meth:`Component.record_merged`: read
        for the connection, yet no output shows them alone, so they are shown here."""
        self._last_start: float | None = None

    def record(self, start: float, end: float) -> None:
        """One execution from ``start`` to ``end`` (perf_counter seconds)."""
        self.compute.add(end - start)
        if self._last_start is not None:
            self.service.add(start - self._last_start)
        self._last_start = start

    @property
    def executions(self) -> int:
        return self.compute.count


@dataclass(frozen=True)
class ErrorSummary:
    """Percentiles of an activity's period error, in seconds."""

    samples: int
    p50: float
    p99: float
    max: float
    mean: float


class ActivityStats:
    """Cycles, overruns and the period error of one activity."""

    RING = 1 << 16

    def __init__(self) -> None:
        self.cycles = 0
        self.overruns = 0
        self._errors = array("d", bytes(8 * self.RING))
        """The last RING period errors, as doubles: a list would allocate a float object per error
        until it wrapped (1.5 MB over the first five minutes of a 5 ms activity, read as a leak)."""
        self._next = 0
        self._lock = threading.Lock()

    def record_error(self, error: float) -> None:
        """Wake-up time minus deadline of one periodic cycle."""
        self._errors[self._next & (self.RING - 1)] = error
        self._next += 1

    def reset(self) -> None:
        """Forget the period errors so far (e.g. after a warm-up or a period change)."""
        with self._lock:
            self._next = 0

    def error_summary(self) -> ErrorSummary | None:
        """Percentiles over the last ``RING`` cycles, or None before the first periodic cycle."""
        with self._lock:
            count = min(self._next, self.RING)
            if count == 0:
                return None
            values = sorted(self._errors[:count])

        def percentile(q: float) -> float:
            return values[min(count - 1, int(round(q * (count - 1))))]

        return ErrorSummary(count, percentile(0.5), percentile(0.99), values[-1], sum(values) / count)
