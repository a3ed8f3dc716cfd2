"""``<composite>``: a sub-application in a file of its own, instantiated under a scoped name.

FlowVR builds its large applications (hundreds of modules) from composite components: a reusable
network with parameters and exposed ports, instantiated several times with different parameters
(two copies of one 3D modelling pipeline, one per camera). Here a composite is an application file
(a ``<package>``) whose ``<arg>`` declarations are its parameters and whose ``<ports>`` section names
the inner ports it exposes; ``<composite name="cam1" file="rgbd_mesh.xml">`` in a ``<components>``
section instantiates it:

    <components>
        <composite name="cam1" file="composites/rgbd_mesh.xml">
            <arg name="camera" value="left"/>
        </composite>
    </components>
    <connections>
        <connection><src task="cam1" port="mesh"/><dest task="display" port="mesh"/></connection>
    </connections>

The composite's file is read as an included file is, with an argument scope of its own (it sees
the ``<arg>`` values of its ``<composite>`` element, not the includer's args), into a draft of its
own; then every name it defined is scoped (components and their peers, activities, processes,
pipeline and farm activities, nested instances: ``cam1/mesher``, ``cam1/acquire``) and the draft
joins the application's. An outer connection names an exposed port through the instance
(``task="cam1" port="mesh"``); :func:`resolve_exposed` replaces it by the inner port it stands for
once the whole application is read. Every error found inside the composite's file keeps that file's
line and says which instance, instantiated where, it belongs to (:func:`within`), so two instances
with different arguments report their own problems.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Collection, Mapping

from ..errors import ConfigError, Location, did_you_mean
from ..iteration import BEGIN, END, PORTS
from ..model import ComponentSpec, CompositeSpec, PortRef
from .draft import Draft
from .reader import CONDITIONS, FileReader
from .tree import Element

COMPOSITE_ATTRIBUTES = ("file", "name", *CONDITIONS)
INSTANCE_ARG_ATTRIBUTES = ("name", "value", *CONDITIONS)
PORT_ATTRIBUTES = ("activity", "name", "port", "task")
SEPARATOR = "/"
"""Between an instance's name and the names inside it (``cam1/mesher``), as in FlowVR's
hierarchical ids and ROS names, so that a scoped component's operations are ROS services under the
instance's namespace (``~/cam1/mesher/export_ply``)."""


@dataclasses.dataclass
class Instance:
    """A ``<composite>`` element as read: its name, the file it names, the values it gives."""

    name: str
    file: str
    args: dict[str, str]
    arg_locations: dict[str, Location]
    """Where each value is given, for an arg the composite does not declare."""
    location: Location


def read_instance(reader: FileReader, element: Element) -> Instance | None:
    """A ``<composite name= file=>`` whose conditions held, with its ``<arg name= value=/>``
    children (expanded in the instantiating file, with its args); None without a usable name or
    file (the error is recorded)."""
    values = reader.attributes(element, COMPOSITE_ATTRIBUTES, required=("file", "name"))
    args: dict[str, str] = {}
    locations: dict[str, Location] = {}
    for child in reader.children(element, ("arg",)):
        if not reader.kept(child):
            continue
        arg_values = reader.attributes(child, INSTANCE_ARG_ATTRIBUTES, required=("name",))
        reader.empty(child)
        arg = arg_values.get("name", "").strip()
        if not arg:
            continue
        if arg in locations:
            reader.error(f"<composite> gives arg {arg!r} twice (the first is at line {locations[arg].line})", child)
            continue
        locations[arg] = child.location
        args[arg] = arg_values.get("value", "")
    name, file = values.get("name", "").strip(), values.get("file", "").strip()
    if SEPARATOR in name:
        reader.error(f'<composite> attribute name="{name}": an instance name cannot contain "{SEPARATOR}", '
                     f"which separates it from the names inside it ({name.replace(SEPARATOR, '_')}{SEPARATOR}...)",
                     element)
        return None
    if not name or not file:
        return None
    return Instance(name, file, args, locations, element.location)


def read_ports(reader: FileReader, element: Element, draft: Draft) -> None:
    """``<ports>`` of a composite file: ``<port name="mesh" task="mesher" port="mesh"/>`` exposes a
    component's port, ``<port name="done" activity="meshing" port="endit"/>`` an activity's."""
    for child in reader.container(element, ("port",)):
        values = reader.attributes(child, PORT_ATTRIBUTES, required=("name", "port"))
        reader.empty(child)
        name, port = values.get("name", "").strip(), values.get("port", "").strip()
        if ("task" in child.attributes) == ("activity" in child.attributes):
            reader.error("<port> needs either task= (a component's port) or activity= (an activity's "
                         f"{' or '.join(PORTS)}), not both", child)
            continue
        activity = "activity" in child.attributes
        if activity and port not in PORTS:
            reader.error(f'<port activity=...> port="{port}": an activity\'s ports are {" and ".join(PORTS)}', child)
            continue
        if not name or not port:
            continue
        if name in draft.ports:
            first = draft.ports[name].location
            reader.error(f"exposed port {name!r} is declared twice (the first is at {first})", child)
            continue
        target = values.get("activity" if activity else "task", "").strip()
        draft.ports[name] = PortRef(target, port, child.location, activity=activity)


def unknown_args(instance: Instance, declared: Collection[str], used: Collection[str]) -> list[ConfigError]:
    """An error at each ``<arg>`` of the ``<composite>`` that its file neither declares nor reads."""
    return [
        ConfigError(f"composite {instance.file} declares no arg {name!r}; {did_you_mean(name, declared)}",
                    instance.arg_locations[name])
        for name in instance.args
        if name not in declared and name not in used
    ]


def within(errors: list[ConfigError], spec: CompositeSpec) -> list[ConfigError]:
    """``errors`` found while reading an instance's file, each saying which instance it belongs to
    and where that instance is made; the location stays the inner file's line."""
    return [ConfigError(f"{error.message}{_context(spec)}", error.location) for error in errors]


def _context(spec: CompositeSpec) -> str:
    return f" (in composite instance {spec.name!r} of {spec.file}, instantiated at {spec.location})"


def context_of(name: str, composites: Mapping[str, CompositeSpec]) -> str:
    """The instances a scoped name belongs to, innermost first, for an error about it ("" for a
    name of the application itself)."""
    parts = name.split(SEPARATOR)[:-1]
    scopes = [SEPARATOR.join(parts[:count]) for count in range(len(parts), 0, -1)]
    return "".join(_context(composites[scope]) for scope in scopes if scope in composites)


def scope_of(name: str, composites: Mapping[str, CompositeSpec]) -> str:
    """The innermost instance ``name`` belongs to, with the separator (``cam1/``); "" for none."""
    parts = name.split(SEPARATOR)[:-1]
    for count in range(len(parts), 0, -1):
        if SEPARATOR.join(parts[:count]) in composites:
            return SEPARATOR.join(parts[:count]) + SEPARATOR
    return ""


def scope(draft: Draft, prefix: str) -> None:
    """Put every name ``draft`` defines or refers to under ``prefix`` (``cam1/``), in place.

    The draft is a composite's, read on its own: every name in it is its own (a reference to a
    name it does not define is then reported as unknown inside the instance), and its farms are
    already expanded.
    """
    def scoped(ref: PortRef) -> PortRef:
        return dataclasses.replace(ref, component=prefix + ref.component)

    pending = list(draft.components)
    while pending:
        component = pending.pop()
        component.name = prefix + component.name
        pending.extend(component.peers)
    for connection in draft.connections:
        connection.src, connection.dest = scoped(connection.src), scoped(connection.dest)
    for activity in draft.activities:
        activity.name = prefix + activity.name
        activity.components = [prefix + name for name in activity.components]
        activity.process = prefix + activity.process if activity.process else ""
    for process in draft.processes:
        process.name = prefix + process.name
    for scheduled in draft.scheduled:
        scheduled.component, scheduled.activity = prefix + scheduled.component, prefix + scheduled.activity
    draft.pipeline_inputs = [scoped(ref) for ref in draft.pipeline_inputs]
    draft.ports = {name: scoped(ref) for name, ref in draft.ports.items()}
    for composite in draft.composites:
        composite.name = prefix + composite.name
        composite.ports = {name: scoped(ref) for name, ref in composite.ports.items()}
        composite.components = [prefix + name for name in composite.components]
        composite.activities = [prefix + name for name in composite.activities]


def join(outer: Draft, inner: Draft, spec: CompositeSpec) -> None:
    """Add an instance's scoped ``inner`` draft to ``outer``: the instance first, then its parts.
    Paths, the log and the ``<transforms>`` declaration were shared during the reading (frames are
    one graph for the whole application, as for an included file)."""
    spec.ports = dict(inner.ports)
    spec.components = [component.name for component in inner.components]
    spec.activities = [activity.name for activity in inner.activities]
    outer.composites += [spec, *inner.composites]
    outer.components += inner.components
    outer.connections += inner.connections
    outer.activities += inner.activities
    outer.processes += inner.processes
    outer.scheduled += inner.scheduled
    outer.file_attributes += inner.file_attributes
    outer.pipeline_inputs += inner.pipeline_inputs
    outer.transforms, outer.log = inner.transforms, inner.log


def resolve_exposed(
    draft: Draft, components: Mapping[str, ComponentSpec], errors: list[ConfigError]
) -> None:
    """Check the instances and their exposed ports, and make every connection that names an
    exposed port (``task="cam1" port="mesh"``) name the inner port instead, through nested
    instances; ``components`` are every component name (peers included).

    A connection whose exposed port cannot be resolved is left out of ``draft`` once its error is
    recorded, so that it is not reported a second time as an unknown component.
    """
    composites = {spec.name: spec for spec in draft.composites}  # unique: the loader refuses a second
    for spec in draft.composites:
        if spec.name in components:
            errors.append(ConfigError(f"composite instance name {spec.name!r} is already used by the component at "
                                      f"{components[spec.name].location}; instance and component names must be "
                                      "unique", spec.location))
    activities = {activity.name for activity in draft.activities}
    names = {*components, *composites}
    broken: set[tuple[str, str]] = set()
    """Exposed ports whose own target is wrong: reported at their ``<port>``, not at each use."""

    def follow(ref: PortRef, tag: str, context: str) -> PortRef | None:
        """The inner port ``ref`` stands for; None (the error recorded) when there is none."""
        while not ref.activity and ref.component in composites:
            instance = composites[ref.component]
            target = instance.ports.get(ref.port)
            if (ref.component, ref.port) in broken:
                return None
            if target is None:
                errors.append(ConfigError(
                    f'<{tag} task="{ref.component}" port="{ref.port}">: composite instance {ref.component!r} '
                    f"({instance.file}) exposes no port {ref.port!r}; {did_you_mean(ref.port, instance.ports)}"
                    f"{context}", ref.location))
                return None
            ref = dataclasses.replace(target, location=ref.location)
        if tag != "port" and ref.activity and ref.port != (END if tag == "src" else BEGIN):
            errors.append(ConfigError(
                f"<{tag}> names activity {ref.component!r}'s {ref.port} port (an exposed port), but a connection "
                f"{'starts at' if tag == 'src' else 'ends at'} an activity's {END if tag == 'src' else BEGIN}"
                f"{context}", ref.location))
            return None
        return ref

    owners: list[CompositeSpec | None] = [*composites.values(), None]  # None: the file's own <ports>
    for owner in owners:
        ports = owner.ports if owner is not None else draft.ports
        context = _context(owner) + context_of(owner.name, composites) if owner is not None else ""
        for name, target in ports.items():
            known = activities if target.activity else names
            if target.component not in known:
                what = "an activity" if target.activity else "a component"
                valid = [other for other in known if scope_of(other, composites) == scope_of(target.component, composites)]
                errors.append(ConfigError(
                    f"exposed port {name!r} names {target.component!r}, which is not {what} of the composite; "
                    f"{did_you_mean(target.component, valid)}{context}", target.location))
                broken.add((owner.name if owner is not None else "", name))
            elif follow(target, "port", context) is None:
                broken.add((owner.name if owner is not None else "", name))
    kept = []
    for connection in draft.connections:
        src = follow(connection.src, "src", context_of(connection.src.component, composites))
        dest = follow(connection.dest, "dest", context_of(connection.dest.component, composites))
        if src is not None and dest is not None:
            connection.src, connection.dest = src, dest
            kept.append(connection)
    draft.connections = kept
