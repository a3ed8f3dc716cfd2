"""Activities: the threads of the scheduling tree.

An activity runs its components in order, either periodically (absolute, drift-free deadlines with a
precise sleep) or when triggered (data arriving on an event port of one of its components, or an
operation queued to it). Before each cycle it runs the operation calls queued to it, so components
only ever see their state touched by their own thread. One activity may be the application's *main*
activity and run in the launcher's main thread.

Timing numbers that decided the design are in the architecture notes: a plain thread that sleeps to
0.2 ms before the deadline and then spins holds a 1 kHz period to a few microseconds at p99, far
better than an rclpy timer.
"""

from __future__ import annotations

import logging
import sys
import threading
import time
from collections import deque
from typing import Callable, Iterable

from .component import Component
from .operations import set_current_activity
from .profiling import ActivityStats
from .scheduling import SchedulingRequest, apply_to_current_thread

log = logging.getLogger("coco")

DEFAULT_SPIN = 200e-6
"""Seconds before a periodic deadline at which the coarse sleep ends and spinning begins."""


class Activity:
    """Base of periodic and triggered activities."""

    kind = "activity"
    wakes_on_data = True
    """Whether data arriving on an event port starts a cycle (triggered) or waits for one (periodic)."""
    host: Callable[[Activity], None] | None = None
    """Set by another host before :meth:`start` (``coco_ros`` runs activities as callback groups of an
    rclpy executor): ``start`` then calls ``host(self)`` instead of starting a thread, and that host
    drives :meth:`configure`, :meth:`cycle` and :meth:`finish`."""

    def __init__(
        self,
        name: str,
        components: Iterable[Component] = (),
        *,
        main: bool = False,
        scheduling: SchedulingRequest | None = None,
    ) -> None:
        self.name = name
        self.main = main
        self.scheduling = scheduling or SchedulingRequest()
        self.reserved_cores: set[int] = set()
        """Cores held exclusively by other activities (set by the application)."""
        self.components: list[Component] = []
        self.stats = ActivityStats()
        self.current: Component | None = None
        """The component being updated right now: named when the activity does not stop in time."""
        self._position = sys.maxsize
        """Index of ``current`` in ``components`` during a cycle; ``sys.maxsize`` between cycles."""
        self._ops: deque[Callable[[], None]] = deque()
        self._wake = threading.Event()
        self._stopping = False
        self._started = False
        self._entered = False
        """Whether a thread runs (or will run) the body: a main activity enters it only in run_here."""
        self._finished = threading.Event()
        self._thread: threading.Thread | None = None
        for component in components:
            self.add(component)

    def add(self, component: Component) -> None:
        """Schedule ``component`` (and so its peers) in this activity."""
        if component.owner is not None:
            raise ValueError(f"component {component.name} is a peer of {component.owner.name}; "
                             "peers are run by their owner, not scheduled")
        if component.activity is not None and component.activity is not self:
            raise ValueError(f"component {component.name} is already in activity {component.activity.name}")
        component.activity = self
        self.components.append(component)
        self._bind_wake(len(self.components) - 1, component)

    def _bind_wake(self, position: int, component: Component) -> None:
        """Let every input of ``component`` (at ``position`` in the order) and its peers wake this
        activity (event ports use it)."""
        wake = self._waker(position) if self.wakes_on_data else None
        for member in component.walk():
            for port in member.inputs.values():
                port.set_wake(wake)

    def _waker(self, position: int) -> Callable[[], None]:
        """The wake-up of the inputs of the component at ``position``: none while a cycle has yet to
        update that component (an earlier one of the pipeline wrote to it, or another thread did
        before the cycle reached it), since that cycle reads the data; otherwise :meth:`wake`, so the
        data gets a cycle of its own. Without this, every pipeline in one activity ran one empty cycle
        after each real one. ``_position`` only grows during a cycle, and the data is stored before
        the wake-up, so a skipped wake-up's data is always read."""
        def wake() -> None:
            if position <= self._position:
                self.wake()  # looked up at each call: a host may replace ``wake``

        return wake

    @property
    def running(self) -> bool:
        """Started and not yet finished: calls from other threads must be queued."""
        return self._started and not self._finished.is_set()

    @property
    def finished(self) -> bool:
        return self._finished.is_set()

    def start(self) -> None:
        """Start the thread (a main activity only marks itself started: call :meth:`run_here`)."""
        if self._started:
            raise RuntimeError(f"activity {self.name} was already started")
        self._started = True
        for position, component in enumerate(self.components):  # ports and peers may have been added
            self._bind_wake(position, component)
        if self.host is not None:
            self._entered = True
            self.host(self)
        elif not self.main:
            self._entered = True
            self._thread = threading.Thread(target=self.run_here, name=f"coco:{self.name}", daemon=True)
            self._thread.start()

    def run_here(self) -> None:
        """The activity's body, in the calling thread: configure, loop until stopped, stop components."""
        self._started = self._entered = True
        set_current_activity(self)
        try:
            for warning in apply_to_current_thread(self.scheduling, self.reserved_cores):
                log.warning("activity %s: %s", self.name, warning)
            self.configure()
            if not self._stopping:
                self._loop()
        finally:
            self.finish()
            set_current_activity(None)

    # The three steps of an activity's life, public so that another host (an rclpy executor running
    # the activity as a callback group) can drive them instead of the activity's own thread.
    def configure(self) -> None:
        """Configure the components, in order, unless a stop was asked meanwhile."""
        self._started = self._entered = True
        for component in self.components:
            if not self._stopping:
                component.configure()

    def cycle(self) -> None:
        """One activation: queued operation calls, then every component in order."""
        if self._ops:
            self._run_pending()
        try:
            for position, component in enumerate(self.components):
                self.current, self._position = component, position
                component.step()
        finally:  # a stale position would keep later wake-ups from waking the activity
            self.current, self._position = None, sys.maxsize
        self.stats.cycles += 1

    def finish(self) -> None:
        """Run what was queued, stop the components (``on_stop``) and mark the activity finished."""
        self._run_pending()
        for component in self.components:
            component.stop()
        self._finished.set()
        self._run_pending()

    @property
    def stopping(self) -> bool:
        return self._stopping

    @property
    def wake_pending(self) -> bool:
        """Whether a wake-up (data, a queued call) is waiting for the next cycle; a host taking the
        activity over must not lose it."""
        return self._wake.is_set()

    def _loop(self) -> None:
        raise NotImplementedError

    def _run_pending(self) -> None:
        ops = self._ops
        while ops:
            try:
                ops.popleft()()
            except Exception:  # an operation's own errors go to its future; this is a bug guard
                log.exception("activity %s: queued call failed", self.name)

    def enqueue(self, call: Callable[[], None]) -> None:
        """Queue ``call`` to run in this activity before its next cycle."""
        self._ops.append(call)
        if self._finished.is_set():  # the activity's last drain may have run already: do not lose it
            self._run_pending()
        else:
            self.wake()

    def wake(self) -> None:
        """Ask a triggered activity for one more cycle (what event ports call on new data)."""
        self._wake.set()

    def stop(self) -> None:
        """Ask the activity to finish its current cycle and stop; returns at once."""
        self._stopping = True
        self._wake.set()

    def join(self, timeout: float | None = None) -> bool:
        """Wait until the activity has finished; False on timeout."""
        return self._finished.wait(timeout) if self._entered else True

    def describe(self) -> str:
        return self.kind

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r} {self.describe()}>"


class PeriodicActivity(Activity):
    """Runs every ``period`` seconds on absolute deadlines: late cycles never shift later ones.

    A cycle that ends after the next deadline is an *overrun*; the deadlines it missed are skipped so
    the activity stays on its time grid. Queued operations and data on event ports wait for the next
    deadline.
    """

    kind = "periodic"
    wakes_on_data = False

    def __init__(self, name: str, period: float, components: Iterable[Component] = (), *,
                 spin: float = DEFAULT_SPIN, **options: object) -> None:
        super().__init__(name, components, **options)  # type: ignore[arg-type]
        if period <= 0:
            raise ValueError(f"activity {name}: the period must be positive, got {period}")
        self._period = period
        self.spin = spin
        self._interrupt = threading.Event()
        """Ends the coarse sleep early: a stop or a period change (data never does)."""

    @property
    def period(self) -> float:
        return self._period

    def set_period(self, period: float) -> None:
        """Change the period at run time: the next cycle comes ``period`` after the last one began
        (at once if that is already past), and the time grid continues from there."""
        if period <= 0:
            raise ValueError(f"activity {self.name}: the period must be positive, got {period}")
        self._period = period
        self._interrupt.set()

    def wake(self) -> None:
        """Data on an event port does not advance a periodic activity: it is read at the next cycle."""

    def stop(self) -> None:
        super().stop()
        self._interrupt.set()

    def _loop(self) -> None:
        clock = time.perf_counter
        stats = self.stats
        period = self._period
        deadline = clock()
        while not self._stopping:
            self.cycle()
            deadline += period
            now = clock()
            if now > deadline:
                stats.overruns += 1
                deadline += (int((now - deadline) / period) + 1) * period
            woke = self._sleep_until(deadline)
            while woke is None:  # interrupted: stopping, or a new period
                if self._stopping:
                    return
                deadline, period = max(deadline - period + self._period, clock()), self._period
                woke = self._sleep_until(deadline)
            stats.record_error(woke - deadline)

    def _sleep_until(self, deadline: float) -> float | None:
        """Sleep coarsely, then spin to ``deadline``; the wake-up time, or None when interrupted."""
        remaining = deadline - time.perf_counter()
        if remaining > self.spin and self._interrupt.wait(remaining - self.spin):
            self._interrupt.clear()
            return None
        while (now := time.perf_counter()) < deadline:
            if self._stopping:
                return None
        return now

    def describe(self) -> str:
        return f"periodic {self._period * 1e3:g} ms"


class TriggeredActivity(Activity):
    """Runs one cycle each time it is woken: data on an event port, a queued operation, or ``wake()``.

    Wake-ups that arrive during a cycle are not lost: they cause one more cycle, unless the data is
    for a component that cycle has yet to update (a pipeline's stages in one activity: each stage's
    output is read by the next in the same cycle).
    """

    kind = "triggered"

    def _loop(self) -> None:
        wait, clear = self._wake.wait, self._wake.clear
        while not self._stopping:
            wait()
            clear()
            if self._stopping:
                break
            self.cycle()
