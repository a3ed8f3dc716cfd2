"""The application's life cycle: configure all, then start all; and how long a stop may take.

The CoCo paper and OROCOS RTT configure a whole application before they start it: ``on_config``
of every component runs, then the first cycle of any activity. Without that rule an activity that
produces data (a bag replay) can emit before its readers are configured: a reader that publishes its
initial state in ``on_config`` (a fixed pose) then stamps it after data already emitted, or a
component that subscribes in ``on_config`` misses what came first.

A :class:`StartGate` holds that rule for one process. Each activity configures in its driver's
thread (a thread-bound component needs it there), says so (:meth:`StartGate.configured`) and waits
for the gate before its first cycle; the gate opens once every activity it expects has configured.
Where the application spans processes, the launcher's gate also expects every child's activities:
a child's gate is *held* (:meth:`StartGate.hold`), it tells the launcher when its own activities are
configured, and opens when the launcher's gate opens. Every driver and launcher (``coco-launch``, the
ROS launcher, their children, every ROS hosting) goes through this one gate, and a stop opens it so
that nothing waits for a start that will not come.

The stop has two kinds. A *hard* stop (a signal, a fault: a component's error policy, a dead
process, an executor that failed) gives every activity :data:`STOP_TIMEOUT` seconds in all, so that
Ctrl-C ends a run within a second. A *natural* stop, one the application asked for itself (the end of
a bag, a trajectory that is over, ``--duration``), lets every activity finish its work and flush (a
video writer encoding its last frames on a loaded machine needs more than a second): it waits as
long as the application makes progress (:class:`Progress`: its processes use the CPU, or an
activity finishes), and gives up only after :data:`STOP_TIMEOUT` seconds without any. A hard stop
that comes during a natural one (Ctrl-C) bounds it again.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable

from .cpu import process_cpu

STOP_TIMEOUT = 1.0
"""Seconds every activity gets, together, to finish its cycle and run ``on_stop`` after a hard stop;
after a natural stop, the longest time without progress."""
PROGRESS_CPU = 0.05
"""CPU seconds the application's processes must use during :data:`STOP_TIMEOUT` to count as working:
5 % of a core (an activity blocked for ever uses none, the middleware's idle threads a few
milliseconds; one that encodes or writes, even on a loaded machine, far more)."""


class StartGate:
    """Opens once every expected activity was configured (or on a stop); see the module docstring."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._waiting: set[str] = set()
        self._expected = False
        self._ready = False
        """Every expected activity configured: the gate opened, or this process said so (held)."""
        self._opened = threading.Event()
        self._on_open: list[Callable[[], None]] = []
        self._report: Callable[[], None] | None = None
        self._paused = False
        self._on_pause: list[Callable[[bool], None]] = []

    def hold(self, report: Callable[[], None]) -> None:
        """This process runs one part of the application: once its activities are configured, call
        ``report`` (tell the launcher) instead of opening; :meth:`open` opens (the launcher's word)."""
        self._report = report

    def expect(self, names: Iterable[str]) -> None:
        """The activities to wait for (the application's start; a child's stand-ins included)."""
        with self._lock:
            self._waiting = set(names)
            self._expected = True
        self._check()

    def configured(self, name: str) -> None:
        """Activity ``name`` has configured its components."""
        with self._lock:
            self._waiting.discard(name)
        self._check()

    def _check(self) -> None:
        with self._lock:
            if self._ready or not self._expected or self._waiting:
                return
            self._ready = True
        if self._report is not None:
            self._report()
        else:
            self.open()

    def open(self) -> None:
        """Let every activity start (all configured, the launcher's word, or a stop)."""
        with self._lock:
            if self._opened.is_set():
                return
            self._opened.set()
            callbacks, self._on_open = self._on_open, []
        for callback in callbacks:
            callback()

    @property
    def is_open(self) -> bool:
        """Whether the activities may cycle (see :meth:`open`)."""
        return self._opened.is_set()

    @property
    def paused(self) -> bool:
        """Whether the activities' cycles are held (:meth:`pause`): their components do not run."""
        return self._paused

    def pause(self, paused: bool) -> None:
        """Hold every activity's cycles (True) or let them run again (False), after the gate
        opened: a managed node's deactivate and activate (``coco_ros.managed``). The activities
        keep their threads, timers and configuration; what is written meanwhile waits in the
        connections. ``listener(paused)`` of :meth:`when_paused` is called at each change."""
        with self._lock:
            if self._paused == paused:
                return
            self._paused = paused
            listeners = list(self._on_pause)
        for listener in listeners:
            listener(paused)

    def when_paused(self, listener: Callable[[bool], None]) -> None:
        """Call ``listener(paused)`` at each :meth:`pause` (the process level tells the children)."""
        with self._lock:
            self._on_pause.append(listener)

    def when_open(self, callback: Callable[[], None]) -> None:
        """Call ``callback`` when the gate opens (now, if it is open)."""
        with self._lock:
            if not self._opened.is_set():
                self._on_open.append(callback)
                return
        callback()


def cpu_seconds(pid: int) -> float:
    """CPU seconds (user + system) used so far by process ``pid``; 0 when it is gone."""
    use = process_cpu(pid)
    return 0.0 if use is None else use.seconds


class Progress:
    """Whether a natural stop still progresses: the CPU time of this process and of the application's
    other processes (:attr:`pids`, added by the process level) grows, or something finished
    (:meth:`advance`). :meth:`wait` waits on a condition under this rule."""

    def __init__(self) -> None:
        self.pids: list[int] = []
        """The application's child processes, whose work counts too."""
        self._marks = 0

    def advance(self) -> None:
        """Something finished (an activity, a process): progress, whatever the CPU says."""
        self._marks += 1

    def _state(self) -> tuple[float, int]:
        return time.process_time() + sum(cpu_seconds(pid) for pid in self.pids), self._marks

    def wait(self, done: Callable[[float], bool], hard_deadline: Callable[[], float | None]) -> bool:
        """Call ``done(timeout)`` (a wait of at most ``timeout`` seconds, True once done) until it is
        done; False when it is not before ``hard_deadline()`` (a monotonic time: the stop is hard)
        or, while that is None (a natural stop), after :data:`STOP_TIMEOUT` seconds without progress."""
        slice_ = STOP_TIMEOUT / 10
        cpu, marks = self._state()
        stalled_at = time.monotonic() + STOP_TIMEOUT
        while True:
            deadline = hard_deadline()
            limit = stalled_at if deadline is None else deadline
            if done(max(0.0, min(slice_, limit - time.monotonic()))):
                return True
            now = time.monotonic()
            if deadline is None:
                new_cpu, new_marks = self._state()
                if new_cpu - cpu >= PROGRESS_CPU or new_marks != marks:
                    cpu, marks, stalled_at = new_cpu, new_marks, now + STOP_TIMEOUT
                limit = stalled_at
            if now >= limit:
                return False
