"""Activities: the scheduling tree's level between processes and components.

An activity runs its components in order, either periodically (on the absolute, drift-free time grid
of :mod:`coco_core.period`) or when triggered (data arriving on an event port of one of its
components, or an operation queued to it). Before each cycle it runs the operation calls queued to it,
so components only ever see their state touched by their own activity.

What an activity *is* lives here: its components, operation queue, the three steps of its life
(``configure``, ``cycle``, ``finish``), its stats and its schedule. What *drives* it (a thread of its
own, the launcher's main thread, an rclpy executor, ...) is a separate :mod:`driver
<coco_core.drivers>` object, given before the activity starts (:meth:`Activity.drive_with`); the
activity's ``wake``, ``stop``, ``set_period`` and ``join`` go to that driver, so nothing that talks to
an activity knows what drives it. Which driver is the deployment plan's word alone
(:mod:`coco_core.deployment`): an activity has none until it is given one, by its launch
(:func:`coco_core.deployment.drive`, a launch host's own driver) or, for an application built in
code, by :meth:`Application.start <coco_core.application.Application.start>` from the plan of the
application's own activities.
"""

from __future__ import annotations

import logging
import sys
import threading
from collections import deque
from typing import TYPE_CHECKING, Callable, Iterable

from .component import Component
from .drivers import Driver, ThreadDriver
from .errors import ActivityError
from .garbage import GarbageBetweenCycles
from .lifecycle import StartGate
from .profiling import ActivityStats
from .schedule import DEFAULT_SPIN, Schedule
from .thread_placement import SchedulingRequest

if TYPE_CHECKING:
    from .iteration import IterationPorts

log = logging.getLogger("coco")


class Activity:
    """What runs a list of components by its :class:`~coco_core.schedule.Schedule` (triggered unless
    given one; :class:`PeriodicActivity` and :class:`TriggeredActivity` say which by their names)."""

    def __init__(
        self,
        name: str,
        components: Iterable[Component] = (),
        *,
        schedule: Schedule = Schedule(),
        main: bool = False,
        scheduling: SchedulingRequest | None = None,
    ) -> None:
        self.name = name
        self.schedule = schedule
        """When it cycles: the drivers read it; :meth:`set_period` is the one path that changes it."""
        self.main = main
        self.process = ""
        """The ``<process>`` that runs this activity; empty: the launcher's own process."""
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
        self._driver: Driver | None = None
        """None until the plan's driver is given (:meth:`drive_with`)."""
        self._woken = False
        """A wake-up (data, a queued call) that came before the activity had a driver: handed to the
        driver it is given."""
        self._stopping = False
        self._drain = False
        """Whether the stop is natural and this activity's feeders have finished: see :meth:`stop`."""
        self._configured = False
        """Whether :meth:`configure` configured every component (no stop came first)."""
        self._started = False
        self._finished = threading.Event()
        self.failure = ""
        """Why the activity's driver failed (see :meth:`fail`); empty while it has not."""
        self._may_run = threading.Event()
        """Set when the application's :class:`~coco_core.lifecycle.StartGate` opens, or on a stop."""
        self.gate: StartGate | None = None
        """The start gate of the application (set by ``Application.start``); None: none to wait for."""
        self.garbage: GarbageBetweenCycles | None = None
        """The process's garbage collections, run between this (periodic) activity's cycles by its
        thread driver (``<process gc="between_cycles">``, see :mod:`.garbage`); None: CPython's own."""
        self.iteration: IterationPorts | None = None
        """The activity's ``beginit``/``endit`` ports (:mod:`.iteration`), made when a connection
        names one; None: the cycles wait for nothing and announce nothing."""
        for component in components:
            self.add(component)

    # --- composition and driver -----------------------------------------------------------------
    def add(self, component: Component) -> None:
        """Schedule ``component`` (and so its peers) in this activity."""
        if component.owner is not None:
            raise ActivityError(f"component {component.name} is a peer of {component.owner.name}; "
                                "peers are run by their owner, not scheduled")
        if component.activity is not None and component.activity is not self:
            raise ActivityError(f"component {component.name} is already in activity {component.activity.name}")
        component.activity = self
        self.components.append(component)
        self._bind_wake(len(self.components) - 1, component)

    @property
    def driver(self) -> Driver | None:
        """What drives this activity: the one the deployment plan names (:meth:`drive_with`); None
        before it was given one."""
        return self._driver

    @property
    def driven(self) -> bool:
        """Whether the activity was given its driver."""
        return self._driver is not None

    def drive_with(self, driver: Driver) -> None:
        """Have ``driver`` drive this activity; before :meth:`start` only. A wake-up already pending
        (data written before the start) is handed to the new driver."""
        if self._started:
            raise ActivityError(f"activity {self.name} already started: its driver cannot change")
        pending = self.wake_pending
        self._driver, self._woken = driver, False
        if pending:
            driver.wake()
        for position, component in enumerate(self.components):
            self._bind_wake(position, component)

    def _wake_before_driven(self) -> None:
        self._woken = True

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
        before the cycle reached it), since that cycle reads the data; otherwise the driver's, so the
        data gets a cycle of its own. Without this, every pipeline in one activity ran one empty cycle
        after each real one. ``_position`` only grows during a cycle, and the data is stored before
        the wake-up, so a skipped wake-up's data is always read."""
        wake = self._driver.wake if self._driver is not None else self._wake_before_driven

        def waker() -> None:
            if position <= self._position:
                wake()

        return waker

    # --- state ----------------------------------------------------------------------------------
    @property
    def running(self) -> bool:
        """Started and not yet finished: calls from other threads must be queued."""
        return self._started and not self._finished.is_set()

    @property
    def finished(self) -> bool:
        return self._finished.is_set()

    @property
    def stopping(self) -> bool:
        return self._stopping

    @property
    def period(self) -> float | None:
        """Seconds between cycles of a periodic activity; None for a triggered one."""
        return self.schedule.period

    @property
    def wakes_on_data(self) -> bool:
        """Whether data arriving on an event port starts a cycle (triggered) or waits for one (periodic)."""
        return self.schedule.period is None

    def set_period(self, period: float) -> None:
        """Change a periodic activity's period at run time: the next cycle comes ``period`` after the
        last one was due (at once if that is already past), and the time grid continues from there.
        The one path to a new period: it is checked here, then the driver applies it."""
        self.schedule = self.schedule.with_period(period, f"activity {self.name}: ")
        if self._driver is not None:  # else its driver reads the new period when it starts
            self._driver.set_period(period)

    @property
    def wake_pending(self) -> bool:
        """Whether a wake-up (data, a queued call) is waiting for a cycle that has not begun."""
        return self._driver.wake_pending if self._driver is not None else self._woken

    def wait_finished(self, timeout: float | None = None) -> bool:
        """Block until :meth:`finish` ran; False on timeout (for drivers' ``join``)."""
        return self._finished.wait(timeout)

    # --- life -----------------------------------------------------------------------------------
    def start(self) -> None:
        """Hand the activity to its driver (a main activity's driver waits for :meth:`run_here`)."""
        if self._started:
            raise ActivityError(f"activity {self.name} was already started")
        driver = self._driver
        if driver is None:
            raise ActivityError(f"activity {self.name} has no driver: the deployment plan gives it one "
                                "(Application.start, or a launch's coco_core.deployment.drive)")
        self._started = True
        for position, component in enumerate(self.components):  # ports and peers may have been added
            self._bind_wake(position, component)
        driver.start(self)

    def run_here(self) -> None:
        """Run the activity in the calling thread until it stops (the main activity)."""
        driver = self._driver
        if not isinstance(driver, ThreadDriver):
            raise ActivityError(f"activity {self.name} is driven by {type(driver).__name__}; "
                                "only a thread driver runs in the calling thread")
        self._started = True
        driver.run(self)

    # The three steps of an activity's life: every driver calls them, in the driver's thread.
    def configure(self) -> None:
        """Configure the components, in order, unless a stop was asked meanwhile; then tell the
        start gate (every driver calls it, then :meth:`when_may_run` or :meth:`wait_may_run` before
        the first cycle: no activity of the application cycles before all are configured)."""
        self._started = True
        for component in self.components:
            if not self._stopping:
                component.configure()
        self._configured = not self._stopping
        if self.gate is None:
            self._may_run.set()
        else:
            self.gate.when_open(self._may_run.set)
            self.gate.configured(self.name)

    @property
    def may_run(self) -> bool:
        """Whether the first cycle may run: every activity of the application is configured (or a
        stop was asked, which :meth:`cycle`'s callers check)."""
        return self._may_run.is_set()

    def wait_may_run(self) -> None:
        """Block until :attr:`may_run` (a thread driver, between ``configure`` and its first cycle)."""
        self._may_run.wait()

    def when_may_run(self, callback: Callable[[], None]) -> None:
        """Call ``callback`` once :attr:`may_run` (now, if it is): a driver that must not block its
        thread (an rclpy executor's) resumes from it."""
        if self.gate is None or self._may_run.is_set():
            callback()
        else:
            self.gate.when_open(callback)

    def cycle(self) -> None:
        """One activation: queued operation calls, then every component in order (not while the
        application is paused, :meth:`StartGate.pause`, unless it stops: its drain still runs)."""
        if self._ops:
            self._run_pending()
        if self.gate is not None and self.gate.paused and not self._stopping:
            return
        iteration = self.iteration
        if iteration is not None and not iteration.begin():
            return  # no message on beginit (FlowVR's module waits for one): no cycle
        try:
            for position, component in enumerate(self.components):
                self.current, self._position = component, position
                component.step()
        finally:  # a stale position would keep later wake-ups from waking the activity
            self.current, self._position = None, sys.maxsize
        if iteration is not None:
            iteration.end()
        self.stats.cycles += 1

    def finish(self) -> None:
        """Run the cycles that the data waiting on its event inputs asks for (a natural stop only,
        see :meth:`stop`), run what was queued, stop the components (``on_stop``) and mark the
        activity finished."""
        self._drain_inputs()
        self._run_pending()
        for component in self.components:
            component.stop()
        writers = [member for component in self.components for member in component.walk()]
        if self.iteration is not None:  # its endit, the last cycle's number written: done too
            writers.append(self.iteration)
        for member in writers:  # what on_stop wrote was the last: readers elsewhere may stop
            for port in member.outputs.values():
                for connection in port.connections:
                    connection.writer_done()
        self._finished.set()
        self._run_pending()

    def fail(self, error: BaseException) -> None:
        """The driver could not go on (an exception outside any component's callbacks, which the
        components' error policies handle): record it, log it, and stop the application, so that the
        launcher exits with 1 rather than 0 with this activity silently gone."""
        self.failure = f"{type(error).__name__}: {error}"
        log.error("activity %s failed and ended: %s", self.name, self.failure, exc_info=error)
        apps = {id(component.app): component.app for component in self.components if component.app is not None}
        for app in apps.values():
            app.request_stop(f"activity {self.name} failed: {self.failure}")

    def _drain_inputs(self) -> None:
        """After a natural stop, cycle while data waits on the connections that wake this activity:
        the last values its feeders wrote before they finished (the last frame a display rendered,
        for its writer) are processed instead of being left pending. Stops when a cycle takes none
        (a component that does not read its input) and as soon as the stop becomes hard."""
        if not (self.wakes_on_data and self._drain and self._configured):
            return
        triggering = [connection for component in self.components for member in component.walk()
                      for port in member.inputs.values() for connection in port.triggering]
        waiting = sum(connection.pending for connection in triggering)
        while waiting and self._drain:
            self.cycle()
            left = sum(connection.pending for connection in triggering)
            if left >= waiting:
                break
            waiting = left

    def _run_pending(self) -> None:
        ops = self._ops
        while ops:
            try:
                ops.popleft()()
            except Exception:  # an operation's own errors go to its future; this is a bug guard
                log.exception("activity %s: queued call failed", self.name)

    # --- what other threads ask (each goes to the driver) ---------------------------------------
    def enqueue(self, call: Callable[[], None]) -> None:
        """Queue ``call`` to run in this activity before its next cycle."""
        self._ops.append(call)
        if self._finished.is_set():  # the activity's last drain may have run already: do not lose it
            self._run_pending()
        else:
            self.wake()

    def wake(self) -> None:
        """Ask a triggered activity for one more cycle (what event ports call on new data). Data on
        an event port does not advance a periodic activity: it is read at the next cycle."""
        if self.schedule.period is None:
            if self._driver is not None:
                self._driver.wake()
            else:
                self._wake_before_driven()

    def stop(self, drain: bool = False) -> None:
        """Ask the activity to finish its current cycle and stop; returns at once.

        ``drain``: the stop is natural and every activity of this process that feeds this one has
        finished, so nothing more will come: a triggered activity first processes what waits on its
        event inputs (:meth:`finish`). A later call without it (the stop became hard) cancels that."""
        self._drain = drain
        self._stopping = True
        self._may_run.set()  # an activity waiting for the start gate finishes instead
        if self._driver is not None:  # else nothing runs it: there is nothing to end
            self._driver.stop()

    def join(self, timeout: float | None = None) -> bool:
        """Wait until the activity has finished; False on timeout."""
        return self._driver.join(timeout) if self._driver is not None else True

    def describe(self) -> str:
        return self.schedule.describe()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r} {self.describe()}>"


class PeriodicActivity(Activity):
    """Runs every ``period`` seconds on absolute deadlines (a :class:`~coco_core.period.PeriodGrid`
    its driver keeps): late cycles never shift later ones, and missed deadlines are skipped and
    counted as overruns. Queued operations and data on event ports wait for the next deadline."""

    def __init__(self, name: str, period: float, components: Iterable[Component] = (), *,
                 spin: float = DEFAULT_SPIN, **options: object) -> None:
        super().__init__(name, components, schedule=Schedule.periodic(period, f"activity {name}: ", spin),
                         **options)  # type: ignore[arg-type]

    @property
    def period(self) -> float:
        period = self.schedule.period
        assert period is not None  # a periodic schedule keeps a period
        return period


class TriggeredActivity(Activity):
    """Runs one cycle each time it is woken: data on an event port, a queued operation, or ``wake()``.

    Wake-ups that arrive during a cycle are not lost: they cause one more cycle, unless the data is
    for a component that cycle has yet to update (a pipeline's stages in one activity: each stage's
    output is read by the next in the same cycle).

    ``min_period``: seconds from the start of one cycle to the start of the next, at least (0: no
    bound); the wake-ups within it cause one cycle at the bound (:attr:`Schedule.min_period
    <coco_core.schedule.Schedule.min_period>`).
    """

    def __init__(self, name: str, components: Iterable[Component] = (), *, min_period: float = 0.0,
                 **options: object) -> None:
        super().__init__(name, components, schedule=Schedule.triggered(min_period, f"activity {name}: "),
                         **options)  # type: ignore[arg-type]
