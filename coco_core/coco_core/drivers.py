"""What drives an activity: its own thread, the launcher's main thread, or another host.

An :class:`~coco_core.activity.Activity` is what runs (components, operation queue, ``configure`` /
``cycle`` / ``finish``, stats, its schedule); a *driver* decides when and in which thread. This is
OROCOS RTT's split of ``RunnableInterface`` (the activity's steps) from ``ActivityInterface`` (a
thread, a slave driven by another, ...): the same activity runs unchanged under every driver, and a
launch host with its own way of running activities brings its own driver (``HOSTED`` in the
deployment plan) instead of changing the activity. Every driver has the protocol of :class:`Driver`.

The thread drivers sleep coarsely and then spin to each periodic deadline: the architecture notes
measured that a plain thread doing so holds a 1 kHz period to a few microseconds at p99, far better
than a middleware's timer.
"""

from __future__ import annotations

import enum
import logging
import threading
import time
from typing import TYPE_CHECKING, Protocol

from .cpu import CpuUse
from .operations import set_current_activity
from .period import PeriodGrid
from .thread_placement import apply_to_current_thread
from .wakeup import Wakeup

if TYPE_CHECKING:
    from .activity import Activity

log = logging.getLogger("coco")


class Driving(str, enum.Enum):
    """What drives an activity, as the deployment plan (:mod:`coco_core.deployment`) names it."""

    THREAD = "own thread"
    MAIN = "main thread"
    HOSTED = "hosted"
    """The launch host's own driver (the plan's words for the activity say which)."""


class Driver(Protocol):
    """When and where an activity's steps run. Called by the activity only (its methods of the same
    names delegate here), so that ports, operations and the application never know the driver."""

    @property
    def driving(self) -> Driving:
        """What kind of driver this is, in the deployment plan's words."""

    @property
    def eventfd(self) -> Wakeup | None:
        """The eventfd through which other processes wake the activity; None: they do not."""

    def start(self, activity: Activity) -> None:
        """Begin driving ``activity``: configure it, then cycle it by its schedule until stopped."""

    def wake(self) -> None:
        """One more cycle of a triggered activity (data on an event port, a queued operation)."""

    @property
    def wake_pending(self) -> bool:
        """Whether a wake-up waits for a cycle that has not begun: data is still in flight."""

    def stop(self) -> None:
        """End after the current cycle (``finish`` runs ``on_stop``); returns at once."""

    def set_period(self, period: float) -> None:
        """The activity's period changed (it is stored already): apply it from the next cycle on."""

    def join(self, timeout: float | None = None) -> bool:
        """Wait until the activity has finished; False on timeout."""


class ThreadDriver:
    """Runs the activity in a thread of its own: periodic on the activity's time grid with a precise
    sleep, triggered on each wake-up (no sooner than the schedule's ``min_period`` after the last
    cycle began, when it has one). Wake-ups that arrive during a cycle are not lost: they cause one
    more cycle.

    ``eventfd``: a Linux eventfd (a kernel counter that any process holding the descriptor can
    increment) that wakes the activity instead of a thread event. A triggered activity that reads a
    connection from another process is driven so, and the writer's process wakes it directly (one
    ``write`` system call), without a relay thread; wake-ups from its own process go the same way. A
    periodic activity is never woken by data: it ignores the descriptor."""

    driving = Driving.THREAD

    def __init__(self, eventfd: Wakeup | None = None) -> None:
        self.eventfd = eventfd
        self._wake = threading.Event()
        self._interrupt = threading.Event()
        """Ends a periodic activity's coarse sleep early (a stop or a period change), and a triggered
        one's wait for its ``min_period`` (a stop); data never does."""
        self._activity: Activity | None = None
        self._entered = False
        """Whether a thread runs (or will run) the activity: a main activity's only once it is run."""
        self._thread: threading.Thread | None = None

    def start(self, activity: Activity) -> None:
        self._activity, self._entered = activity, True
        self._thread = threading.Thread(target=self.run, args=(activity,), name=f"coco:{activity.name}",
                                        daemon=True)
        self._thread.start()

    def run(self, activity: Activity) -> None:
        """The activity's life in the calling thread: configure, loop until stopped, finish."""
        self._activity, self._entered = activity, True
        self._thread = threading.current_thread()
        set_current_activity(activity)
        began, cpu = time.perf_counter(), time.thread_time()
        try:
            for warning in apply_to_current_thread(activity.scheduling, activity.reserved_cores):
                log.warning("activity %s: %s", activity.name, warning)
            activity.configure()
            activity.wait_may_run()  # every activity of the application configured (or a stop)
            if not activity.stopping:
                period = activity.schedule.period
                if period is None:
                    self._triggered(activity)
                else:
                    self._periodic(activity, PeriodGrid(period, activity.stats))
        except Exception as error:  # the driver's own failure: the components' errors never reach here
            activity.fail(error)
        finally:
            activity.finish()
            activity.stats.thread_cpu = CpuUse(time.thread_time() - cpu, time.perf_counter() - began)
            set_current_activity(None)

    def _triggered(self, activity: Activity) -> None:
        """Cycle when woken (the eventfd's counter, or the thread event), and with a ``min_period`` no
        sooner than that after the last cycle began. The bound is waited out *before* the wait for a
        wake-up: the wake-ups that come meanwhile are all taken at once after it, and cause one cycle
        at the bound (which reads the newest of every input), not one each. The wait is on
        ``_interrupt``, so a stop ends it at once."""
        min_period = activity.schedule.min_period
        clock, interrupted = time.perf_counter, self._interrupt.wait
        if self.eventfd is not None:
            woken = self.eventfd.wait  # blocks with the GIL released until the counter is non-zero, then clears it
        else:
            event = self._wake

            def woken() -> None:
                event.wait()
                event.clear()

        began = float("-inf")  # no cycle yet: nothing to wait for
        while not activity.stopping:
            if min_period:
                while (remaining := began + min_period - clock()) > 0 and not activity.stopping:
                    interrupted(remaining)
            woken()
            if activity.stopping:
                break
            if min_period:
                began = clock()
            activity.cycle()

    def _periodic(self, activity: Activity, grid: PeriodGrid) -> None:
        """Cycle on ``grid``, this driver's own: only this thread touches it."""
        clock = time.perf_counter
        grid.begin(clock())
        garbage = activity.garbage
        while not activity.stopping:
            activity.cycle()
            deadline = grid.after_cycle(clock())
            if garbage is not None:
                garbage.after_cycle(deadline, clock())
            woke = self._sleep_until(activity, deadline)
            while woke is None:  # interrupted: stopping, or a new period
                if activity.stopping:
                    return
                period = activity.schedule.period
                assert period is not None  # a periodic schedule keeps a period
                deadline = grid.change_period(period, clock())
                woke = self._sleep_until(activity, deadline)
            grid.woke(woke)

    def _sleep_until(self, activity: Activity, deadline: float) -> float | None:
        """Sleep coarsely, then spin to ``deadline``; the wake-up time, or None when interrupted."""
        remaining = deadline - time.perf_counter()
        spin = activity.schedule.spin
        if remaining > spin and self._interrupt.wait(remaining - spin):
            self._interrupt.clear()
            return None
        while (now := time.perf_counter()) < deadline:
            if activity.stopping:
                return None
        return now

    @property
    def thread(self) -> threading.Thread | None:
        """The thread that runs the activity (None before it started, or while a main activity waits
        for the launcher's thread)."""
        return self._thread

    def wake(self) -> None:
        if self.eventfd is not None:
            self.eventfd.wake()
        else:
            self._wake.set()

    @property
    def wake_pending(self) -> bool:
        return self.eventfd.pending if self.eventfd is not None else self._wake.is_set()

    def stop(self) -> None:
        self._wake.set()
        self._interrupt.set()
        if self.eventfd is not None:
            self.eventfd.wake()

    def set_period(self, period: float) -> None:
        self._interrupt.set()

    def join(self, timeout: float | None = None) -> bool:
        activity = self._activity
        return activity.wait_finished(timeout) if activity is not None and self._entered else True


class MainThreadDriver(ThreadDriver):
    """Runs the activity in the thread that calls :meth:`run` (the launcher's main thread, which
    some GUI toolkits require): ``start`` only marks it started, ``Activity.run_here`` runs it."""

    driving = Driving.MAIN

    def start(self, activity: Activity) -> None:
        self._activity = activity
