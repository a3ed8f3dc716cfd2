"""The application: components, their connections and the activities that run them.

Built from an XML file by :mod:`coco_core.builder`, or by hand in Python. Owns the run: start every
activity, run the main activity (if any) in the calling thread, and stop everything cleanly within a
second when asked (Ctrl-C, ``--duration``, or a component whose error policy is ``stop_app``).
"""

from __future__ import annotations

import logging
import threading
import time
from types import UnionType
from typing import Callable, Protocol, Union, get_args, get_origin
from .activity import Activity
from .component import Component, ErrorPolicy, UnknownNameError
from .connections import Connection, End, make_connection
from .deployment import drive_unplanned
from .filters import Filter
from .filters import Router as RoutingFilter
from .hosts.auth import Refusals
from .hosts.clock import ClockOffset
from .errors import CocoError, WiringError, did_you_mean
from .lifecycle import STOP_TIMEOUT, Progress, StartGate
from .policy import BufferPolicy, ConnectionPolicy, SyncPolicy
from .operations import Operation
from .ports import InputPort, OutputPort, PooledOutputPort, Port, type_name
from .profiling import MessageAges
from .processes.remote import RemoteOperation, Router
from .thread_placement import available_cores
from .stamps import Stamp
from .transforms.graph import TransformGraph

log = logging.getLogger("coco")

WRITER_POLL = 0.002
"""Seconds between two looks at whether writers in other processes have finished (a natural stop)."""


def check_stamps_only(into: InputPort) -> None:
    """A stamps-only connection gives its reader :class:`~coco_core.stamps.Stamp` values: the input
    must take them (from a plain output or a pooled one, whose frames it never holds)."""
    if not types_compatible(Stamp, into.type):
        raise WiringError(f"a stamps-only connection gives {into.qualified_name} the messages' stamps "
                          f"(coco_core.stamps.Stamp), and that port takes {type_name(into.type)}; "
                          "connect it to a port of type Stamp or object")


def types_compatible(source: object, sink: object) -> bool:
    """Whether values of port type ``source`` may flow into an input of port type ``sink``.

    Generic types compare by their origin when either side is unparameterised
    (``Stamped[float]`` flows into ``Stamped``); two parameterised types must be equal. An input typed
    as a union accepts any of its members (``int`` flows into ``int | None``).
    """
    if sink is object or source is object:
        return True
    if get_origin(sink) in (Union, UnionType):
        return any(types_compatible(source, member) for member in get_args(sink))
    if get_origin(source) in (Union, UnionType):
        return all(types_compatible(member, sink) for member in get_args(source))
    if get_args(source) and get_args(sink):
        return source == sink
    source, sink = get_origin(source) or source, get_origin(sink) or sink
    if isinstance(source, type) and isinstance(sink, type):
        return issubclass(source, sink)
    return source == sink


def activity_of(end: End | None) -> Activity | None:
    """The activity that runs the owner of the port at ``end`` of a connection; None without a port
    (the other process's side of a channel) or an activity."""
    return end.owner.activity if isinstance(end, Port) and end.owner is not None else None


class ApplicationHost(Protocol):
    """What may host a process's part of an application besides CoCo's own threads: it starts with
    the application and is closed after it stopped (the ROS launcher's ``ExecutorHost``)."""

    def start(self) -> None: ...

    def close(self) -> None: ...


class Application:
    """A set of components, connections and activities that start and stop together."""

    def __init__(self, name: str = "coco", on_error: ErrorPolicy | None = None) -> None:
        self.name = name
        self.on_error = on_error or ErrorPolicy.CONTINUE
        """What a component's error does, unless the component has a policy of its own."""
        self.stops_on_refused_config = on_error is None
        """Whether a component that refuses its configuration (raises in ``on_config``) stops the
        application: yes unless a policy was given. Why: such a component never runs (a haptic
        device without its trajectory), and an application running on without it only looks
        healthy; ``continue`` or ``stop_component``, given, say that it may."""
        self.process = ""
        """Which ``<process>`` of the application this object runs; empty: the launcher's own. The
        launcher's application also holds stand-ins of the activities its child processes run."""
        self.elsewhere: dict[str, str] = {}
        """Components that another process of the application runs -> that process."""
        self.router: Router | None = None
        """What carries operation calls to the other processes (set by the process level)."""
        self._host: ApplicationHost | None = None
        self._components: dict[str, Component] = {}
        self.activities: dict[str, Activity] = {}
        self.connections: list[Connection] = []
        self.outgoing: list[Connection] = []
        """The writers' ends of connections into other processes (their readers' processes profile them)."""
        self.attribute_watchers: list[Callable[[Component, str], None]] = []
        """Called with the component and the attribute's name after ``set_attribute`` changed one at
        run time (in the component's thread): what shows the running values (the ROS launcher's
        parameters) follows."""
        self.incoming_filters: dict[str, Filter] = {}
        """The filters of connections from other processes into this one, by ``src->dest`` label:
        made by the builder (a Merge in its group, in file order) and put on the reader's side of
        the channel when the process level attaches it (:mod:`coco_core.processes.filtered`)."""
        self.outgoing_routers: dict[str, RoutingFilter] = {}
        """The Split and Cull filters of connections from this process into other processes or
        hosts, by ``src->dest`` label: made by the builder (a Split numbered among its output's
        connections in file order), they decide on the writer's end of the channel, before a message
        crosses (:mod:`coco_core.processes.routed`)."""
        self._stop_requested = threading.Event()
        self._stop_listeners: list[Callable[[str], None]] = []
        self._damage_listeners: list[Callable[[str], None]] = []
        self._stop_requested_at = 0.0
        self.stop_reason = ""
        self._started = False
        self._stopped = False
        self._clean = True
        """Whether the stop was clean (every activity finished in time): what later stop() calls say."""
        self.started_at = 0.0
        self.measure_ages = False
        """Whether each connection's reader records the age of what it takes (:class:`~coco_core.
        profiling.MessageAges`, the profile's ``age`` column): set by a profiled launch
        (``--profile``) before :meth:`start`, which gives every connection its record then, once the
        process level has attached the channels from other processes."""
        self.transforms = TransformGraph()
        """The application's transformation graph, shared by every component (thread-safe)."""
        self._hard_at: float | None = None
        """When a hard stop (a signal, a fault) was first asked; None while the stop is natural."""
        self.progress = Progress()
        """What a natural stop waits on (:mod:`coco_core.lifecycle`)."""
        self.gate = StartGate()
        """Configure all, then start all (:mod:`coco_core.lifecycle`): what every driver waits for
        between an activity's ``configure`` and its first cycle."""
        self.damage: list[str] = []
        """Damaged input found while running (e.g. a truncated bag), one line each: the launchers
        exit non-zero and summaries report it, although the application ran on what was readable.
        With processes, each process's list also holds what the others found (the process level
        passes it on), so that a summary sees the damage of the whole application."""
        self.clock = ClockOffset()
        """This host's clock against the application's (the first host's), measured when the hosts
        joined (:mod:`coco_core.hosts.clock`); the identity on one host. A component that sends its
        stamps to another host by a way of its own (a stream) puts them on the application's clock
        with it, and its reader back on its own, as connections between hosts do."""
        self.network_refusals = Refusals()
        """Messages from other hosts this process refused (not authenticated, replayed, from a host
        the file does not declare): counted by topic and sender for the profile, never damage and
        never a stop, so that a packet from outside changes nothing (:mod:`coco_core.hosts.auth`)."""

    # --- host ------------------------------------------------------------------------------------
    @property
    def host(self) -> ApplicationHost | None:
        """What hosts this process's part beyond CoCo's own threads (the ROS launcher's
        ``coco_ros.hosting.ExecutorHost``: its node, callback groups, wait sets); None: none."""
        return self._host

    def hosted_by(self, host: ApplicationHost) -> None:
        """Give this process's part its host, once and before it starts (components reach it
        through ``app.host``, e.g. ``coco_ros.hosting.ros_node``)."""
        if self._started:
            raise CocoError(f"application {self.name} already started: its host cannot change")
        if self._host is not None and self._host is not host:
            raise CocoError(f"application {self.name} is hosted by {self._host!r} already")
        self._host = host

    # --- composition ----------------------------------------------------------------------------
    def add(self, component: Component, activity: Activity | str | None = None) -> Component:
        """Add ``component`` and its peers (``init`` runs now), optionally scheduling it."""
        members = component.walk()
        for member in members:
            if member.name in self._components:
                raise CocoError(f"two components are called {member.name!r}; instance names must be unique")
        for member in members:
            self._components[member.name] = member
            member.app = self
        for member in reversed(members):
            member.init()
        made = [member for member in component.walk() if member.app is not self]
        for member in made:  # peers an owner's init made (RgbdCameraReader's from its backend attribute)
            if member.name in self._components:
                raise CocoError(f"two components are called {member.name!r}; instance names must be unique")
            self._components[member.name] = member
            member.app = self  # its damage reaches the application, its row the profile
        for member in reversed(made):
            member.init()
        if activity is not None:
            self.schedule(component, activity)
        return component

    def add_activity(self, activity: Activity) -> Activity:
        if activity.name in self.activities:
            raise CocoError(f"two activities are called {activity.name!r}")
        if activity.main and any(other.main for other in self.activities.values()):
            raise CocoError(f"activity {activity.name!r} cannot be main: another activity already is")
        self.activities[activity.name] = activity
        return activity

    def schedule(self, component: Component | str, activity: Activity | str) -> None:
        """Put a component (by object or name) into an activity (by object or name)."""
        target = activity if isinstance(activity, Activity) else self.activity(activity)
        if target.name not in self.activities:
            self.add_activity(target)
        target.add(component if isinstance(component, Component) else self.component(component))

    def component(self, name: str) -> Component:
        try:
            return self._components[name]
        except KeyError:
            if name in self.elsewhere:
                raise UnknownNameError(
                    f"component {name!r} runs in process {self.elsewhere[name] or 'launcher'}, not in this one "
                    f"({self.process or 'launcher'}): reach it through its ports, or call its operations "
                    f"by name (Component.find_operation)") from None
            raise UnknownNameError(f"no component {name!r} in application {self.name}; "
                                   f"{did_you_mean(name, self._components)}") from None

    @property
    def components(self) -> dict[str, Component]:
        """Every component by instance name, peers included."""
        return dict(self._components)

    def attribute_changed(self, component: Component, name: str) -> None:
        """Tell the :attr:`attribute_watchers` that ``component``'s attribute ``name`` changed."""
        for watcher in self.attribute_watchers:
            watcher(component, name)

    def operation(self, component: str, name: str) -> Operation | RemoteOperation:
        """The operation ``name`` of ``component``, called by name: a local one, or one that another
        process of the application runs (its result comes back to the Future all the same)."""
        process = self.elsewhere.get(component)
        if process is not None:
            return RemoteOperation(self, process, component, name)
        return self.component(component).operation(name)

    def activity(self, name: str) -> Activity:
        try:
            return self.activities[name]
        except KeyError:
            raise UnknownNameError(f"no activity {name!r} in application {self.name}; "
                                   f"{did_you_mean(name, self.activities)}") from None

    def _port(self, ref: str | Port) -> Port:
        if isinstance(ref, Port):
            return ref
        component, dot, port = ref.rpartition(".")
        if not dot:
            raise CocoError(f"port reference {ref!r} must be 'component.port'")
        return self.component(component).port(port)

    def connect(self, source: str | Port, sink: str | Port,
                policy: ConnectionPolicy | None = None, event: bool | None = None,
                connection: Connection | None = None, stamps_only: bool = False) -> Connection:
        """Connect an output to an input (``"camera.image"`` or port objects) with ``policy``.

        ``event`` overrides whether writes on this connection wake the sink's triggered activity.
        ``connection``: the storage to use instead of the policy's (a :mod:`filter <.filters>`).
        ``stamps_only``: the connection carries each message's stamp, not its payload (FlowVR's
        dashed connections): the input reads :class:`~coco_core.stamps.Stamp` values.
        """
        policy = policy or ConnectionPolicy()
        out, into = self._port(source), self._port(sink)
        if not isinstance(out, OutputPort):
            raise WiringError(f"{out.qualified_name} is an input port; a connection starts at an output "
                                   f"(outputs of {out.owner.name if out.owner else '?'}: "
                                   f"{', '.join(out.owner.outputs) if out.owner else ''})")
        if not isinstance(into, InputPort):
            raise WiringError(f"{into.qualified_name} is an output port; a connection ends at an input "
                                   f"(inputs of {into.owner.name if into.owner else '?'}: "
                                   f"{', '.join(into.owner.inputs) if into.owner else ''})")
        if stamps_only:
            check_stamps_only(into)
        elif not types_compatible(out.type, into.type):
            raise WiringError(f"cannot connect {out.qualified_name} ({type_name(out.type)}) to "
                                   f"{into.qualified_name} ({type_name(into.type)}): types differ")
        if connection is None:
            connection = self._make(out, policy, stamps_only)
        elif isinstance(out, PooledOutputPort) and not stamps_only:
            raise WiringError(f"{out.qualified_name} is a pooled output: its frames go to every reader as they "
                              f"are and cannot pass through a {connection.describe()} filter")
        out.add_connection(connection, stamps_only)
        into.add_connection(connection, event)
        if connection.pending and connection.trigger is not None:
            connection.trigger()  # it holds values from the start (a PreSignal's tokens): as if written now
        self.connections.append(connection)
        return connection

    @staticmethod
    def _make(out: OutputPort, policy: ConnectionPolicy, stamps_only: bool = False) -> Connection:
        """The connection ``policy`` makes from ``out``: a reader of a pooled output's pool, or a
        connection of its own (a stamps-only one from a pooled output too: it carries stamps)."""
        if stamps_only and policy.data is BufferPolicy.POOL:
            raise WiringError(f"a stamps-only connection from {out.qualified_name} carries the messages' stamps, "
                              "not frames: connect it with data=DATA, BUFFER or CIRCULAR, not POOL")
        if isinstance(out, PooledOutputPort) and not stamps_only:
            if policy.data not in (BufferPolicy.DATA, BufferPolicy.POOL):
                raise WiringError(f"{out.qualified_name} is a pooled output: connect it with data=POOL "
                                       f"(latest frame, no copy), not {policy.data.value}")
            return out.connection()
        if policy.data is BufferPolicy.POOL:
            raise WiringError(f"data=POOL needs a pooled output port; {out.qualified_name} is not one "
                                   "(use DATA, BUFFER or CIRCULAR)")
        return make_connection(policy)

    # --- checks ---------------------------------------------------------------------------------
    def problems(self) -> list[tuple[Connection | Component, str]]:
        """What would make this application run wrongly, with the object each problem is about."""
        found: list[tuple[Connection | Component, str]] = []
        for connection in self.connections:
            if connection.policy.sync is not SyncPolicy.UNSYNC:
                continue
            writer, reader = activity_of(connection.source), activity_of(connection.sink)
            if writer is None or writer is not reader:
                names = (writer.name if writer else "none", reader.name if reader else "none")
                found.append((connection, f"UNSYNC connection {connection.source.qualified_name} -> "  # type: ignore[union-attr]
                                          f"{connection.sink.qualified_name} joins activities {names[0]} and "  # type: ignore[union-attr]
                                          f"{names[1]}; UNSYNC is only valid inside one activity (use LOCKED "
                                          "or LOCK_FREE)"))
        return found

    def unscheduled(self) -> list[Component]:
        """Top-level components no activity runs (they are configured, and serve operations)."""
        return [c for c in self._components.values() if c.owner is None and c.activity is None]

    # --- running --------------------------------------------------------------------------------
    def start(self) -> None:
        """Start every activity but the main one (see :meth:`run`). Each configures at once, in its
        driver's thread, and cycles once every activity is configured (:attr:`gate`): the main
        one too, so with a main activity nothing cycles before :meth:`run` (or
        ``main.run_here()``) configured it."""
        if self._started:
            raise CocoError(f"application {self.name} was already started")
        problems = self.problems()
        if problems:
            raise CocoError("\n".join(text for _, text in problems))
        self._started = True
        self.started_at = time.perf_counter()
        if self.measure_ages:
            for connection in self.connections:
                connection.measure_ages(MessageAges())
        drive_unplanned(self)  # an application built in code: the plan of its own activities drives them
        reserved = self._exclusive_cores()
        self.gate.expect(self.activities)
        for component in self.unscheduled():
            log.warning("component %s is in no activity: it is configured and serves operations, "
                        "but on_update never runs", component.name)
            component.configure()
        for activity in self.activities.values():
            activity.reserved_cores = reserved - set(activity.scheduling.affinity)
            activity.gate = self.gate
            activity.start()

    def _exclusive_cores(self) -> set[int]:
        reserved: set[int] = set()
        for activity in self.activities.values():
            if activity.scheduling.exclusive:
                reserved |= set(activity.scheduling.affinity) & available_cores()
        return reserved

    @property
    def main_activity(self) -> Activity | None:
        return next((a for a in self.activities.values() if a.main), None)

    def run(self, duration: float | None = None) -> None:
        """Start, run until stopped (or for ``duration`` seconds), then stop cleanly.

        The main activity, if any, runs in the calling thread.
        """
        self.start()
        timer = self.stop_after(duration) if duration is not None else None
        try:
            main = self.main_activity
            if main is not None:
                main.run_here()
            self._stop_requested.wait()
        finally:
            if timer is not None:
                timer.cancel()
            self.stop()

    def stop_after(self, duration: float) -> threading.Timer:
        """Ask for a stop ``duration`` seconds after the application starts running: from the opening
        of its gate (every activity of every process configured), so that a slow configuration (an
        OpenGL context, a URDF, on a loaded machine) does not eat into the time asked for (``--duration
        3`` once ran no cycle at all). Cancel the returned timer when the run ends first."""
        timer = threading.Timer(duration, self.request_stop, args=(f"duration of {duration:g} s reached",))
        timer.daemon = True
        self.gate.when_open(timer.start)
        return timer

    def report_damage(self, what: str, *, here: bool = True) -> None:
        """Record damaged input (see :attr:`damage`); list.append is atomic, any thread may call it.
        ``here``: found by this process's components, so the damage listeners pass it on to the
        other processes; False for damage another process found (the process level's delivery)."""
        self.damage.append(what)
        if here:
            for listener in self._damage_listeners:
                listener(what)

    def add_damage_listener(self, listener: Callable[[str], None]) -> None:
        """Call ``listener(what)`` for each damage this process's components report (the process
        level tells the other processes of the application)."""
        self._damage_listeners.append(listener)

    def request_stop(self, reason: str = "stop requested", hard: bool = False) -> None:
        """Ask every activity to stop; returns at once (from any thread or component; not from a
        signal handler, which may interrupt a thread that holds a lock this takes: the launchers'
        handlers only record, :mod:`coco_core.signals`).

        ``hard``: a signal or a fault, after which :meth:`stop` waits :data:`STOP_TIMEOUT` seconds at
        most; otherwise the application asks itself (its work is done) and the activities get what
        their work needs to finish and flush (:mod:`coco_core.lifecycle`). A hard request during a
        natural stop bounds it from then on."""
        first = not self._stop_requested.is_set()
        if hard and self._hard_at is None:
            self._hard_at = time.monotonic()
        running = self.gate.is_open  # before it: no cycle ran, nothing to drain, nothing configures
        if first:
            self.stop_reason = reason
            self._stop_requested_at = time.monotonic()
            # Said when no cycle ran (not started yet, or still configuring): an output that a component
            # makes when it configures may then be absent.
            early = "" if running else " (before it ran: no activity had cycled)"
            log.info("stopping application %s: %s%s", self.name, reason, early)
        self._stop_requested.set()
        self.gate.open()  # nothing waits for a start that will not come
        if self.stop_is_hard or not running:
            for activity in self.activities.values():
                activity.stop()
        else:  # the others once their feeders have finished (stop)
            order, fed = self.stop_order()
            for activity in order:
                if activity.name not in fed:
                    activity.stop(drain=True)
        if first:
            for listener in self._stop_listeners:
                listener(reason)

    def add_stop_listener(self, listener: Callable[[str], None]) -> None:
        """Call ``listener(reason)`` once, when a stop is first requested (the process level tells the
        other processes of the application)."""
        self._stop_listeners.append(listener)

    def stop_order(self) -> tuple[list[Activity], set[str]]:
        """The order in which a natural stop stops the activities, feeders first, and the names of
        those that wait for their feeders: an activity is *fed* by another of this process when a
        component of the other writes to one of its components. A triggered activity stopped with
        its feeders still running would leave their last values pending (the last frame a display
        rendered, for the writer that records it); stopped after them, it drains what waits
        (:meth:`Activity.stop`). Activities on a cycle of feeders do not wait for each other, nor does
        the main activity (the thread that runs it is the one that stops the others); feeders in
        other processes are not known here (each process orders its own part)."""
        activities = list(self.activities.values())
        known = {id(activity) for activity in activities}
        feeders: dict[str, set[str]] = {activity.name: set() for activity in activities}
        outside = self.fed_from_outside()
        for connection in self.connections:
            writer, reader = activity_of(connection.source), activity_of(connection.sink)
            if writer is not None and reader is not None and writer is not reader and {id(writer), id(reader)} <= known:
                feeders[reader.name].add(writer.name)
        order: list[Activity] = []
        placed: set[str] = set()
        while True:
            ready = [a for a in activities if a.name not in placed and feeders[a.name] <= placed]
            if not ready:
                break
            order += ready
            placed.update(a.name for a in ready)
        fed = {a.name for a in order if (feeders[a.name] or a.name in outside) and not a.main}  # main: it stops them
        order += [a for a in activities if a.name not in placed]  # on a cycle: stopped at once
        return order, fed

    def fed_from_outside(self) -> dict[str, list[Connection]]:
        """The queued connections (BUFFER, CIRCULAR) from another process into each activity of this
        one, by activity name: on a natural stop the activity waits until their writers' activities
        have finished (:attr:`Connection.writer_finished`) before it stops and reads what they wrote
        last. Without it a recorder stopped with its process while the 1 kHz loop of another process
        still wrote lost the loop's last samples. Latest-value connections (DATA, POOL) do not wait:
        a value left unread there is not lost data, and they may close a loop between processes."""
        outside: dict[str, list[Connection]] = {}
        for connection in self.connections:
            activity = activity_of(connection.sink)
            if (connection.source is None and activity is not None
                    and connection.policy.data in (BufferPolicy.BUFFER, BufferPolicy.CIRCULAR)):
                outside.setdefault(activity.name, []).append(connection)
        return outside

    def _writers_finished(self, connections: list[Connection], timeout: float) -> bool:
        """Whether every writer of ``connections`` has finished; waits up to ``timeout`` seconds."""
        deadline = time.monotonic() + timeout
        while not all(connection.writer_finished for connection in connections):
            if time.monotonic() >= deadline:
                return False
            time.sleep(min(WRITER_POLL, timeout))
        return True

    def in_flight(self, besides: Activity | None = None) -> bool:
        """Whether data is still moving through the application: an activity (other than ``besides``,
        typically the caller's own) is in a cycle or has a wake-up waiting, or a queued (BUFFER,
        CIRCULAR) connection holds data, into another process too. Latest-value connections (DATA,
        POOL) do not count: a value left unread there is not in flight. A producer that is done asks
        this before stopping the application, so that what it produced last is processed, not
        dropped. (An activity of another process is seen while a wake-up waits for it, not while it
        runs its cycle.)"""
        busy = any(a is not besides and (a.current is not None or a.wake_pending) for a in self.activities.values())
        return busy or any(c.pending for c in [*self.connections, *self.outgoing]
                           if c.policy.data in (BufferPolicy.BUFFER, BufferPolicy.CIRCULAR))

    @property
    def stop_requested(self) -> bool:
        return self._stop_requested.is_set()

    @property
    def stop_is_hard(self) -> bool:
        """Whether a signal or a fault asked the stop (see :meth:`request_stop`)."""
        return self._hard_at is not None

    def stop_deadline(self, begun: float, timeout: float = STOP_TIMEOUT) -> float | None:
        """The monotonic time by which a wait that began at ``begun`` must end: ``timeout`` after it
        (or after the hard request, when that came later) for a hard stop; None for a natural one,
        which waits while it progresses (:class:`~coco_core.lifecycle.Progress`)."""
        return None if self._hard_at is None else max(begun, self._hard_at) + timeout

    def wait(self, timeout: float | None = None) -> bool:
        """Block until a stop is requested; False on timeout."""
        return self._stop_requested.wait(timeout)

    def stop(self, timeout: float = STOP_TIMEOUT) -> bool:
        """Stop every activity; False if one hung. After a hard stop (see :meth:`request_stop`) they
        get ``timeout`` seconds in total; after a natural one, as long as the application progresses,
        and ``timeout`` seconds without progress."""
        if self._stopped:
            return self._clean
        self._stopped = True
        self.request_stop(self.stop_reason or "stop requested")
        begun = time.monotonic()
        clean = True
        order, fed = self.stop_order()
        outside = self.fed_from_outside()
        # This process's own activities are joined before the stand-ins of other processes' (which
        # wait for a whole child): a child's reader may be waiting for one of ours to finish writing.
        order.sort(key=lambda activity: activity.process != self.process)
        for activity in order:  # feeders first: every feeder of an activity has finished when it stops
            if activity.name in fed and not activity.stopping:
                writers = outside.get(activity.name, [])
                if writers and not self.progress.wait(lambda seconds: self._writers_finished(writers, seconds),
                                                      lambda: self.stop_deadline(begun, timeout)):
                    log.warning("activity %s: a writer in another process did not finish; stopping without "
                                "its last values", activity.name)
                activity.stop(drain=True)
            if self.progress.wait(activity.join, lambda: self.stop_deadline(begun, timeout)):
                self.progress.advance()
                continue
            clean = False
            where = f" (inside {activity.current.name}.on_update)" if activity.current else ""
            if self.stop_is_hard:
                log.error("activity %s did not stop within %.1f s%s; abandoning its thread",
                          activity.name, timeout, where)
            else:
                log.error("activity %s did not stop: no progress for %.1f s after the application's own stop "
                          "request%s; abandoning its thread", activity.name, timeout, where)
        for component in self.unscheduled():
            component.stop()
        self._clean = clean
        log.info("application %s stopped %.3f s after the request (%s)", self.name,
                 time.monotonic() - self._stop_requested_at, "clean" if clean else "some activities did not stop")
        return clean

    def pause(self, paused: bool) -> None:
        """Hold every activity's cycles, in every process, or let them run again
        (:meth:`StartGate.pause`); resumed, this process's triggered activities look at what was
        written to them meanwhile."""
        self.gate.pause(paused)
        if not paused:
            for activity in self.activities.values():
                if activity.process == self.process:
                    activity.wake()

    def set_period(self, activity: str, period: float) -> None:
        """Change a periodic activity's period (seconds) while it runs."""
        target = self.activity(activity)
        if target.period is None:
            raise CocoError(f"activity {activity} is {target.describe()}, it has no period")
        target.set_period(period)

    def schedule_tree(self) -> list[tuple[Activity | None, list[Component]]]:
        """The scheduling tree's activity level, unscheduled components last."""
        tree: list[tuple[Activity | None, list[Component]]] = [
            (activity, list(activity.components)) for activity in self.activities.values()]
        rest = self.unscheduled()
        if rest:
            tree.append((None, rest))
        return tree
