"""An activity's schedule as a value: when it cycles, read by whatever drives it.

A periodic activity cycles every ``period`` seconds on an absolute, drift-free time grid
(:class:`~coco_core.period.PeriodGrid`, kept by its driver); a triggered one when it is woken (data on
an event port, a queued operation), no sooner than ``min_period`` after its last cycle began when it
has one. The bound is the schedule's, not a component's: a display woken by every camera frame and
hand pose that must not draw faster than its rate, or any activity woken faster than it should
compute, gets it from its schedule, and its components never know when or in which thread they run
(the paper's scheduling tree). The drivers of :mod:`coco_core.drivers` and ``coco_ros.hosting``
read this value instead of asking which subclass the activity is, and a period changes only through
:meth:`Schedule.with_period`, which checks it (``Activity.set_period`` is the one path to it).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from .errors import ActivityError
from .period import MAX_PERIOD, check_period

DEFAULT_SPIN = 200e-6
"""Seconds before a periodic deadline at which a thread driver's coarse sleep ends and spinning begins."""


@dataclass(frozen=True)
class Schedule:
    """When an activity cycles."""

    period: float | None = None
    """Seconds between cycles; None: triggered."""
    spin: float = DEFAULT_SPIN
    """Seconds before each deadline at which a thread driver stops sleeping and spins (periodic)."""
    min_period: float = 0.0
    """Triggered: seconds from the start of one cycle to the start of the next, at least (0: no
    bound). Wake-ups within it wait for the bound and then cause one cycle, which reads the newest of
    every input."""

    @classmethod
    def periodic(cls, period: float, owner: str = "", spin: float = DEFAULT_SPIN) -> Schedule:
        """Every ``period`` seconds (checked: ``owner`` names the activity in the error)."""
        return cls(check_period(period, owner), spin)

    @classmethod
    def triggered(cls, min_period: float = 0.0, owner: str = "") -> Schedule:
        """When woken, no sooner than ``min_period`` seconds after the last cycle began (checked: 0,
        no bound, up to :data:`~coco_core.period.MAX_PERIOD`; ``owner`` names the activity in the
        error)."""
        if not 0 <= min_period <= MAX_PERIOD:
            raise ActivityError(f"{owner}the minimum period must be from 0 (no bound) to {MAX_PERIOD:g} s "
                                f"(a day), got {min_period} s")
        return cls(min_period=min_period)

    @property
    def is_periodic(self) -> bool:
        return self.period is not None

    def with_period(self, period: float, owner: str = "") -> Schedule:
        """This schedule with a new, checked period; a triggered schedule has none to change."""
        if self.period is None:
            raise ActivityError(f"{owner}a triggered activity has no period to change")
        return replace(self, period=check_period(period, owner))

    def describe(self) -> str:
        """``periodic 1 ms``, ``triggered`` or ``triggered, at most every 16 ms``."""
        if self.period is not None:
            return f"periodic {self.period * 1e3:g} ms"
        return f"triggered, at most every {self.min_period * 1e3:g} ms" if self.min_period else "triggered"
