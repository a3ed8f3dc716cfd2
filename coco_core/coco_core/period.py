"""The time grid of a periodic activity: absolute deadlines, written once for every driver.

A periodic activity's deadlines lie on a grid ``start + k * period``: a late cycle never shifts the
later ones (no drift). A cycle that ends, or a wake-up that comes, a whole period or more after its
deadline is an *overrun*; the deadlines it missed are skipped so the activity stays on its grid.
Every driver (its own thread, an rclpy timer, a child process's thread) keeps the grid with this one
class, so the period error and the overruns in the profile mean the same whatever drives the
activity.
"""

from __future__ import annotations

from .errors import ActivityError
from .profiling import ActivityStats

MAX_PERIOD = 86_400.0
"""The longest period, in seconds (a day): a larger one is a mistake, and one beyond what a timed wait
takes (``threading.TIMEOUT_MAX``, about 292 years) ended the activity's thread at its first sleep."""


def check_period(period: float, owner: str = "") -> float:
    """``period`` (seconds) when it is a valid period: greater than 0 and at most :data:`MAX_PERIOD`
    (NaN is neither); else :class:`ActivityError`, naming ``owner`` (``activity x: ``)."""
    if not 0 < period <= MAX_PERIOD:
        raise ActivityError(f"{owner}the period must be greater than 0 and at most {MAX_PERIOD:g} s "
                            f"(a day), got {period} s")
    return period


class PeriodGrid:
    """Deadlines ``period`` apart from a start time; records period errors and overruns in ``stats``."""

    __slots__ = ("period", "deadline", "stats")

    def __init__(self, period: float, stats: ActivityStats) -> None:
        self.period = check_period(period)
        self.deadline = 0.0
        """The deadline of the next cycle (``time.perf_counter`` seconds)."""
        self.stats = stats

    def begin(self, now: float) -> None:
        """The grid starts at ``now``: the first cycle is due at once."""
        self.deadline = now

    def after_cycle(self, now: float) -> float:
        """A cycle ended at ``now``: the next deadline, past the missed ones (each skip is an overrun)."""
        period = self.period
        deadline = self.deadline + period
        if now > deadline:
            self.stats.overruns += 1
            deadline += (int((now - deadline) / period) + 1) * period
        self.deadline = deadline
        return deadline

    def woke(self, now: float) -> None:
        """A sleep to :attr:`deadline` ended at ``now``: record the period error."""
        self.stats.record_error(now - self.deadline)

    def fired(self, now: float) -> None:
        """A timer that keeps its own grid fired at ``now`` for :attr:`deadline`: record the error and
        advance. A wake-up a whole period or more late is an overrun, and the deadlines it missed are
        skipped, as :meth:`after_cycle` skips them for a driver that sleeps by itself."""
        period = self.period
        late = now - self.deadline
        if late >= period:
            self.stats.overruns += 1
            missed = int(late // period)
            self.deadline += missed * period
            late -= missed * period
        self.stats.record_error(late)
        self.deadline += period

    def change_period(self, period: float, now: float) -> float:
        """A new period: the next cycle comes ``period`` after the last one was due (at once if that
        is already past), and the grid continues from there; returns the new next deadline."""
        check_period(period)
        self.deadline = max(self.deadline - self.period + period, now)
        self.period = period
        return self.deadline
