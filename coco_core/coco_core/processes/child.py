"""A child process of the launcher: ``python -m coco_core.processes.child FD PARENT_PID``.

It receives the application model over its control link (descriptor ``FD``), builds only the
components of its ``<process>``, says so, waits for the word to start, configures its activities,
says so, waits for the word that every process is configured (``run``: the application's
:class:`~coco_core.lifecycle.StartGate`), and runs its activities until
the launcher (or one of its components) asks for a stop; then every activity runs ``on_stop`` in its
own thread and the child sends its final profile. It is a plain CoCo process: the same builder,
activities and drivers as the launcher's.

It never outlives the launcher: the kernel sends it SIGTERM when its parent dies
(``PR_SET_PDEATHSIG``), and a child orphaned that way also unlinks the launch's shared-memory
segments, which the launcher could not do. Ctrl-C at a terminal reaches every process of the group:
a child ignores SIGINT and lets the launcher decide.
"""

from __future__ import annotations

import ctypes
import logging
import os
import signal
import sys
import threading
import time
from concurrent.futures import Future
from typing import Any, Sequence

from ..application import Application
from ..builder import build_application
from ..deployment import deployed, drive
from ..errors import CocoError
from ..garbage import GarbageBetweenCycles
from ..calls import serve_call
from ..launcher import stopped_by_a_failure
from ..levels import Ends
from ..lock_ceiling import describe as describe_ceiling, raise_lock_holders
from ..memory_lock import lock_memory
from ..messages import Call, Damage, Outcome
from ..report import snapshot
from ..signals import signal_watcher
from ..wakeup import Wakeup
from .channels import attach
from .control import ControlLink, Handlers
from .messages import (
    BuildFailed,
    Built,
    Config,
    Configured,
    ProfileRequest,
    Pause,
    Run,
    SetPeriod,
    Start,
    Stop,
    Stopped,
    StopRequest,
)
from .remote import call_over

log = logging.getLogger("coco")

PR_SET_PDEATHSIG = 1
PR_SET_NAME = 15


def prctl(option: int, argument: int | bytes) -> None:
    """Linux's ``prctl(option, argument)`` for this process; nothing elsewhere (what it sets here is
    a convenience there: the control link's end still stops a child, a name is only cosmetic)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(option, argument, 0, 0, 0)
    except (OSError, AttributeError):
        pass


def die_with_parent(parent: int) -> None:
    """Have the kernel send SIGTERM when the launcher dies; exit now if it already did."""
    prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    if os.getppid() != parent:
        sys.exit(1)


def name_process(process: str) -> None:
    """Call this process ``coco:<process>`` where ``ps``, ``top`` and ``/proc/PID/comm`` show it
    (15 bytes at most), instead of ``python``: which process of the application is the view, and
    which the haptic loop, can then be seen from outside it."""
    prctl(PR_SET_NAME, f"coco:{process}".encode()[:15])


def apply_process_placement(affinity: Sequence[int], nice: int | None) -> None:
    """The ``<process>``'s cores and nice value, for every thread of the process."""
    if affinity:
        try:
            os.sched_setaffinity(0, affinity)
        except OSError as error:
            log.warning("cannot run on cores %s: %s", affinity, error.strerror)
    if nice is not None:
        try:
            os.nice(nice - os.nice(0))
        except OSError as error:
            log.warning("cannot set nice %d (%s): lowering a nice value needs CAP_SYS_NICE", nice, error.strerror)


def collect_between_cycles(app: Application) -> GarbageBetweenCycles | None:
    """Give the collections of ``app`` to its fastest periodic activity (see :mod:`..garbage`);
    None, with a warning, when it has none (nothing would collect: the collector stays as it is)."""
    periodic = {activity: period for activity in app.activities.values() if (period := activity.period) is not None}
    if not periodic:
        log.warning('process %s: gc="between_cycles" needs a periodic activity to collect between its cycles; '
                    "this process has none: its garbage collector is left automatic", app.process)
        return None
    fastest = min(periodic, key=periodic.__getitem__)
    fastest.garbage = GarbageBetweenCycles()
    return fastest.garbage


class ChildProcess:
    """One child's life: configure, build, start, serve the control link, stop."""

    def __init__(self, link: ControlLink, parent: int) -> None:
        self.link = link
        self.parent = parent
        self.app: Application | None = None
        self.launch = ""
        self.garbage: GarbageBetweenCycles | None = None
        """The collections between cycles of a ``gc="between_cycles"`` process."""
        self.ends: Ends | None = None
        """This process's ends of connections between hosts (over the network), when it has any
        (:class:`~coco_core.levels.HostEnds` attached them)."""
        self.orphaned = False
        """Whether the launcher went away under this process (its link closed, or a SIGTERM, which
        its death sends): the child then sweeps the launch's segments once the launcher is gone."""

    def run(self) -> int:
        config = self.link.receive()
        if not isinstance(config, Config):
            return 2
        process = config.process
        name_process(process)
        self.launch = config.launch
        logging.basicConfig(level=config.log_level, format=f"[%(levelname)s] %(name)s[{process}]: %(message)s")
        deployment = config.deployment
        spec = deployment.spec
        settings = deployment.process(process)
        apply_process_placement(settings.affinity, settings.nice)
        if settings.lock_memory and (refused := lock_memory()):
            log.warning("process %s: %s", process, refused)
        ceiling, refusals = raise_lock_holders(settings.realtime.priorities if settings.realtime is not None else ())
        for refusal in refusals:
            log.warning("process %s: %s", process, refusal)
        if ceiling:
            log.info("process %s: %s", process, describe_ceiling())
        try:
            app = self.app = build_application(spec, process, placement=deployment.placement)
            app.measure_ages = config.measure_ages
            wakes = {activity: Wakeup(fd) for activity, fd in config.wakes.items()}  # inherited, kept to the end
            drive(app, config.deployment, wakes)
            attach(app, config.plans, wakes)
            if config.hosts is not None:  # the host level's side, which the launch put in the config
                self.ends = config.hosts.attach(app, spec)
        except CocoError as error:
            self.link.send(BuildFailed(str(error)))
            return 1
        app.add_stop_listener(self._stop_requested_here)
        if settings.gc == "between_cycles":
            self.garbage = collect_between_cycles(app)
        app.add_damage_listener(self._damage_found_here)
        app.gate.hold(self._configured)  # the launcher's word (Run) opens it
        app.router = self
        self.link.send(Built())
        # Every process builds, then all start: wait for the word. What comes meanwhile is served as
        # while the application runs: damage found while building, and an operation called as soon as
        # the launcher is up (its ROS services exist before the application starts), which runs at
        # once, as an operation of an application not started yet does in one process. It was
        # dropped here, and its caller waited for an answer that never came.
        word = self.link.serve(self._handlers(app), until=(Start, Stop))
        if not isinstance(word, Start):
            return 0 if isinstance(word, Stop) else 1  # told to stop, or the launcher is gone
        listener = threading.Thread(target=self._serve, args=(app,), name="coco:control", daemon=True)
        listener.start()
        clean = self.run_app(app, config)
        if self.garbage is not None:
            log.info("process %s: %s", process, self.garbage.describe())
        failed = stopped_by_a_failure(app)  # a component's error policy, or damaged input
        self.link.send(Stopped(clean, failed, snapshot(app, process)))
        self.release()
        if self.ends is not None:
            self.ends.close()
        return 0 if clean else 1

    def call(self, process: str, component: str, operation: str, args: tuple[Any, ...],
             kwargs: dict[str, Any]) -> Future[Any]:
        """An operation of a component in another process (the :class:`Router` protocol): the
        launcher runs it or passes it to the process that runs it."""
        return call_over(self.link, process, component, operation, args, kwargs)

    def run_app(self, app: Application, config: Config) -> bool:
        """Run this process's part until a stop; whether it stopped cleanly. A launcher with more to
        host (the ROS launcher's node and executor) runs its children with a subclass."""
        deployed(app, config.deployment)
        app.run()
        return app.stop()

    def release(self) -> None:
        """What a launcher with more to host holds beyond the application (the ROS launcher's node),
        released once the launcher heard that this process stopped; nothing here."""

    def _configured(self) -> None:
        """Every activity of this process is configured: tell the launcher, whose gate counts them.
        A ``gc="between_cycles"`` process freezes what it built now, before the first cycle."""
        if self.garbage is not None:
            self.garbage.take_over()
        self.link.send(Configured())

    def _stop_requested_here(self, reason: str) -> None:
        """A stop that began in this process (a component's error policy) stops the whole application."""
        if not reason.startswith("launcher:"):
            assert self.app is not None  # it is the app that calls its stop listeners
            self.link.send(StopRequest(reason, self.app.stop_is_hard))

    def _damage_found_here(self, what: str) -> None:
        """Damaged input found in this process: the launcher records it and passes it on to the
        other processes, whose summaries report it too."""
        self.link.send(Damage(what))

    def _handlers(self, app: Application) -> Handlers:
        """What the launcher may send from the moment this process is built: before the word to
        start as after it."""
        return {
            Damage: lambda message: app.report_damage(message.what, here=False),
            ProfileRequest: lambda message: self.link.answer(message, Outcome(True, snapshot(app, app.process))),
            Call: lambda message: serve_call(app, message, lambda outcome: self.link.answer(message, outcome)),
            SetPeriod: lambda message: self._set_period(app, message),
        }

    def _serve(self, app: Application) -> None:
        """The launcher's messages while the application runs; when the launcher is gone, stop."""
        self.link.serve({
            **self._handlers(app),
            Run: lambda _: app.gate.open(),
            Pause: lambda message: app.pause(message.paused),
            Stop: lambda message: app.request_stop(f"launcher: {message.reason}", hard=message.hard),
        })
        self.link.abandon("the launcher is gone")
        self.orphaned = True
        app.request_stop("launcher: gone", hard=True)

    @staticmethod
    def _set_period(app: Application, message: SetPeriod) -> None:
        try:
            app.set_period(message.activity, message.period)
        except CocoError as error:
            log.error("%s", error)


def main(argv: list[str] | None = None, kind: type[ChildProcess] = ChildProcess) -> int:
    """The child's entry point: ``argv`` is ``FD PARENT_PID``; ``kind`` runs it."""
    fd, parent = (int(word) for word in (argv or sys.argv[1:])[:2])
    die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the launcher handles Ctrl-C for the whole group
    child = kind(ControlLink(fd, "the launcher"), parent)

    def terminate(_signum: int, _frame: object) -> None:
        """Record (the watcher's thread stops the application: a handler takes no lock, see
        :mod:`coco_core.signals`); before the application is built, end the child here."""
        child.orphaned = True
        if child.app is None:
            sys.exit(1)

    def stop(_signum: int) -> None:
        if child.app is not None:
            child.app.request_stop("launcher: SIGTERM", hard=True)

    signal.signal(signal.SIGTERM, terminate)
    signal_watcher().watch(stop)
    try:
        return child.run()
    finally:
        # Nobody else will unlink the launch's segments once the launcher is gone.
        if child.launch and launcher_gone(parent, ORPHAN_WAIT if child.orphaned else 0.0):
            from ..shm import sweep

            sweep(child.launch)


ORPHAN_WAIT = 1.0
"""Seconds an orphaned child waits for its launcher's death to complete before it sweeps."""


def launcher_gone(parent: int, within: float = 0.0) -> bool:
    """Whether the launcher died, looking for ``within`` seconds: this child was given to another
    parent, or the launcher is no such process or a zombie (killed, not yet reaped). A killed
    launcher closes its end of the link (the child stops) before the kernel makes it a zombie and
    sends the parent-death signal, so a child that stops because its launcher went away waits a
    moment for that; the parent-death signal alone does not say it reliably either (the child may
    still see the dead launcher as its parent), so the child looks at the process itself."""
    deadline = time.monotonic() + within
    while True:
        if os.getppid() != parent:
            return True
        try:
            with open(f"/proc/{parent}/stat") as stat:
                if stat.read().rsplit(")", 1)[1].split()[0] in ("Z", "X"):
                    return True
        except OSError:
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.01)


if __name__ == "__main__":
    sys.exit(main())
