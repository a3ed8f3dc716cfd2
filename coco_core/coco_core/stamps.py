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
    """Acquisition time (``time.perf_counter`` seconds in this process), sequence number and source."""

    time: float
    seq: int = 0
    source: str = ""
    steps: tuple[tuple[str, float], ...] = ()
    """Named times (``perf_counter`` seconds) the data passed on its way from the acquisition, in
    order, appended by the stages that choose to (FlowVR's stamps carry such fields too): a latency
    from the acquisition to an output is then split step by step where it was spent (the remote
    palpation app: sent, received, meshed, built, frame start, drawn, read back)."""

    @classmethod
    def now(cls, seq: int = 0, source: str = "") -> Stamp:
        return cls(time.perf_counter(), seq, source)

    def age(self) -> float:
        """Seconds since acquisition."""
        return time.perf_counter() - self.time

    def step(self, name: str, at: float | None = None) -> Stamp:
        """This stamp with the step ``name`` passed at ``at`` (default: now) appended to ``steps``."""
        return Stamp(self.time, self.seq, self.source, (*self.steps, (name, time.perf_counter() if at is None else at)))

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
