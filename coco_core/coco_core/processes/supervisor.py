"""The launcher's side of the process level: one child process per ``<process>``.

The launcher builds its own part of the application (its components and activities, and a stand-in
of every child's activity), then a :class:`ProcessSupervisor` starts the children. Each child gets
the application model over its control link, builds only its own components and says so: the
application starts only once *every* process was built (one wrong component anywhere and nothing
runs). Then every process configures its activities and says so; once every activity of every
process is configured (the launcher's :class:`~coco_core.lifecycle.StartGate` opens), every process
runs their first cycles.

Faults: a child that dies (an exception at start, ``kill -9``, a segfault) is reported by process
name and exit signal or status, and the application stops cleanly (exit status 1). Children die with
the launcher (a parent-death signal, set by the child itself), and the shared-memory segments of the
launch are unlinked by the launcher at its end, or by the children when the launcher died first.
"""

from __future__ import annotations

import logging
import os
import secrets
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from functools import partial
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout
from typing import TYPE_CHECKING, Any, Callable

from ..activity import Activity
from ..application import Application
from ..calls import serve_call
from ..deployment import HostDeployment, drive
from ..drivers import Driving
from ..errors import ProcessError
from ..lifecycle import STOP_TIMEOUT
from ..messages import Call, Damage, Outcome
from ..report import ProfileSnapshot, connection_rows, render, snapshot
from ..wakeup import Wakeup
from .control import ControlLink
from .messages import (
    BuildFailed,
    Built,
    Config,
    HostConfig,
    Configured,
    Pause,
    ProfileRequest,
    Run,
    SetPeriod,
    Start,
    Stop,
    Stopped,
    StopRequest,
)
from .channels import ChannelPlan, attach, plan_channels, reader_stats
from .placement import LAUNCHER
from .remote import call_over

if TYPE_CHECKING:
    from ..levels import HostEnds, OtherHosts
    from ..shm import Arena

log = logging.getLogger("coco")

BUILD_TIMEOUT = 120.0
"""Seconds a child may take to build its components (a URDF with meshes, an OpenGL context)."""
PROFILE_TIMEOUT = 1.0
"""Seconds the launcher waits for a child's profile before printing without it."""


def exit_description(code: int | None) -> str:
    """How a process ended, in words: ``killed by SIGKILL``, ``exit status 1``."""
    if code is None:
        return "still running"
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit status {code}"


def _exited(popen: subprocess.Popen[bytes], timeout: float) -> bool:
    """Whether ``popen`` exited within ``timeout`` seconds."""
    try:
        popen.wait(timeout)
    except subprocess.TimeoutExpired:
        return False
    return True


def _deliver(future: Future[Any], outcome: Outcome) -> None:
    """A child's answer to a request, into the future the launcher waits on."""
    future.set_result(outcome.value)


@dataclass
class Child:
    """One child process as the launcher sees it."""

    name: str
    link: ControlLink
    popen: subprocess.Popen[bytes]
    activities: list[str]
    started: bool = False
    stopped: threading.Event = field(default_factory=threading.Event)
    """Set when the child said it stopped, or it exited."""
    clean: bool = False
    failed: bool = False
    """A component of the child stopped the application by its error policy."""
    last: ProfileSnapshot | None = None
    """The child's final profile, sent when it stopped."""
    stop_sent: bool = False
    hard_stop_sent: bool = False
    """The child was told that the stop is hard (a signal or a fault came during a natural stop)."""
    watcher: threading.Thread | None = None
    """The thread reading the child's link until its end (:meth:`ProcessSupervisor.close` waits for it)."""
    cut_short: bool = False
    """The launcher ended the child after it stopped its part cleanly, while it still released what it
    holds beyond it (a ROS child's node and rclpy): not a death, nothing lost."""


class ProcessDriver:
    """The driver of a child's activity, as the launcher holds it (the stand-in activity): the
    protocol of :mod:`coco_core.drivers`, carried out by the child that runs the activity. Lets the
    launcher's application stop, join, re-period and ask the state of every activity by name,
    wherever it runs."""

    def __init__(self, supervisor: ProcessSupervisor, child: Child, activity: Activity, driving: Driving,
                 eventfd: Wakeup | None) -> None:
        self.supervisor = supervisor
        self.child = child
        self.activity = activity
        self.driving = driving
        """What drives the activity in the child (the deployment plan's word)."""
        self.eventfd = eventfd
        activity.drive_with(self)

    def start(self, activity: Activity) -> None:
        """The launcher's application starts: so does the child (once, for all its activities)."""
        self.supervisor.start_child(self.child)

    def wake(self) -> None:
        if self.eventfd is not None:
            self.eventfd.wake()

    @property
    def wake_pending(self) -> bool:
        return self.eventfd is not None and self.eventfd.pending

    def stop(self) -> None:
        self.supervisor.stop_child(self.child, self.supervisor.app.stop_reason or "stop requested")

    def set_period(self, period: float) -> None:
        self.child.link.send(SetPeriod(self.activity.name, period))

    def join(self, timeout: float | None = None) -> bool:
        return self.child.stopped.wait(timeout)


class ProcessSupervisor:
    """Starts, watches and stops the child processes of ``app`` (the launcher's part of the host's
    ``deployment``)."""

    def __init__(self, app: Application, deployment: HostDeployment, log_level: int = logging.INFO,
                 child_module: str = "coco_core.processes.child", child_config: HostConfig = HostConfig(),
                 hosts_link: HostEnds | None = None, hosts: OtherHosts | None = None) -> None:
        self.child_module = child_module
        """The module a child runs (``python -m``): the ROS launcher's children host an rclpy node."""
        self.child_config = child_config
        """Extra configuration every child receives (the ROS launcher's node name and ROS arguments)."""
        self.hosts_link = hosts_link
        """How every child attaches its ends of connections between hosts, when the application has
        several (the host level's :class:`~coco_core.levels.HostEnds`, carried without knowing it)."""
        self.app = app
        self.deployment = deployment
        """This host's part of the launch's plan, which every child receives and executes
        (:mod:`coco_core.deployment`): the processes, their wake sets, the channels' crossings."""
        self.log_level = log_level
        self.launch_id = f"{os.getpid()}-{secrets.token_hex(3)}"
        self.children: dict[str, Child] = {}
        self._wakes: dict[str, Wakeup] = {}
        """activity -> its eventfd, for every activity of the plan's wake sets: made here for the
        children, closed at the end (:meth:`close`)."""
        self.arena: Arena | None = None
        """The launch's shared-memory segments (when a connection crosses processes)."""
        self.plans: list[ChannelPlan] = []
        self._lock = threading.Lock()
        self.failure = ""
        """Why the application failed because of a child (its death), for the exit status."""
        self.hosts = hosts
        """The other hosts of the application, when it has several: the calls to their components
        and the damage this host's children find go there (:class:`~coco_core.levels.OtherHosts`)."""

    # --- start ----------------------------------------------------------------------------------
    def launch(self) -> None:
        """Start every child and wait until each has built its part; raises :class:`ProcessError`
        (after stopping the others) when one could not."""
        try:
            if self.deployment.crossings:
                from ..shm import Arena

                self.arena = Arena(self.launch_id)
                self.plans = plan_channels(self.arena, self.deployment)
            for name in sorted(self.deployment.woken):
                self._wakes[name] = Wakeup.new()
            drive(self.app, self.deployment, self._wakes)
            attach(self.app, self.plans, self._wakes)
            for name in self.deployment.placement.processes:
                self.children[name] = self._spawn(name)
                self.app.progress.pids.append(self.children[name].popen.pid)  # a natural stop sees its work
            for child in self.children.values():
                self._wait_built(child)
        except BaseException:
            self.kill_all()
            self.close()
            raise
        self.app.gate.when_open(self._start_all)
        self.app.gate.when_paused(self._pause_all)
        for child in self.children.values():
            for name in child.activities:
                ProcessDriver(self, child, self.app.activities[name], self.deployment.activities[name].driving,
                              self._wakes.get(name))
            child.watcher = threading.Thread(target=self._watch, args=(child,), name=f"coco:watch:{child.name}",
                                             daemon=True)
            child.watcher.start()
        self.app.add_damage_listener(self.pass_on_damage)

    def _spawn(self, name: str) -> Child:
        link, theirs = ControlLink.pair(f"process {name}")
        activities = list(self.deployment.process(name).activities)
        try:  # every child gets every wake-up eventfd: it may write to any process's reader
            popen = subprocess.Popen(
                [sys.executable, "-m", self.child_module, str(theirs), str(os.getpid())],
                pass_fds=(theirs, *(wakeup.fd for wakeup in self._wakes.values())), stdin=subprocess.DEVNULL,
                start_new_session=True)  # a terminal's Ctrl-C reaches the launcher, which stops them
        finally:
            os.close(theirs)
        wakes = {activity: wakeup.fd for activity, wakeup in self._wakes.items()}
        link.send(Config(name, self.launch_id, wakes, self.plans, self.deployment, self.log_level,
                         self.child_config, self.hosts_link, self.app.measure_ages))
        return Child(name, link, popen, activities)

    def _wait_built(self, child: Child) -> None:
        deadline = time.monotonic() + BUILD_TIMEOUT
        while True:
            try:
                message = child.link.receive(timeout=0.1)
            except EOFError:
                message = None
            if isinstance(message, Built):
                return
            if isinstance(message, BuildFailed):
                raise ProcessError(f"process {child.name}: {message.text}")
            if message is not None:  # a child says nothing else before it built
                child.link.refuse(message)
            code = child.popen.poll()
            if code is not None:
                raise ProcessError(f"process {child.name} ended while building its components "
                                   f"({exit_description(code)})")
            if time.monotonic() > deadline:
                raise ProcessError(f"process {child.name} did not build its components within {BUILD_TIMEOUT:g} s")

    def _start_all(self) -> None:
        """Every activity of every process is configured (or the application stops): let the
        children run their first cycles (not when it stops: they get the word to stop instead)."""
        if self.app.stop_requested:
            return
        for child in self.children.values():
            child.link.send(Run())

    def _pause_all(self, paused: bool) -> None:
        """Pass the launcher's pause or resume on to every child (:meth:`Application.pause`)."""
        for child in self.children.values():
            child.link.send(Pause(paused))

    def start_child(self, child: Child) -> None:
        """Tell ``child`` to start (configure) its activities, once: every process was built by now;
        it says ``configured`` when it is done, and runs them on the word ``run``."""
        with self._lock:
            if child.started:
                return
            child.started = True
        child.link.send(Start())

    # --- running --------------------------------------------------------------------------------
    def _watch(self, child: Child) -> None:
        """Read the child's messages until it is gone; a death that nobody asked for stops the app."""
        child.link.serve({
            Configured: lambda _: self._configured(child),
            Stopped: lambda message: self._stopped(child, message),
            Damage: lambda message: self._damaged(child, message),
            StopRequest: lambda message: self._stop_requested(child, message),
            Call: lambda message: self._route(child, message),
        })
        code = child.popen.wait()
        child.stopped.set()
        self.app.progress.advance()
        child.link.abandon(f"process {child.name} ended ({exit_description(code)}) before it answered")
        if child.last is not None and (code == 0 or child.cut_short):
            return  # it stopped as asked
        what = exit_description(code)
        log.error("process %s (pid %d) died: %s", child.name, child.popen.pid, what)
        with self._lock:
            self.failure = self.failure or f"process {child.name} died: {what}"
        self.app.request_stop(f"process {child.name} died ({what})", hard=True)

    def _configured(self, child: Child) -> None:
        for name in child.activities:
            self.app.gate.configured(name)

    def _stopped(self, child: Child, message: Stopped) -> None:
        """The child's activities have all stopped: their stand-ins here have (``ProcessDriver.join``),
        while the process still ends (a ROS child destroys its node and shuts rclpy down, which took
        over a second on a loaded machine: the launcher then called the activity hung)."""
        child.clean, child.failed, child.last = message.clean, message.failed, message.snapshot
        child.stopped.set()
        self.app.progress.advance()

    def _stop_requested(self, child: Child, message: StopRequest) -> None:
        self.app.request_stop(f"process {child.name}: {message.reason}", hard=message.hard)

    def _damaged(self, child: Child, message: Damage) -> None:
        self.app.report_damage(message.what, here=False)
        self.pass_on_damage(message.what, found_by=child)
        if self.hosts is not None:  # and to the other hosts (the launcher's own damage goes there itself)
            self.hosts.damage_found(message.what)

    def pass_on_damage(self, what: str, found_by: Child | None = None) -> None:
        """Damaged input that one process found (a child, or the launcher's own components) goes to
        every other process's :attr:`Application.damage`: a summary written in one process (the
        palpation's, beside the haptic loop) reports the damage the others' readers found, and each
        process's exit status carries it. The messages of one link keep their order, so damage a
        process found before it asked the application to stop reaches the others before the stop."""
        for child in self.children.values():
            if child is not found_by:
                child.link.send(Damage(what))

    def stop_child(self, child: Child, reason: str) -> None:
        """Tell ``child`` to stop, once (every stand-in of its activities asks, when the application
        stops them), and once more when a natural stop becomes hard, so that the child too ends it
        within a second."""
        hard = self.app.stop_is_hard
        with self._lock:
            if child.stop_sent and (child.hard_stop_sent or not hard):
                return
            child.stop_sent, child.hard_stop_sent = True, hard
        child.link.send(Stop(reason, hard))

    def call(self, process: str, component: str, operation: str, args: tuple[Any, ...],
             kwargs: dict[str, Any]) -> Future[Any]:
        """An operation of a component that child ``process`` runs, or another host's (``process@host``,
        through :attr:`hosts`) (the :class:`Router` protocol)."""
        if process not in self.children and self.hosts is not None:
            return self.hosts.call(process, component, operation, args, kwargs)
        return call_over(self.children[process].link, process, component, operation, args, kwargs)

    def _route(self, caller: Child, call: Call) -> None:
        """A child calls an operation of another process: run it here, or pass it on."""
        def reply(outcome: Outcome) -> None:
            caller.link.answer(call, outcome)

        self.route(call, reply)

    def route(self, call: Call, reply: Callable[[Outcome], None]) -> None:
        """Run ``call`` here, or pass it to the process (of this host, or through :attr:`hosts` of
        another) that runs its component; ``reply`` gets the outcome as it came (so the exception's
        own type name reaches the caller)."""
        if call.process == LAUNCHER:
            serve_call(self.app, call, reply)
        elif call.process in self.children:
            self.children[call.process].link.request(call, reply)
        elif self.hosts is not None:
            self.hosts.forward(call, reply)
        else:
            reply(Outcome.failure("ProcessError", f"no process {call.process!r}"))

    def snapshots(self) -> list[ProfileSnapshot]:
        """The launcher's profile and every child's (its last one once it stopped)."""
        shots = [snapshot(self.app)]
        waiting: list[tuple[Child, Future[Any]]] = []
        for child in self.children.values():
            future: Future[Any] = Future()
            if not child.stopped.is_set():
                child.link.request(ProfileRequest(), partial(_deliver, future))
            waiting.append((child, future))
        deadline = time.monotonic() + PROFILE_TIMEOUT
        for child, future in waiting:
            shot = child.last
            if not child.stopped.is_set():
                try:
                    shot = future.result(max(0.0, deadline - time.monotonic()))
                except FutureTimeout:
                    shot = None
            shots.append(shot if shot is not None else self._silent(child))
        return shots

    def _silent(self, child: Child) -> ProfileSnapshot:
        """The profile of a child that sent none (it died, or did not answer in time): no figures
        of its own, but the counters of the connections it reads, which live in shared memory."""
        shot = ProfileSnapshot(child.name, child.popen.pid, 0.0, 0.0, 0)
        shot.connections = connection_rows(reader_stats(self.plans, child.name))
        return shot

    def report(self) -> str:
        """The profile of the whole application, every process in one report."""
        return render(self.app.name, self.snapshots())

    @property
    def failed(self) -> bool:
        """Whether a child died unasked or a child's component stopped the application."""
        return bool(self.failure) or any(child.failed for child in self.children.values())

    # --- end ------------------------------------------------------------------------------------
    def join(self, timeout: float = STOP_TIMEOUT) -> bool:
        """Wait for every child to exit, as :meth:`Application.stop` waits for activities: after a
        hard stop, ``timeout`` seconds in all; after a natural one, while they progress
        (:mod:`coco_core.lifecycle`). The ones still there then are killed."""
        begun = time.monotonic()
        clean = True
        for child in self.children.values():
            if not self.app.progress.wait(partial(_exited, child.popen), lambda: self.app.stop_deadline(begun, timeout)):
                how = (f"within {timeout:.1f} s" if self.app.stop_is_hard else
                       f"(no progress for {timeout:.1f} s after the application's own stop request)")
                if child.last is not None and child.clean:
                    # Its activities stopped and flushed (Stopped, clean): only its release is late.
                    child.cut_short = True
                    log.warning("process %s stopped its part cleanly but did not end %s (what it holds "
                                "beyond the application: a ROS node, a thread left running); ending it",
                                child.name, how)
                else:
                    log.error("process %s did not stop %s; killing it", child.name, how)
                    clean = False
                child.popen.kill()
                child.popen.wait()
            clean = clean and child.clean
        return clean

    def kill_all(self) -> None:
        for child in self.children.values():
            if child.popen.poll() is None:
                child.popen.kill()
                child.popen.wait()

    def close(self) -> None:
        """Release the control links and descriptors (after the children exited). Each link's reader
        reads the end of its exited child first: a link closed under a thread still in ``recv`` made
        that thread fail on a released handle (seen at the end of a benchmark's run)."""
        for child in self.children.values():
            if child.watcher is not None and child.watcher is not threading.current_thread():
                child.watcher.join(timeout=1.0)
            child.link.close()
        for wakeup in self._wakes.values():  # a late write (a host's receiver) then does nothing
            wakeup.close()
        if self.arena is not None:
            self.arena.close()
            self.arena = None
