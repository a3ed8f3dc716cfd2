"""Message stamps (FlowVR's term): where and when a piece of data was born.

A stamp travels with data through every port, so latency can be measured end to end, from the
acquisition of a sample to whatever output it produced, whatever components and threads it crossed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Generic, TypeVar

T = TypeVar("T")


@dataclass(frozen=True, slots=True)
class Stamp:
    """Acquisition time (``time.perf_counter`` seconds in this process), sequence number and source.

    The stamp of a *message* (what an output port made of a write, :class:`Message`) has FlowVR's
    fields: ``seq`` is the message's number on its port (FlowVR's ``num``), ``source`` the writing
    port (``component.port``) and ``it`` the iteration of the writing activity (FlowVR's ``it``), so
    that a filter or a reader can route, sample and check messages without reading their payload."""

    time: float
    seq: int = 0
    source: str = ""
    steps: tuple[tuple[str, float], ...] = ()
    """Named times (``perf_counter`` seconds) the data passed on its way from the acquisition, in
    order, appended by the stages that choose to (FlowVR's stamps carry such fields too): a latency
    from the acquisition to an output is then split step by step where it was spent (the remote
    palpation app: sent, received, meshed, built, frame start, drawn, read back)."""
    it: int = -1
    """The iteration (cycle number, from 0) of the activity whose component wrote the message; -1:
    not written through a port, or by a component no activity runs."""

    @classmethod
    def now(cls, seq: int = 0, source: str = "") -> Stamp:
        return cls(time.perf_counter(), seq, source)

    def age(self) -> float:
        """Seconds since acquisition."""
        return time.perf_counter() - self.time

    def step(self, name: str, at: float | None = None) -> Stamp:
        """This stamp with the step ``name`` passed at ``at`` (default: now) appended to ``steps``."""
        return Stamp(self.time, self.seq, self.source, (*self.steps, (name, time.perf_counter() if at is None else at)),
                     self.it)

    def intervals(self) -> list[tuple[str, float]]:
        """Seconds from each step's predecessor (the acquisition for the first) to it, by step name."""
        times = [self.time, *(at for _, at in self.steps)]
        return [(name, times[index + 1] - times[index]) for index, (name, _) in enumerate(self.steps)]


@dataclass(frozen=True, slots=True)
class Stamped(Generic[T]):
    """A value with its stamp, the usual payload of a port that carries measurements."""

    value: T
    stamp: Stamp = field(default_factory=Stamp.now)


def unstamped(value: T | Stamped[T]) -> tuple[T, Stamp | None]:
    """``(value, stamp)`` of a :class:`Stamped` value, ``(value, None)`` of a plain one.

    Lets an input take both, so a producer can start stamping its values (for end-to-end latency)
    without breaking the consumers that were written for plain ones."""
    if isinstance(value, Stamped):
        return value.value, value.stamp
    return value, None


class Message:
    """A value as it travels on a connection inside one process: the payload and the fields of the
    stamp the writing port gave it. The port wraps and the reading port unwraps, so components see
    the plain value (a :class:`Stamped` one included, unchanged) and the stamp is read beside it
    (:attr:`InputPort.stamp <coco_core.ports.InputPort.stamp>`), or alone by a filter.

    The :class:`Stamp` object is made only when asked for (:attr:`stamp`): a write costs a few
    slot stores, not a frozen dataclass, since most messages are read without their stamp."""

    __slots__ = ("value", "time", "seq", "source", "it")

    def __init__(self, value: object, time: float, seq: int, source: str, it: int) -> None:
        self.value = value
        self.time = time
        """When it was written (``perf_counter`` seconds)."""
        self.seq = seq
        self.source = source
        self.it = it

    @property
    def stamp(self) -> Stamp:
        """The message's stamp: a :class:`Stamped` value's acquisition time and steps, else the
        time of the write."""
        value = self.value
        if isinstance(value, Stamped):
            return Stamp(value.stamp.time, self.seq, self.source, value.stamp.steps, self.it)
        return Stamp(self.time, self.seq, self.source, (), self.it)

    def __repr__(self) -> str:
        return f"<Message it={self.it} seq={self.seq} from {self.source}>"
