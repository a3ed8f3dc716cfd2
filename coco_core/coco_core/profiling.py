"""Per-component and per-activity timing, cheap enough to stay on in production.

A component records, for every execution, its *compute time* (how long ``on_update`` took) and its
*service time* (the time since its previous activation), as count, total, mean and variance with
Welford's running update: no samples are stored. An activity records its period error (actual wake
time minus deadline) into a fixed ring, from which percentiles are computed on demand. A profiled
run also records the age of what each connection's reader takes (:class:`MessageAges`).
"""

from __future__ import annotations

import math
import threading
import time
from array import array
from dataclasses import dataclass
from typing import Any

from .cpu import CpuUse
from .pool import Slot
from .stamps import Message


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


class MessageAges:
    """The age of each message a connection's reader takes (the read time - the message's stamp
    time: its write, or a ``Stamped`` value's acquisition), as count, mean and max: the profile's
    per-connection latency, which needs no component to record it. The stamps of every process of
    a host share ``perf_counter``'s clock (CLOCK_MONOTONIC), and a connection between hosts puts
    them on the application's clock, so the age is meaningful wherever the writer ran.

    Kept only in a profiled run (``--profile``, :attr:`Application.measure_ages
    <coco_core.application.Application.measure_ages>`): the reader's port then pays a clock read
    per message, which an unprofiled 1 kHz loop should not."""

    __slots__ = ("count", "total", "max")

    def __init__(self) -> None:
        self.count = 0
        self.total = 0.0
        self.max = 0.0

    def took(self, item: Any) -> None:
        """The reader took ``item`` from the connection (a message, a pooled frame or a bare value,
        which has no stamp and is not counted)."""
        if type(item) is Message:
            born = item.time
        elif type(item) is Slot and item.message is not None:
            born = item.message.time
        else:
            return
        age = time.perf_counter() - born
        self.count += 1
        self.total += age
        if age > self.max:
            self.max = age

    @property
    def mean(self) -> float:
        return self.total / self.count if self.count else 0.0


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
        self.thread_cpu: CpuUse | None = None
        """The CPU its thread used from the activity's start to its end, set by the driver when it ends:
        the profile at exit is taken after the threads ended, when /proc no longer lists them."""

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
