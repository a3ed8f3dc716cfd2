"""A producer and a consumer that cost time, to try how two activities at different rates are
coupled: data-driven, demand-driven, frequency-bounded or greedy (FlowVR's Figure 1 a-d,
``config/flowvr_*.xml``, ``docs/flowvr.md``). Neither knows the coupling: it is the XML's.

Each keeps a bounded record of what it did (``history`` entries), from the message stamps only, so
that the rates and what the consumer got can be read back and checked: the producer the iteration
and times of each write, the consumer, for each value it took, when it asked, whether it was new or
reused, and the iteration that wrote it. With ``record`` set, each writes that record to a JSON file
when it stops (:func:`load_record` reads it back): how the checks and ``bench/bench_flowvr.py`` read
what happened in a process of their own. ``stop_after`` lets the consumer stop the application
(a natural stop) once it has worked on that many new values.
"""

from __future__ import annotations

import json
import math
import time
from collections import deque
from pathlib import Path
from types import SimpleNamespace
from typing import NamedTuple

from ..attributes import Attribute
from ..component import Component
from ..policy import NEW_DATA, NO_DATA
from ..ports import InputPort, OutputPort
from .record import save_record


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
    stamped: float
    """The value's stamp time (when the producer wrote it): ``answered - stamped`` is its age."""


class CostlyProducer(Component):
    """Each update works ``cost_ms`` (sleeping, as native code that releases the GIL would), then
    writes its count on ``out``."""

    cost_ms = Attribute(float, 1.0, "time one update takes, in milliseconds", min=0.0)
    history = Attribute(int, 100_000, "how many writes the record keeps (the newest)", min=1)
    record = Attribute(str, "", "a JSON file the record goes to when the producer stops; empty: none")

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

    def on_stop(self) -> None:
        if self.record:
            save_record(self.record, {"produced": self.produced, "writes": list(self.writes)})


class CostlyConsumer(Component):
    """Each update takes the values waiting on ``item`` when it began (one, through a greedy
    filter, which holds only the newest) and works ``cost_ms`` on each; with nothing new it works on
    the last value again (a greedy coupling's "reuse"), with nothing at all it does nothing."""

    cost_ms = Attribute(float, 5.0, "time the work on one value takes, in milliseconds", min=0.0)
    history = Attribute(int, 100_000, "how many taken values the record keeps (the newest)", min=1)
    record = Attribute(str, "", "a JSON file the record goes to when the consumer stops; empty: none")
    stop_after = Attribute(int, 0, "stop the application (naturally) after this many new values; 0: never", min=0)

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
                                stamp.seq if stamp else -1, stamp.time if stamp else math.nan))
        if new:
            self.consumed += 1
            if stamp is not None:
                self.record_latency(stamp)
            if self.consumed == self.stop_after and self.app is not None:
                self.app.request_stop(f"{self.name}: {self.consumed} values consumed")
        else:
            self.reused += 1
        time.sleep(self.cost_ms / 1e3)

    def on_stop(self) -> None:
        if self.record:
            save_record(self.record, {"consumed": self.consumed, "reused": self.reused, "taken": list(self.taken)})


def load_record(path: str | Path) -> SimpleNamespace:
    """A record written at stop, with ``writes`` as :class:`Written` and ``taken`` as :class:`Taken`
    (the same attributes as the live component's, so that one check reads either)."""
    record = json.loads(Path(path).read_text())
    if "writes" in record:
        record["writes"] = [Written(*entry) for entry in record["writes"]]
    if "taken" in record:
        record["taken"] = [Taken(*entry) for entry in record["taken"]]
    return SimpleNamespace(**record)
