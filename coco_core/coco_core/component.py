"""The component: CoCo's unit of computation.

A component declares, on its class, typed attributes, input and output ports and operations, and
implements the life cycle ``init`` -> ``on_config`` -> ``on_update`` (repeated) -> ``on_stop``.
It never knows which activity, thread or process runs it: that is the scheduling tree's business,
decided in the application file.

Life cycle and threads:
- ``init()`` runs when the component is added to an application, after its attributes were set from
  the file, in the thread building the application: declare ports that depend on attributes here.
- ``on_config()`` runs in the component's activity thread before the first update (thread-bound
  resources such as OpenGL contexts belong here).
- ``on_update()`` runs every activation of the activity; pending operation calls run before it.
- ``on_stop()`` runs in the activity thread when the application stops: flush and close here.
Peers (nested components) follow their owner: configured before it, updated after it (unless the
owner sets ``manages_peers`` and calls ``peer.step()`` itself, e.g. to render in order), stopped after it.
"""

from __future__ import annotations

import contextlib
import enum
import logging
import time
import traceback
from concurrent.futures import Future
from typing import TYPE_CHECKING, Any, Callable, ClassVar, Iterator

from .attributes import Attribute, FileAttribute
from .errors import CocoError, DeclarationError, FileReadError, UnknownNameError, did_you_mean
from .hosts.clock import ClockOffset
from . import operations as ops
from .operations import Operation
from .ports import InputPort, OutputPort, Port
from .profiling import ComponentStats
from .stamps import Stamp

if TYPE_CHECKING:
    from .processes.remote import RemoteOperation
    from .activity import Activity
    from .application import Application
    from .transforms.graph import TransformGraph

log = logging.getLogger("coco")

DAMAGE_LISTED = 10
"""Refused samples a component reports as damaged input one by one (:meth:`Component.refuse_damaged_input`)."""


class ErrorPolicy(enum.Enum):
    """What happens when a component's callback raises."""

    CONTINUE = "continue"
    """Report, count, and keep calling it."""
    STOP_COMPONENT = "stop_component"
    """Report and stop calling this component (its activity goes on with the others)."""
    STOP_APP = "stop_app"
    """Report and stop the whole application cleanly."""


_TRACEBACKS_SHOWN = 3
"""Full tracebacks logged per component before switching to periodic one-line summaries."""


class Component:
    """Base class of every CoCo component.

    Construct with the instance name and any attribute values: ``MovingAverage("filter", window=8)``.
    """

    manages_peers: ClassVar[bool] = False
    """True when the component runs its peers itself (``peer.step()``) instead of after ``on_update``."""
    thread_bound: ClassVar[bool] = False
    """True when the component holds a resource tied to the thread that created it (an OpenGL context
    is current in one thread only): its activity must then run every cycle in one thread, which a host
    that spreads callbacks over a thread pool (the ROS launcher's executor) has to honour."""

    dynamic_ports: ClassVar[str] = ""
    """Which ports ``init`` makes from the attributes (a ROSInterface's, one per topic): what
    ``--list`` shows of a component whose ports are not all declared on its class."""

    _attribute_decls: ClassVar[dict[str, Attribute]] = {}
    _port_decls: ClassVar[dict[str, Port]] = {}
    _operation_decls: ClassVar[dict[str, str]] = {}

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        attributes: dict[str, Attribute] = {}
        ports: dict[str, Port] = {}
        operations: dict[str, str] = {}
        for klass in reversed(cls.__mro__):
            for name, member in vars(klass).items():
                if isinstance(member, Attribute):
                    attributes[name] = member
                elif isinstance(member, Port):
                    ports[name] = member
                elif callable(member) and hasattr(member, "_coco_operation"):
                    operations[member._coco_operation] = name
        clashes = sorted((set(attributes) | set(ports)) & _RESERVED_NAMES)
        if clashes:
            raise DeclarationError(f"component {cls.__name__}: {', '.join(clashes)} would shadow Component's own "
                                   "member(s) of that name; choose another attribute or port name")
        cls._attribute_decls, cls._port_decls, cls._operation_decls = attributes, ports, operations

    def __init__(self, name: str | None = None, **attributes: Any) -> None:
        self.name = name or type(self).__name__
        self.owner: Component | None = None
        self._activity: Activity | None = None
        self._attribute_values: dict[str, Any] = {}
        self.inputs: dict[str, InputPort] = {}
        self.outputs: dict[str, OutputPort] = {}
        for port_name, declaration in self._port_decls.items():
            self._add_port(declaration.bind(self, port_name))
        self._operations: dict[str, Operation] = {
            op_name: Operation(self, op_name, getattr(self, method))
            for op_name, method in self._operation_decls.items()
        }
        self.peers: list[Component] = []
        self.app: Application | None = None
        self.stats = ComponentStats()
        self.on_error: ErrorPolicy | None = None
        """None: the application's policy (continue when standalone)."""
        self.enabled = True
        self._configured = False
        """Set once ``on_config`` succeeded: only configured components get ``on_stop``. Private,
        like every base-class field a subclass could otherwise shadow by accident."""
        self._last_error_log = 0.0
        self._refusals_reported: set[type] = set()
        for attribute_name, value in attributes.items():
            self.set_attribute_now(attribute_name, value)

    # --- life cycle, overridden by components ---------------------------------------------------
    def init(self) -> None:
        """Declare what depends on attributes (dynamic ports, operations); no threads yet."""

    def on_config(self) -> None:
        """Acquire resources, in the activity thread, before the first update."""

    def on_update(self) -> None:
        """One activation: read inputs, compute, write outputs. Must not block."""

    def on_stop(self) -> None:
        """Release resources and flush what was produced, in the activity thread."""

    # --- declarations at run time ---------------------------------------------------------------
    def add_input(self, name: str, type_: Any = object, event: bool = False, doc: str = "") -> InputPort:
        """Declare an input port from ``init`` (e.g. one per configured topic)."""
        port = InputPort(type_, event, doc).bind(self, name)
        self._add_port(port)
        return port

    def add_output(self, name: str, type_: Any = object, doc: str = "") -> OutputPort:
        """Declare an output port from ``init``."""
        port = OutputPort(type_, doc).bind(self, name)
        self._add_port(port)
        return port

    def _add_port(self, port: Port) -> None:
        if port.name in self.inputs or port.name in self.outputs:
            raise CocoError(f"component {self.name}: port {port.name!r} declared twice")
        target: dict[str, Any] = self.inputs if isinstance(port, InputPort) else self.outputs
        target[port.name] = port
        if isinstance(port, InputPort) and self.activity is not None and self.activity.wakes_on_data:
            port.set_wake(self.activity.wake)
        if isinstance(port, OutputPort):
            port.activity = self.activity
        # Declared ports shadow the class-level declaration of the same name.
        self.__dict__[port.name] = port

    def add_operation(self, name: str, function: Callable[..., Any]) -> Operation:
        """Declare an operation from a plain function (the decorator covers methods)."""
        op = Operation(self, name, function)
        self._operations[name] = op
        return op

    def add_peer(self, peer: Component) -> Component:
        """Nest ``peer``: it shares this component's activity and is run by it."""
        if peer.owner is not None:
            raise CocoError(f"component {peer.name} is already a peer of {peer.owner.name}")
        peer.owner = self
        self.peers.append(peer)
        peer._stamp_outputs()
        return peer

    # --- lookups with errors that list the valid names ------------------------------------------
    def port(self, name: str) -> Port:
        """The input or output port called ``name``."""
        port = self.inputs.get(name) or self.outputs.get(name)
        if port is None:
            valid = list(self.inputs) + list(self.outputs)
            raise UnknownNameError(f"component {self.name} ({type(self).__name__}) has no port {name!r}; "
                                   f"{did_you_mean(name, valid)}")
        return port

    def operation(self, name: str) -> Operation:
        """The operation called ``name``, to call from any thread."""
        try:
            return self._operations[name]
        except KeyError:
            raise UnknownNameError(f"component {self.name} ({type(self).__name__}) has no operation {name!r}; "
                                   f"{did_you_mean(name, self._operations)}") from None

    @property
    def operations(self) -> dict[str, Operation]:
        return dict(self._operations)

    def attribute_declaration(self, name: str) -> Attribute:
        try:
            return self._attribute_decls[name]
        except KeyError:
            raise UnknownNameError(f"component {self.name} ({type(self).__name__}) has no attribute {name!r}; "
                                   f"{did_you_mean(name, self._attribute_decls)}") from None

    def find_component(self, name: str) -> Component:
        """Another component of the same application, by instance name."""
        if self.app is None:
            raise CocoError(f"component {self.name} is not part of an application")
        return self.app.component(name)

    def find_operation(self, component: str, operation: str) -> Operation | RemoteOperation:
        """An operation of another component of the application, by names: callable the same way
        whether that component runs in this process or in another one."""
        if self.app is None:
            raise CocoError(f"component {self.name} is not part of an application")
        return self.app.operation(component, operation)

    @property
    def transform_graph(self) -> TransformGraph:
        """The application's transformation graph (thread-safe: read and write it from any activity)."""
        if self.app is None:
            raise CocoError(f"component {self.name} is not part of an application, so it has no "
                            "transformation graph")
        return self.app.transforms

    @property
    def host_clock(self) -> ClockOffset:
        """This host's clock against the application's (:attr:`Application.clock
        <coco_core.application.Application.clock>`): what stamps sent to another host by a way of
        the component's own are converted with; the identity outside an application."""
        return self.app.clock if self.app is not None else ClockOffset()

    # --- attributes -----------------------------------------------------------------------------
    def set_attribute_now(self, name: str, value: Any) -> None:
        """Set an attribute immediately (text is parsed). Use from the component's own thread or
        before it runs; other threads use :meth:`set_attribute`."""
        declaration = self.attribute_declaration(name)
        declaration.__set__(self, value)

    def attributes(self) -> dict[str, Any]:
        """Current value of every declared attribute."""
        return {name: getattr(self, name) for name in self._attribute_decls}

    @ops.operation
    def set_attribute(self, name: str, value: Any) -> None:
        """Change an attribute at run time; validated, applied between two updates. The
        application's attribute watchers hear of it (the ROS launcher's parameters show what runs)."""
        self.set_attribute_now(name, value)
        if self.app is not None:
            self.app.attribute_changed(self, name)

    @ops.operation
    def get_attribute(self, name: str) -> Any:
        """Read an attribute at run time, consistently with the component's own thread."""
        self.attribute_declaration(name)
        return getattr(self, name)

    # --- scheduling -----------------------------------------------------------------------------
    @property
    def activity(self) -> Activity | None:
        """The activity that runs this component (its owner's, for a peer)."""
        return self.owner.activity if self.owner is not None else self._activity

    @activity.setter
    def activity(self, activity: Activity | None) -> None:
        self._activity = activity
        self._stamp_outputs()

    def _stamp_outputs(self) -> None:
        """Give the output ports of this component and its peers the activity that runs each, whose
        cycle number stamps their messages: a write then reads its port's field, not this property."""
        for component in self.walk():
            for port in component.outputs.values():
                port.activity = component.activity

    def walk(self) -> list[Component]:
        """This component and its peers, depth first."""
        found = [self]
        for peer in self.peers:
            found.extend(peer.walk())
        return found

    def configure(self) -> bool:
        """Run ``on_config`` of the peers, then of this component; False when it failed."""
        for peer in self.peers:
            peer.configure()
        self._configured = self.run_guarded("on_config", self.on_config)
        return self._configured

    def step(self) -> None:
        """One profiled, exception-isolated execution, then the peers' unless managed here; a
        stopped (disabled) component runs neither itself nor its peers."""
        if not self.enabled:
            return
        start = time.perf_counter()
        try:
            self.on_update()
        except Exception:
            self.report_error("on_update")
        self.stats.record(start, time.perf_counter())
        if not self.manages_peers:
            for peer in self.peers:
                peer.step()

    def stop(self) -> None:
        """Run ``on_stop`` of this component (if it was configured), then of its peers; errors are
        reported, not raised."""
        if self._configured:
            self.run_guarded("on_stop", self.on_stop, count_only=True)
            self._configured = False
        for peer in self.peers:
            peer.stop()

    def run_guarded(self, phase: str, callback: Callable[[], None], count_only: bool = False) -> bool:
        """Run ``callback`` (a life-cycle step named ``phase``) under this component's error policy:
        an exception is reported and counted, never raised, so that one component cannot take its
        activity down. Owners that drive their peers' extra phases (GLManager's ``gl_init``) use it too.
        A failure disables the component unless ``count_only``; True when the callback returned."""
        try:
            callback()
        except Exception:
            self.report_error(phase, disable=not count_only)
            return False
        return True

    def report_error(self, phase: str, disable: bool = False) -> None:
        """Report the exception being handled, raised in ``phase``, and apply the error policy (call
        from an ``except`` block)."""
        self.stats.errors += 1
        errors = self.stats.errors
        now = time.monotonic()
        if errors <= _TRACEBACKS_SHOWN:
            log.error("component %s raised in %s (error %d):\n%s", self.name, phase, errors,
                      traceback.format_exc().rstrip())
        elif now - self._last_error_log >= 1.0:
            log.error("component %s raised in %s again (%d errors so far): %s", self.name, phase, errors,
                      traceback.format_exc().strip().splitlines()[-1])
            self._last_error_log = now
        policy = self.error_policy(phase)
        if disable or policy is ErrorPolicy.STOP_COMPONENT:
            self.enabled = False
            log.error("component %s is stopped after its error in %s", self.name, phase)
        if policy is ErrorPolicy.STOP_APP:
            if self.app is not None:
                self.app.request_stop(f"component {self.name} raised in {phase}", hard=True)
            elif self.activity is not None:
                self.activity.stop()

    def error_policy(self, phase: str) -> ErrorPolicy:
        """What an error in ``phase`` does: the component's own policy, else the application's; a
        refused configuration (``on_config``) stops an application that was given no policy
        (:attr:`Application.stops_on_refused_config <coco_core.application.Application.stops_on_refused_config>`)."""
        if self.on_error is not None:
            return self.on_error
        if self.app is None:
            return ErrorPolicy.CONTINUE
        if phase == "on_config" and self.app.stops_on_refused_config:
            return ErrorPolicy.STOP_APP
        return self.app.on_error

    @contextlib.contextmanager
    def reading_attribute_file(self, name: str, expected: str = "") -> Iterator[None]:
        """A block that reads the file attribute ``name`` names, with
        :func:`~coco_core.files.read_regular_file` (a regular file of bounded size: ``/dev/zero``
        would grow without end, a FIFO block ``on_config`` for ever); its error is raised again
        naming the attribute, and ``expected`` (what the file should be; empty: the ``expected`` of
        the attribute's :class:`~coco_core.attributes.FileAttribute` declaration)."""
        declaration = self.attribute_declaration(name)
        if not expected and isinstance(declaration, FileAttribute):
            expected = declaration.expected
        try:
            yield
        except FileReadError as error:
            raise FileReadError(f"attribute {self.name}.{name}: {error}; expected {expected}") from None

    def record_refusal(self, what: str, error: Exception) -> None:
        """Count an input sample this component refused (a malformed value: it read it, so its
        connection shows no drop); the profile reports the count, the log the first reason of each kind."""
        self.stats.refused += 1
        if type(error) not in self._refusals_reported:
            self._refusals_reported.add(type(error))
            log.error("component %s refused %s: %s (further refusals are counted in the profile)",
                      self.name, what, error)

    def refuse_damaged_input(self, source: object, what: str, error: Exception) -> None:
        """Refuse ``what``, a malformed sample read from ``source`` (a bag, a folder): counted (the
        profile's refused column) and reported to the application as damaged input, the first
        :data:`DAMAGE_LISTED` each (the launcher then exits 1 and a summary names them), later ones
        only counted. Why: a recording with broken messages must not pass for a sound one, nor
        flood the summary."""
        self.record_refusal(what, error)
        refused = self.stats.refused
        if self.app is not None and refused <= DAMAGE_LISTED:
            more = (f"; further refused samples are only counted (the profile's refused column of {self.name})"
                    if refused == DAMAGE_LISTED else "")
            self.app.report_damage(f"{self.name}: {source}: {what} refused: {error}{more}")

    def record_merged(self, count: int = 1) -> None:
        """Count ``count`` input samples this component read but folded into a later output (or
        none) instead of giving one of their own: a reader that makes one output per input sample
        says where the rows went, and the profile reports the count."""
        self.stats.merged += count

    def record_latency(self, stamp: Stamp) -> None:
        """Record the age of ``stamp`` now: call when this component outputs what the stamped data
        produced, and the profiler reports the end-to-end latency. Give it the input's
        :attr:`InputPort.origin <coco_core.ports.InputPort.origin>` (a ``Stamped`` value's own
        stamp, a plain value's message stamp), so that a plain input is measured from its write."""
        self.stats.latency.add(time.perf_counter() - stamp.time)

    def call(self, operation_name: str, *args: Any, **kwargs: Any) -> Future:
        """Shorthand for ``self.operation(name)(*args)``."""
        return self.operation(operation_name)(*args, **kwargs)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r}>"


_RESERVED_NAMES = {name for name in vars(Component) if not name.startswith("__")} | {
    "name", "inputs", "outputs", "peers", "owner", "app", "stats", "on_error", "enabled"}
"""What an attribute or port of a subclass may not be called: the base class uses these itself."""
