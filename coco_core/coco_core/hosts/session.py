"""A host's part in the launch of an application over several hosts: barriers, stop, clock, calls.

Every host runs the same file with its own ``--host NAME`` and no host commands the others: each
says where it is in the launch in its :class:`~coco_core.hosts.messages.Heartbeat` and waits for
every other host to be as far before going on, so that the same rules hold as between the
processes of one launcher (:mod:`coco_core.processes.supervisor`): every part is built before any
activity configures anywhere, every activity is configured before any cycles, a stop anywhere
(Ctrl-C, ``--duration``, a component's ``stop_app``) stops every host, and damaged input found on
any host reaches every host's summary and exit status. A host whose heartbeats stop before it said
it stops has disappeared (killed, unplugged): it is reported by name and the application's
``on_error`` policy decides (``stop_app``: every other host stops, exit status 1; otherwise the
others go on without it, and say so).

The messages travel over a :class:`Bus` that a transport provides (``coco_ros.hosts``: DDS);
nothing here knows the network.
"""

from __future__ import annotations

import dataclasses
import itertools
import logging
import threading
import time
from concurrent.futures import Future
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

from ..calls import serve_call, settle
from ..component import ErrorPolicy
from ..errors import HostError, WrongTypeError
from ..messages import Call, Damage, Message, Outcome, Result
from .clock import EXCHANGES, ClockOffset, best, exchange
from .messages import ClockRequest, Heartbeat, Stage
from .part import split_address
from .transport import Bus

if TYPE_CHECKING:
    from ..application import Application
    from ..levels import Ends, LocalProcesses
    from ..model import AppSpec

log = logging.getLogger("coco")

BEAT = 0.2
"""Seconds between two heartbeats of a host."""
LOST = 3.0
"""Seconds without a heartbeat after which a host that did not say it stops has disappeared: many
beats, so that a loaded machine or a lossy link does not lose a host that is there."""
START_TIMEOUT = 60.0
"""Seconds a host waits for the others at each stage of the start (``--host-timeout``)."""
CLOCK_TIMEOUT = 2.0
"""Seconds one clock exchange may take."""
REPORT_EVERY = 2.0
"""Seconds between two lines saying which hosts a host still waits for."""
SIGNAL_CHECK = 0.1
"""Seconds between two looks for a signal while a host waits for the others."""


@dataclass
class Peer:
    """Another host as this one knows it: its last heartbeat and when it came."""

    name: str
    beat: Heartbeat | None = None
    at: float = 0.0
    """``time.monotonic()`` of the last heartbeat."""
    lost: bool = False


class HostSession:
    """This host's side of the launch (see the module docstring). It carries operation calls to the
    other hosts too (:class:`~coco_core.levels.OtherHosts`, for addresses ``process@host``), and the
    calls that other hosts make to this host's processes."""

    def __init__(self, spec: AppSpec, app: Application, timeout: float = START_TIMEOUT,
                 interrupted: Callable[[], None] = lambda: None, lost_after: float = LOST) -> None:
        self.host = spec.part_of
        self.hosts = [host.name for host in spec.hosts]
        self.app = app
        self.timeout = timeout
        self.lost_after = lost_after
        """Seconds of silence after which another host has disappeared (:data:`LOST`)."""
        self.interrupted = interrupted
        """Called while the launch waits for the other hosts: raises when a signal ends the launch
        (:meth:`coco_core.signals.LaunchSignals.check`)."""
        self.peers = {name: Peer(name) for name in self.hosts if name != self.host}
        self.stage = Stage.JOINED
        self.bus: Bus | None = None
        self.clock = ClockOffset()
        self.processes: LocalProcesses | None = None
        """This host's child processes (:class:`~coco_core.levels.LocalProcesses`): the calls of other
        hosts to them, and the damage other hosts found, go there; None: this host has no child
        process, the launcher's components serve the calls."""
        self.ends: Ends | None = None
        """The launcher's process's ends of connections between hosts (:mod:`.level` attaches them)."""
        self.failure = ""
        """Why this host's run failed because of another host (one disappeared), for the exit status."""
        self._stop: Heartbeat | None = None
        self._lock = threading.RLock()  # a signal's stop, in the main thread, may come while it holds it
        self._changed = threading.Condition(self._lock)
        self._ids = itertools.count(1)
        self._waiting: dict[int, tuple[str, Callable[[Outcome], None]]] = {}
        """Request id -> (the host asked, what gets its answer)."""
        self.unexpected = 0
        """Messages from other hosts of a type the protocol does not send between hosts (logged)."""
        self._handlers: dict[type, Callable[[str, Any], None]] = {
            Heartbeat: self._heard, ClockRequest: self._clock_asked, Call: self._serve_call, Damage: self._damaged,
            Result: self._answered}
        """The one dispatcher of the link between hosts: the handler of each message type."""
        self._done = threading.Event()
        self._beater = threading.Thread(target=self._beat, name="coco:hosts", daemon=True)

    @property
    def leader(self) -> str:
        """The first host: its clock is the application's."""
        return self.hosts[0]

    # --- start ----------------------------------------------------------------------------------
    def join(self, bus: Bus) -> None:
        """Start beating on ``bus``, wait until every other host is there, then measure this host's
        clock against the first host's. A :class:`HostError` names the hosts that did not come."""
        self.bus = bus
        self.app.add_stop_listener(self._stopping_here)
        self.app.add_damage_listener(self.damage_found)
        self._beater.start()
        self._wait_for(Stage.JOINED, "to start")
        if self.host != self.leader:
            self.clock = self._measure_clock()
        log.info("host %s: clock %s", self.host, self.clock.describe())

    def built(self, processes: LocalProcesses | None) -> None:
        """This host's part is built, ``processes`` (its child processes, if any) too: wait for every
        host to be, then let the start go on; once every activity of this host is configured, wait
        for every host's to be before any cycle runs (the start gate is held until then). The calls
        of other hosts reach this host's child processes through ``processes`` (theirs go out
        through this session, which the launch gave the process level)."""
        self.processes = processes
        if self.ends is not None:  # a sample written before its reader subscribed would be lost
            matched(self.ends, self.timeout, self.interrupted, self.app)
        self._enter(Stage.BUILT)
        self._wait_for(Stage.BUILT, "to build their parts")
        self.app.gate.hold(self._configured)

    def _configured(self) -> None:
        """The start gate's report: every activity of this host is configured. Waits for the others
        in a thread of its own (the report comes from the thread of the last activity configured)."""
        self._enter(Stage.CONFIGURED)
        threading.Thread(target=self._open_when_configured, name="coco:hosts:start", daemon=True).start()

    def _open_when_configured(self) -> None:
        try:
            self._wait_for(Stage.CONFIGURED, "to configure their activities")
        except HostError as error:
            log.error("%s", error)
            self.failure = self.failure or str(error)
            self.app.request_stop(str(error), hard=True)
            return
        self._enter(Stage.RUNNING)
        self.app.gate.open()

    def _wait_for(self, stage: Stage, what: str) -> None:
        """Until every other host is at ``stage`` or further, the application stops, or the timeout."""
        deadline = time.monotonic() + self.timeout
        next_report = time.monotonic() + REPORT_EVERY
        with self._changed:
            while True:
                behind = [peer for peer in self.peers.values()
                          if not peer.lost and (peer.beat is None or peer.beat.stage < stage)]
                if not behind or self.app.stop_requested:
                    return
                now = time.monotonic()
                if now >= deadline:
                    raise HostError(f"host {self.host}: {_waiting_for(behind)} did not come within "
                                    f"{self.timeout:g} s {what} (--host-timeout)")
                if now >= next_report:
                    log.info("host %s: waiting for %s %s", self.host, _waiting_for(behind), what)
                    next_report = now + REPORT_EVERY
                self._changed.wait(min(deadline - now, next_report - now, SIGNAL_CHECK))
                self.interrupted()

    def _measure_clock(self) -> ClockOffset:
        samples = []
        for _ in range(EXCHANGES):
            answer: Future[Any] = Future()
            sent = time.perf_counter()
            self._request(self.leader, ClockRequest(sent=sent), answer.set_result)
            try:
                outcome = answer.result(CLOCK_TIMEOUT)
            except TimeoutError:
                continue
            back = time.perf_counter()
            received, replied = outcome.value
            samples.append(exchange(sent, received, replied, back))
        if not samples:
            raise HostError(f"host {self.host}: the first host, {self.leader}, did not answer the clock exchange "
                            f"within {CLOCK_TIMEOUT:g} s ({EXCHANGES} tries)")
        return best(samples)

    # --- running --------------------------------------------------------------------------------
    def receive(self, sender: str, message: Message) -> None:
        """A message from host ``sender`` (the bus's thread): the link's one dispatcher, by the
        message's type; one of a type the protocol does not send between hosts is counted
        (:attr:`unexpected`) and logged, never dropped silently."""
        handler = self._handlers.get(type(message))
        if handler is None:
            with self._lock:
                self.unexpected += 1
            log.error("host %s: unexpected %s from host %s (%d so far)", self.host, type(message).__name__, sender,
                      self.unexpected)
            return
        handler(sender, message)

    def _clock_asked(self, sender: str, request: ClockRequest) -> None:
        received = time.perf_counter()
        self._answer(sender, request, Outcome(True, (received, time.perf_counter())))

    def _damaged(self, sender: str, damage: Damage) -> None:
        self.app.report_damage(damage.what, here=False)
        if self.processes is not None:
            self.processes.pass_on_damage(damage.what)

    def _answered(self, sender: str, result: Result) -> None:
        with self._lock:
            waiting = self._waiting.pop(result.id, None)
        if waiting is not None:
            waiting[1](result.outcome)

    def _heard(self, sender: str, beat: Heartbeat) -> None:
        peer = self.peers.get(sender)
        if peer is None:
            return  # a host of another application of the same name, or one this file does not declare
        with self._changed:
            first = peer.beat is None
            peer.beat, peer.at = beat, time.monotonic()
            self._changed.notify_all()
        if first:
            log.info("host %s: host %s is there", self.host, sender)
        if beat.stage is Stage.STOPPING and not self.app.stop_requested:
            with self._lock:
                self.failure = self.failure or (f"host {sender} failed: {beat.reason}" if beat.failed else "")
            self.app.request_stop(f"host {sender}: {beat.reason}", hard=beat.hard)

    def _beat(self) -> None:
        """Send this host's heartbeat every :data:`BEAT` seconds, and find the hosts that went silent."""
        while not self._done.wait(BEAT):
            self._send_beat()
            now = time.monotonic()
            for peer in list(self.peers.values()):
                if (peer.beat is not None and not peer.lost and peer.beat.stage < Stage.STOPPING
                        and now - peer.at > self.lost_after):
                    self._lost(peer, now - peer.at)

    def _send_beat(self) -> None:
        bus = self.bus
        if bus is not None:
            bus.send("", self._stop if self._stop is not None else Heartbeat(self.stage))

    def _lost(self, peer: Peer, silent: float) -> None:
        with self._changed:
            peer.lost = True
            self._changed.notify_all()
        what = f"host {peer.name} disappeared (no heartbeat for {silent:.1f} s)"
        log.error("host %s: %s", self.host, what)
        with self._lock:
            unanswered = [number for number, (host, _) in self._waiting.items() if host == peer.name]
            answers = [self._waiting.pop(number)[1] for number in unanswered]
        for deliver in answers:  # its callers are not left waiting
            deliver(Outcome.failure("HostError", what))
        if self.app.on_error is ErrorPolicy.STOP_APP or self.app.stop_requested:
            with self._lock:
                self.failure = self.failure or what
            self.app.request_stop(what, hard=True)
        else:
            log.warning("host %s: going on without host %s (the application's on_error is %s; stop_app would "
                        "stop every host)", self.host, peer.name, self.app.on_error.value)

    def damage_found(self, what: str) -> None:
        """Damaged input found on this host (its launcher's components, or a child process): every
        other host's :attr:`Application.damage` gets it too, as between processes, so that each host's
        summary reports it and each exits with status 1."""
        if self.bus is not None:
            self.bus.send("", Damage(what))

    def _enter(self, stage: Stage) -> None:
        with self._lock:
            if self._stop is None:
                self.stage = stage
        self._send_beat()

    def _stopping_here(self, reason: str) -> None:
        """This host's application stops: every other host is told (at once, then by every beat),
        and a wait for them ends."""
        with self._changed:
            self._changed.notify_all()
            self.stage = Stage.STOPPING
            self._stop = Heartbeat(Stage.STOPPING, reason, self.app.stop_is_hard, bool(self.failure) or
                                   reason.startswith("component") or bool(self.app.damage))
        self._send_beat()

    # --- operations -----------------------------------------------------------------------------
    def call(self, process: str, component: str, operation: str, args: tuple[Any, ...],
             kwargs: dict[str, Any]) -> Future[Any]:
        """An operation of a component of another host (``process`` is its address, ``view@graphics``)."""
        host, local = split_address(process)
        future: Future[Any] = Future()
        target = f"{component}.{operation}"
        if host is None or host not in self.peers:
            future.set_exception(HostError(f"no host {host!r} for {target} ({process})"))
            return future
        call = Call(process=process, component=component, operation=operation, args=args, kwargs=kwargs)
        self.forward(call, lambda outcome: settle(future, outcome, process, target))
        return future

    def forward(self, call: Call, reply: Callable[[Outcome], None]) -> None:
        """Pass ``call`` (its process an address, ``view@graphics``) to its host; ``reply`` gets the
        outcome as it came (a child process of this host calls through the launcher this way)."""
        host, process = split_address(call.process)
        if host is None or host not in self.peers:
            reply(Outcome.failure("HostError", f"no host {host!r} for {call.component}.{call.operation} "
                                               f"({call.process}); the hosts are {', '.join(self.hosts)}"))
            return
        if self.peers[host].lost:
            reply(Outcome.failure("HostError", f"host {host} disappeared: {call.component}.{call.operation} cannot "
                                               "be called"))
            return
        self._request(host, dataclasses.replace(call, process=process), reply)

    def _serve_call(self, sender: str, call: Call) -> None:
        """Another host calls an operation of a component of this one: run it in this process, or
        pass it on to the child process that runs it."""
        def reply(outcome: Outcome) -> None:
            self._answer(sender, call, outcome)

        if self.processes is not None:
            self.processes.route(call, reply)
        elif call.process:
            reply(Outcome.failure("ProcessError", f"no process {call.process!r} on host {self.host}"))
        else:
            serve_call(self.app, call, reply)

    def _request(self, host: str, request: Call | ClockRequest, deliver: Callable[[Outcome], None]) -> None:
        number = next(self._ids)
        with self._lock:
            self._waiting[number] = (host, deliver)
        assert self.bus is not None
        try:
            self.bus.send(host, dataclasses.replace(request, id=number))
        except WrongTypeError as error:  # an argument that cannot cross between hosts
            with self._lock:
                self._waiting.pop(number, None)
            deliver(Outcome.failure("WrongTypeError", f"the call cannot be sent to host {host}: {error}"))

    def _answer(self, host: str, request: Call | ClockRequest, outcome: Outcome) -> None:
        if self.bus is None:
            return
        try:
            self.bus.send(host, Result(request.id, outcome))
        except WrongTypeError as error:  # a result that cannot cross between hosts: its caller must hear so
            self.bus.send(host, Result(request.id, Outcome.failure("WrongTypeError", f"the result cannot be sent to "
                                                                                     f"host {host}: {error}")))

    # --- end ------------------------------------------------------------------------------------
    def close(self) -> None:
        """Stop beating (the last heartbeat, which says this host stops, was sent) and close the bus."""
        self._done.set()
        if self._beater.is_alive():
            self._beater.join(1.0)
        self._send_beat()
        if self.bus is not None:
            self.bus.close()
            self.bus = None


def matched(ends: Ends, timeout: float, interrupted: Callable[[], None], app: Application) -> None:
    """Wait until every end of ``ends`` found its other end on another host (:meth:`Ends.unmatched`),
    for ``timeout`` seconds at most (a :class:`HostError` names the others) or until ``app`` stops:
    what a writer wrote before its reader subscribed would be lost. The launcher's process waits so
    before its host says it is built, a child process before it says it is."""
    deadline = time.monotonic() + timeout
    while (left := ends.unmatched()) and not app.stop_requested:
        if time.monotonic() > deadline:
            raise HostError(f"connections between hosts not joined within {timeout:g} s: {', '.join(left)} "
                            "(--host-timeout)")
        interrupted()
        time.sleep(SIGNAL_CHECK / 5)


def _waiting_for(peers: list[Peer]) -> str:
    words = [f"{peer.name} ({'not seen' if peer.beat is None else peer.beat.stage.name.lower()})" for peer in peers]
    return ("host " if len(words) == 1 else "hosts ") + ", ".join(words)

