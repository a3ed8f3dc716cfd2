"""The replay clock: which bag time is due now, at a rate factor, paused or stepped.

Bag times are integer nanoseconds (the log times of the bag). The clock is anchored at one bag
time and one ``time.monotonic()`` instant; a bag time ``t`` is due once
``monotonic() >= wall_anchor + (t - bag_anchor) / rate``. Changing the rate, pausing or resuming
re-anchors at the current bag time, so none of these makes the replay jump or burst.

``rate <= 0`` (or ``inf``) means *as fast as possible*: every time is due at once, and the clock's
time is the time of the last message released.

While paused nothing is due, except that :meth:`step` grants *n* releases: the next *n* messages
are released at once and the clock's time follows them (the time a ``/clock`` publisher sends).
Thread-safe: the player's thread asks, operations from any thread pause, resume and step.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Callable

from coco_core.errors import ReplayError

MAX_SLEEP = 0.05
"""Seconds :meth:`PlaybackClock.wait` sleeps at most at once, so pause and stop react quickly."""


class PlaybackClock:
    """Bag time (ns) <-> monotonic wall time, at ``rate`` times real time."""

    def __init__(self, rate: float = 1.0, *, paused: bool = False,
                 monotonic: Callable[[], float] = time.monotonic) -> None:
        self._monotonic = monotonic
        self._lock = threading.Lock()
        self._rate = self._checked(rate)
        self._bag_anchor = 0
        self._wall_anchor = monotonic()
        self._paused = paused
        self._credits = 0
        self._last = 0
        """Bag time of the last release (the clock's time while paused or as fast as possible)."""

    @staticmethod
    def _checked(rate: float) -> float:
        rate = float(rate)
        if math.isnan(rate) or rate < 0:
            raise ReplayError(f"the replay rate must be a factor >= 0 (0: as fast as possible), got {rate}")
        return rate

    # -- state -----------------------------------------------------------------------------------
    @property
    def rate(self) -> float:
        return self._rate

    @property
    def as_fast_as_possible(self) -> bool:
        return self._rate == 0 or math.isinf(self._rate)

    @property
    def paused(self) -> bool:
        return self._paused

    def _now_locked(self) -> int:
        if self._paused or self.as_fast_as_possible:
            return self._last
        elapsed = self._monotonic() - self._wall_anchor
        return max(self._last, self._bag_anchor + int(elapsed * self._rate * 1e9))

    def now(self) -> int:
        """The current bag time in ns (what ``/clock`` publishes)."""
        with self._lock:
            return self._now_locked()

    # -- control ---------------------------------------------------------------------------------
    def reset(self, bag_time: int) -> None:
        """Anchor bag time ``bag_time`` at this instant (start of a pass, a seek)."""
        with self._lock:
            self._bag_anchor = self._last = int(bag_time)
            self._wall_anchor = self._monotonic()

    def set_rate(self, rate: float) -> None:
        rate = self._checked(rate)
        with self._lock:
            self._reanchor()
            self._rate = rate

    def pause(self) -> None:
        with self._lock:
            if not self._paused:
                self._last = self._now_locked()
                self._paused = True
                self._credits = 0

    def resume(self) -> None:
        with self._lock:
            if self._paused:
                self._paused = False
                self._credits = 0
                self._bag_anchor, self._wall_anchor = self._last, self._monotonic()

    def step(self, count: int = 1) -> None:
        """Release the next ``count`` messages now (pauses first if running)."""
        if count < 1:
            raise ReplayError(f"step count must be >= 1, got {count}")
        with self._lock:
            if not self._paused:
                self._last = self._now_locked()
                self._paused = True
            self._credits += int(count)

    def _reanchor(self) -> None:
        self._last = self._now_locked()
        self._bag_anchor, self._wall_anchor = self._last, self._monotonic()

    # -- pacing ----------------------------------------------------------------------------------
    def release(self, bag_time: int) -> bool:
        """Whether a message logged at ``bag_time`` is due now; True consumes a step when paused."""
        with self._lock:
            if self._paused:
                if self._credits <= 0:
                    return False
                self._credits -= 1
                self._last = max(self._last, bag_time)
                return True
            if self.as_fast_as_possible:
                self._last = max(self._last, bag_time)
                return True
            due = self._wall_anchor + (bag_time - self._bag_anchor) / (self._rate * 1e9)
            if self._monotonic() >= due:
                self._last = max(self._last, bag_time)
                return True
            return False

    def delay(self, bag_time: int) -> float:
        """Seconds until ``bag_time`` is due (``inf`` while paused without steps)."""
        with self._lock:
            if self._paused:
                return 0.0 if self._credits > 0 else math.inf
            if self.as_fast_as_possible:
                return 0.0
            due = self._wall_anchor + (bag_time - self._bag_anchor) / (self._rate * 1e9)
            return max(0.0, due - self._monotonic())

    def wait(self, bag_time: int, stop: threading.Event | None = None,
             idle: Callable[[], None] | None = None) -> bool:
        """Block until ``bag_time`` is due and release it; False when ``stop`` was set first.

        Sleeps at most :data:`MAX_SLEEP` at once; ``idle`` is called between sleeps (e.g. to publish
        ``/clock``).
        """
        stop = stop or threading.Event()
        while not stop.is_set():
            if self.release(bag_time):
                return True
            if idle is not None:
                idle()
            stop.wait(min(self.delay(bag_time), MAX_SLEEP))
        return False
