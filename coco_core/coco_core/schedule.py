"""An activity's schedule as a value: when it cycles, read by whatever drives it.

A periodic activity cycles every ``period`` seconds on an absolute, drift-free time grid
(:class:`~coco_core.period.PeriodGrid`, kept by its driver); a triggered one when it is woken (data on
an event port, a queued operation). The drivers of :mod:`coco_core.drivers` and ``coco_ros.hosting``
read this value instead of asking which subclass the activity is, and a period changes only through
:meth:`Schedule.with_period`, which checks it (``Activity.set_period`` is the one path to it).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from .errors import ActivityError
from .period import check_period

DEFAULT_SPIN = 200e-6
"""Seconds before a periodic deadline at which a thread driver's coarse sleep ends and spinning begins."""


@dataclass(frozen=True)
class Schedule:
    """When an activity cycles."""

    period: float | None = None
    """Seconds between cycles; None: triggered."""
    spin: float = DEFAULT_SPIN
    """Seconds before each deadline at which a thread driver stops sleeping and spins (periodic)."""

    @classmethod
    def periodic(cls, period: float, owner: str = "", spin: float = DEFAULT_SPIN) -> Schedule:
        """Every ``period`` seconds (checked: ``owner`` names the activity in the error)."""
        return cls(check_period(period, owner), spin)

    @property
    def is_periodic(self) -> bool:
        return self.period is not None

    def with_period(self, period: float, owner: str = "") -> Schedule:
        """This schedule with a new, checked period; a triggered schedule has none to change."""
        if self.period is None:
            raise ActivityError(f"{owner}a triggered activity has no period to change")
        return replace(self, period=check_period(period, owner))

    def describe(self) -> str:
        return "triggered" if self.period is None else f"periodic {self.period * 1e3:g} ms"
