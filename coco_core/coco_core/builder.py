"""From the application model to a runnable application.

Every problem is reported with the file:line of the element that caused it (unknown task, attribute
or port, a value of the wrong type, an impossible connection), all of them in one pass, and nothing
is started when there is any: a wrong file never half-runs.
"""

from __future__ import annotations

import logging
from pathlib import Path

from . import registry
from .activity import Activity, PeriodicActivity, TriggeredActivity
from .application import Application, types_compatible
from .attributes import AttributeValueError
from .component import Component, ErrorPolicy
from .errors import CocoError, ConfigError, ConfigErrors, FileWriteError, WiringError, did_you_mean
from .filters import (FILTERS, Cull, Filter, Gather, GatherGroup, MaxFrequency, Merge, MergeGroup, PreSignal, Router,
                      Split)
from .iteration import IterationPorts, port_of
from .model import ActivitySpec, AppSpec, ComponentSpec, ConnectionSpec, FilterSpec, LogSpec, PortRef
from .policy import ConnectionPolicy
from .ports import InputPort, OutputPort, Port, type_name
from .processes.placement import LAUNCHER, Placement
from .thread_placement import SchedulingRequest
from .xml.composite import context_of, scope_of

log = logging.getLogger("coco")


class _Builder:
    def __init__(self, spec: AppSpec, placement: Placement, allow_unknown: bool = False) -> None:
        self.spec = spec
        self.placement = placement
        self.errors: list[ConfigError] = []
        self.allow_unknown = allow_unknown
        self.missing: set[str] = set()
        """Components left out because their task is unknown (with ``allow_unknown``), peers included."""
        self.composites = {composite.name: composite for composite in spec.composites}

    def fail(self, error: Exception | str, spec: object, within: str = "") -> None:
        """Record an error at ``spec``'s location; ``within``: the scoped name it concerns, whose
        composite instances the message then names with where each is made (two instances of one
        file share its lines, and differ by their arguments)."""
        context = context_of(within, self.composites) if within else ""
        self.errors.append(ConfigError(f"{error}{context}", getattr(spec, "location", None)))

    def inside(self, connection: ConnectionSpec) -> str:
        """A name that stands for the composite instance ``connection`` is written in: its ends'
        when both are in the same one (a connection from outside to an exposed port is written in
        the application, whose line its error gives); "" otherwise."""
        src, dest = connection.src.component, connection.dest.component
        return src if scope_of(src, self.composites) == scope_of(dest, self.composites) else ""

    def check(self) -> None:
        if self.errors:
            raise ConfigErrors(self.errors)

    def instantiate(self, spec: ComponentSpec) -> Component | None:
        try:
            cls = registry.load(spec.task, spec.library)
        except registry.UnknownComponentError as error:
            if not self.allow_unknown:
                self.fail(error, spec, spec.name)
                return None
            left_out = [spec]
            while left_out:
                self.missing.add(left_out[-1].name)
                left_out.extend(left_out.pop().peers)
            library = f" (library {spec.library!r})" if spec.library else ""
            self.spec.warnings.append(str(ConfigError(
                f"unknown component {spec.task!r}{library}: {spec.name!r} is left out, and its "
                "attributes, peers, ports and connections are not checked", spec.location)))
            return None
        except CocoError as error:
            self.fail(error, spec, spec.name)
            return None
        try:
            component = cls(spec.name)
        except Exception as error:
            self.fail(f"component {spec.name} ({spec.task}) could not be constructed: {error!r}", spec, spec.name)
            return None
        for attribute in spec.attributes:
            try:
                component.set_attribute_now(attribute.name, attribute.value)
            except (KeyError, AttributeValueError) as error:
                self.fail(error, attribute, spec.name)
        if spec.on_error:
            component.on_error = ErrorPolicy(spec.on_error)
        for peer_spec in spec.peers:
            peer = self.instantiate(peer_spec)
            if peer is not None:
                component.add_peer(peer)
        return component

    def activity(self, spec: ActivitySpec) -> Activity:
        schedule = spec.schedule
        request = SchedulingRequest.of(schedule)
        if schedule.type == "periodic":
            assert schedule.period_ms is not None  # the loader guarantees it
            return PeriodicActivity(spec.name, schedule.period_ms / 1e3, main=schedule.main, scheduling=request,
                                    spin=schedule.spin)
        return TriggeredActivity(spec.name, main=schedule.main, scheduling=request,
                                 min_period=schedule.min_period_ms / 1e3)

    def install_transforms(self, app: Application) -> None:
        """Install the declared ``<transforms>`` structure into ``app.transforms``.

        This runs before any component is added, because ``app.add`` runs ``init()``, where components
        look frames up or load their own URDFs into the graph. Strictness is switched on last: it
        governs what components write, not what the file declares. Whatever the graph refuses (a URDF
        that cannot be found or parsed, an edge that clashes with a URDF joint) is reported at the
        element that asked for it.
        """
        spec = self.spec.transforms
        if spec is None:
            return
        import numpy as np

        from .transforms import AxisEdge

        graph = app.transforms
        if spec.history is not None:
            graph.history = spec.history
        for frame in spec.frames:
            graph.add_frame(frame.name)
        for edge in spec.edges:
            try:
                if edge.kind == "static":
                    graph.add_static(edge.parent, edge.child, np.array(edge.origin))
                elif edge.kind == "dynamic":
                    graph.add_dynamic(edge.parent, edge.child, edge.history)
                elif edge.dh is not None:
                    d, theta, r, alpha = edge.dh  # four numbers: the parser checked
                    graph.add_edge(AxisEdge.from_dh(edge.parent, edge.child, edge.joint, edge.joint_type,
                                                    d, theta, r, alpha, value=edge.value))
                else:
                    graph.add_axis(edge.parent, edge.child, edge.joint, edge.joint_type,
                                   np.array(edge.origin), edge.axis, edge.value)
            except (CocoError, LookupError, ValueError) as error:
                self.fail(f"<{edge.kind}> {edge.name}: {error}", edge)
        # Which element declares each joint name: a value given by name must drive one joint only.
        joints = {edge.joint: f"<axis> {edge.name} at {edge.location}"
                  for edge in spec.edges if edge.kind == "axis"}
        for urdf in spec.urdfs:
            try:
                from .transforms.urdf import load_urdf

                # joint_prefix only when given: the call then also suits a load_urdf without it.
                extra = {"joint_prefix": urdf.joint_prefix} if urdf.joint_prefix else {}
                model = load_urdf(graph, urdf.file, name=urdf.name or None, prefix=urdf.prefix, **extra)
                for joint in model.joint_names:
                    if joint in joints:
                        self.fail(f"<urdf> {urdf.file}: joint {joint!r} of the robot is also declared by "
                                  f"{joints[joint]}; joint names are unique (give the robot a joint_prefix=)",
                                  urdf)
                    else:
                        joints[joint] = f"<urdf> {urdf.file} at {urdf.location}"
                if urdf.attach:
                    graph.add_static(urdf.attach, model.frame(model.root_link), np.array(urdf.origin))
            except (CocoError, LookupError, ValueError, OSError, ImportError) as error:
                self.fail(f"<urdf> {error}", urdf)
        graph.strict = spec.strict

    def from_other_hosts(self, placement: Placement, process: str) -> list[ConnectionSpec]:
        """The connections from another host into ``process`` that have a filter: it runs here, on
        the reader's side (``coco_ros.hosts`` feeds it from the network), so it is made here."""
        own = set(map(id, self.spec.connections))
        return [connection for connection in self.spec.file_connections
                if id(connection) not in own and connection.filter is not None
                and _here(placement, connection.dest) and placement.process_of_ref(connection.dest) == process]

    def to_other_hosts(self, placement: Placement, process: str) -> list[ConnectionSpec]:
        """The connections from ``process`` to another host that route (a Split or a Cull): the
        writer's end decides, here (``coco_ros.hosts`` puts the router before the network)."""
        own = set(map(id, self.spec.connections))
        return [connection for connection in self.spec.file_connections
                if id(connection) not in own and connection.filter is not None
                and connection.filter.type in ROUTERS and _here(placement, connection.src)
                and placement.process_of_ref(connection.src) == process]

    def build(self, process: str = LAUNCHER) -> Application:
        spec, placement = self.spec, self.placement
        if process and process not in placement.processes:
            raise ConfigError(f"no process {process!r} in the application; "
                              f"{did_you_mean(process, placement.processes)}")
        mine = [c for c in spec.components if placement.process_of(c.name) == process]
        app = Application(spec.name or Path(spec.file).stem, on_error=ErrorPolicy(spec.on_error) if spec.on_error else None)
        app.process = process
        app.elsewhere = {name: owner for name, owner in placement.of_component.items() if owner != process}
        app.elsewhere.update(spec.other_hosts)
        self.errors.extend(placement.problems(spec))
        self.install_transforms(app)  # every process's graph starts from the declared structure
        components = [c for c in map(self.instantiate, mine) if c is not None]
        self.check()
        by_name = {c.name: s for c, s in zip(components, mine)}
        for component in components:
            try:
                app.add(component)
            except Exception as error:
                self.fail(f"component {component.name}: init() failed: {error!r}", by_name.get(component.name),
                          component.name)
        self.check()
        for activity_spec in spec.activities:
            owner = placement.of_activity[activity_spec.name]
            if owner != process and process != LAUNCHER:
                continue  # a child knows only its own activities
            try:
                activity = app.add_activity(self.activity(activity_spec))
                activity.process = owner
                if owner != process:
                    continue  # the launcher's stand-in of a child's activity runs no component here
                for name in activity_spec.components:
                    if name not in self.missing:
                        activity.add(app.component(name))
            except (CocoError, ValueError, KeyError) as error:
                self.fail(error, activity_spec)
        merges: dict[str, MergeGroup] = {}
        """The Merge of each input port that has one (its connections in file order)."""
        splits = split_places(spec.file_connections or spec.connections)
        remote = self.from_other_hosts(placement, process)
        onward = self.to_other_hosts(placement, process)
        for connection_spec in [*spec.connections, *remote, *onward]:
            crosses = placement.crosses(connection_spec) or connection_spec in remote or connection_spec in onward
            incoming = crosses and connection_spec not in onward and placement.process_of_ref(connection_spec.dest) == process
            outgoing = crosses and not incoming and placement.process_of_ref(connection_spec.src) == process
            # A Split or Cull leaving this process is decided on the writer's side: made here for the
            # writer's end of the channel (the reader's process makes its own, for its side).
            routes_out = outgoing and connection_spec.filter is not None and connection_spec.filter.type in ROUTERS
            if (crosses and not incoming and not routes_out) or (
                    not crosses and placement.process_of_ref(connection_spec.src) != process):
                continue  # another process's, or a shared-memory channel made by the process level
            if incoming and connection_spec.filter is None:
                continue  # a plain channel: the process level makes its reader's end
            if {ref.component for ref in (connection_spec.src, connection_spec.dest) if not ref.activity} & self.missing:
                continue
            try:
                policy = ConnectionPolicy(connection_spec.data, connection_spec.policy, max(1, connection_spec.buffersize))
                group = _merge_group(merges, connection_spec)
                made = _filter(connection_spec.filter, policy, group, splits.get(id(connection_spec), (0, 1)))
                if routes_out:
                    assert isinstance(made, Router)
                    app.outgoing_routers[f"{connection_spec.src}->{connection_spec.dest}"] = made
                    continue
                if incoming:  # its filter on the reader's side, in its place in a merge (file order)
                    assert made is not None
                    app.incoming_filters[f"{connection_spec.src}->{connection_spec.dest}"] = made
                    into = _resolved(app, connection_spec.dest)
                    if isinstance(made, Merge) and isinstance(into, InputPort):
                        _check_merged(into)
                    continue
                connection = app.connect(_port(app, connection_spec.src), _port(app, connection_spec.dest), policy,
                                         event=connection_spec.wakes(), connection=made,
                                         stamps_only=connection_spec.stamps_only)
                if isinstance(connection, Merge) and isinstance(connection.sink, InputPort):
                    _check_merged(connection.sink)
                if connection_spec.shared and isinstance(connection.source, OutputPort):
                    connection.source.share(connection)
            except (CocoError, ValueError, KeyError) as error:
                self.fail(error, connection_spec, self.inside(connection_spec))
        self.check()
        locations = dict(zip(map(id, app.connections), spec.connections))
        for subject, problem in app.problems():
            self.fail(problem, locations.get(id(subject)))
        self.check()
        return app


def _port(app: Application, ref: PortRef) -> str | Port:
    """The port ``ref`` names: ``component.port``, or an activity's ``beginit``/``endit``."""
    return port_of(app.activity(ref.component), ref.port) if ref.activity else str(ref)


def _resolved(app: Application, ref: PortRef) -> Port:
    """The port ``ref`` names, found (a crossing connection's end in this process, for its checks)."""
    return port_of(app.activity(ref.component), ref.port) if ref.activity else app.component(ref.component).port(ref.port)


def _here(placement: Placement, ref: PortRef) -> bool:
    """Whether the component or activity ``ref`` names is in this host's part."""
    return ref.component in (placement.of_activity if ref.activity else placement.of_component)


ROUTERS = (Split.name, Cull.name)
"""The filters that decide on the writer's side between processes and hosts."""


def split_places(connections: list[ConnectionSpec]) -> dict[int, tuple[int, int]]:
    """(index, count) of each connection with a Split among the Split connections of its output
    port, in file order, by the connection's ``id``: every process computes the same from the
    whole application, so a split's outputs agree wherever their readers run."""
    groups: dict[str, list[ConnectionSpec]] = {}
    for connection in connections:
        if connection.filter is not None and connection.filter.type == Split.name:
            groups.setdefault(str(connection.src), []).append(connection)
    return {id(connection): (index, len(group))
            for group in groups.values() for index, connection in enumerate(group)}


def _merge_group(merges: dict[str, MergeGroup], connection: ConnectionSpec) -> MergeGroup | None:
    """The group of the Merge or Gather ``connection`` is an input of (one per input port, made by
    its first connection; ``merges`` holds them), None for another filter; a port's connections
    cannot mix the two (each is one tree of what is read)."""
    kind = connection.filter.type if connection.filter is not None else ""
    if kind not in (Merge.name, Gather.name):
        return None
    group = merges.setdefault(str(connection.dest), GatherGroup() if kind == Gather.name else MergeGroup())
    if isinstance(group, GatherGroup) != (kind == Gather.name):
        raise WiringError(f"{connection.dest} already reads a {'Gather' if isinstance(group, GatherGroup) else 'Merge'}"
                          f" of its other connections: every connection into it takes the same filter")
    return group


def _filter(spec: FilterSpec | None, policy: ConnectionPolicy, merge: MergeGroup | None,
            split: tuple[int, int] = (0, 1)) -> Filter | None:
    """The filter ``spec`` describes, with ``policy``'s buffer size (a Merge joins ``merge``, its
    input port's; a Split is output ``split[0]`` of ``split[1]``); None without one."""
    if spec is None:
        return None
    if spec.type == PreSignal.name:
        return PreSignal(policy, spec.tokens)
    if spec.type == MaxFrequency.name:
        return MaxFrequency(policy, spec.hz)
    if spec.type == Merge.name:
        assert merge is not None  # the caller gives the port's group
        return Merge(policy, merge)
    if spec.type == Gather.name:
        assert isinstance(merge, GatherGroup)  # the caller gives the port's group
        return Gather(policy, merge)
    if spec.type == Split.name:
        return Split(policy, *split, by=spec.by)
    if spec.type == Cull.name:
        return Cull(policy, spec.region, spec.stamp, spec.frustum)
    return FILTERS[spec.type](policy)


def _check_merged(port: InputPort) -> None:
    """A Merge gives its reader tuples: the input port must take them; an activity's beginit
    already waits for a message on each of its connections."""
    if isinstance(port.owner, IterationPorts):
        raise WiringError(f"{port.qualified_name} waits for a message on each of its connections already: "
                          "connect them without a Merge")
    if not types_compatible(tuple, port.type):
        raise WiringError(f"a Merge gives {port.qualified_name} a tuple of its connections' values, and that "
                          f"port takes {type_name(port.type)}; merge into a port of type tuple or object")


def build_application(spec: AppSpec, process: str = LAUNCHER, allow_unknown: bool = False,
                      placement: Placement | None = None) -> Application:
    """Instantiate, configure and wire ``spec``; raise :class:`ConfigErrors` listing every problem.

    With ``<process>`` elements, only the part of ``process`` (the launcher's: ``""``) is built: its
    components, its activities and the connections inside it. The launcher's application also holds a
    stand-in (no components) of every child's activity, for a driver to reach it by name; the
    connections between processes are left to :mod:`coco_core.processes`.

    ``allow_unknown`` leaves out the components whose task no installed package provides, with a
    warning in ``spec.warnings`` each, so that the structure of an application can be checked
    without its components (the original CoCo's files name C++ components); such an application
    is for ``--check`` only, not for running.

    ``placement``: the deployment plan's (:attr:`coco_core.deployment.HostDeployment.placement`),
    which every launch passes; an application built outside a launch (a test, a script) has its own
    worked out here.
    """
    return _Builder(spec, placement if placement is not None else Placement.of(spec), allow_unknown).build(process)


def configure_logging(spec: LogSpec | None, default_level: int = logging.INFO) -> None:
    """Map CoCo's ``<log>`` switches onto Python logging: ``types`` with ``debug`` enables debug
    output, ``outfile`` adds a log file next to the console."""
    level = logging.DEBUG if spec is not None and "debug" in spec.types else default_level
    logging.getLogger("coco").setLevel(level)
    if spec is not None and spec.outfile:
        try:
            handler = logging.FileHandler(spec.outfile)
        except OSError as error:  # the loader checked it; what changed since is said as clearly
            raise FileWriteError(f"cannot open the log file (<outfile>) {spec.outfile}: {error.strerror}") from None
        handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
        logging.getLogger("coco").addHandler(handler)
