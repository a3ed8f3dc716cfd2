"""A producer and a consumer that cost time, to try how two activities at different rates are
coupled: data-driven, demand-driven, frequency-bounded or greedy (FlowVR's Figure 1 a-d,
``config/flowvr_*.xml``, ``docs/flowvr.md``). Neither knows the coupling: it is the XML's.

Each keeps a bounded record of what it did (``history`` entries), from the message stamps only, so
that the rates and what the consumer got can be read back and checked: the producer the iteration
and times of each write, the consumer, for each value it took, when it asked, whether it was new or
reused, and the iteration that wrote it.
"""

from __future__ import annotations

import time
from collections import deque
from typing import NamedTuple

from ..attributes import Attribute
from ..component import Component
from ..policy import NEW_DATA, NO_DATA
from ..ports import InputPort, OutputPort


class Written(NamedTuple):
    """One write of :class:`CostlyProducer`."""

    it: int
    """The producer activity's iteration (the message's stamp)."""
    seq: int
    """The message's number on the port."""
    stamped: float
    """The stamp's time: when the write began (``perf_counter`` seconds)."""
    done: float
    """When the write had reached every connection."""


class Taken(NamedTuple):
    """One value :class:`CostlyConsumer` worked on."""

    requested: float
    """When it asked its input (``perf_counter`` seconds)."""
    answered: float
    """When the read returned."""
    new: bool
    """False: nothing newer was there, it reused the last value (``OLD_DATA``)."""
    it: int
    """The iteration of the producer that wrote the value (its stamp); -1 without a stamp."""
    seq: int


class CostlyProducer(Component):
    """Each update works ``cost_ms`` (sleeping, as native code that releases the GIL would), then
    writes its count on ``out``."""

    cost_ms = Attribute(float, 1.0, "time one update takes, in milliseconds", min=0.0)
    history = Attribute(int, 100_000, "how many writes the record keeps (the newest)", min=1)

    out = OutputPort(int, "the number of updates before this one")

    def init(self) -> None:
        self.produced = 0
        self.writes: deque[Written] = deque(maxlen=self.history)

    def on_update(self) -> None:
        time.sleep(self.cost_ms / 1e3)
        self.out.write(self.produced)
        self.produced += 1
        stamp = self.out.stamp
        assert stamp is not None  # a write was just stamped
        self.writes.append(Written(stamp.it, stamp.seq, stamp.time, time.perf_counter()))


class CostlyConsumer(Component):
    """Each update takes the values waiting on ``item`` when it began (one, through a greedy
    filter, which holds only the newest) and works ``cost_ms`` on each; with nothing new it works on
    the last value again (a greedy coupling's "reuse"), with nothing at all it does nothing."""

    cost_ms = Attribute(float, 5.0, "time the work on one value takes, in milliseconds", min=0.0)
    history = Attribute(int, 100_000, "how many taken values the record keeps (the newest)", min=1)

    item = InputPort(int, event=True, doc="the values to work on")

    def init(self) -> None:
        self.consumed = 0
        """New values worked on."""
        self.reused = 0
        """Updates that found nothing new and worked on the last value again."""
        self.taken: deque[Taken] = deque(maxlen=self.history)

    def on_update(self) -> None:
        waiting = self.item.pending
        requested = time.perf_counter()
        status, _ = self.item.read()
        if status is NO_DATA:
            return
        self._work(requested, status is NEW_DATA)
        if status is not NEW_DATA:
            return
        for _ in range(waiting - 1):
            requested = time.perf_counter()
            status, _ = self.item.read()
            if status is not NEW_DATA:
                return
            self._work(requested, True)

    def _work(self, requested: float, new: bool) -> None:
        stamp = self.item.stamp
        self.taken.append(Taken(requested, time.perf_counter(), new, stamp.it if stamp else -1,
                                stamp.seq if stamp else -1))
        if new:
            self.consumed += 1
            if stamp is not None:
                self.record_latency(stamp)
        else:
            self.reused += 1
        time.sleep(self.cost_ms / 1e3)
