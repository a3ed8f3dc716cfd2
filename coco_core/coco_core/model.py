"""The application model: what an application file describes, before anything is instantiated.

The XML loader (``coco_core.xml``) produces an :class:`AppSpec`; the builder turns it into a running
:class:`~coco_core.application.Application`. Keeping the two apart lets a file be checked (and its
errors reported with file:line) without importing any component, and lets tools read applications.
Every spec keeps the :class:`~coco_core.errors.Location` of the element it came from.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .errors import Location
from .frustum import Frustum
from .hosts.channel import HostChannel
from .policy import BufferPolicy, SyncPolicy
from .schedule import DEFAULT_SPIN


@dataclass
class AttributeSpec:
    """``<attribute name="..." value="..." type="..."/>``: the value stays text until the component's
    declared attribute type parses it. ``type="file"`` resolves the value against the file's paths."""

    name: str
    value: str
    type: str = ""
    location: Location | None = None


@dataclass
class ComponentSpec:
    """One component instance; ``peers`` are the nested ``<components>`` run by this one."""

    name: str
    task: str
    library: str = ""
    attributes: list[AttributeSpec] = field(default_factory=list)
    peers: list["ComponentSpec"] = field(default_factory=list)
    on_error: str = ""
    """Empty: the application's policy; else one of continue / stop_component / stop_app."""
    location: Location | None = None


@dataclass
class PortRef:
    """``<src task="..." port="..."/>`` or ``<dest .../>``: a port of a component instance, or with
    ``activity="..."`` the ``beginit``/``endit`` port of an activity (:mod:`coco_core.iteration`)."""

    component: str
    """The component's instance name, or the activity's name when :attr:`activity`."""
    port: str
    location: Location | None = None
    activity: bool = False

    def __str__(self) -> str:
        return f"{self.component}.{self.port}"


@dataclass
class FilterSpec:
    """``<filter type="..." .../>`` of a connection: the FlowVR filter that is its storage
    (:mod:`coco_core.filters`)."""

    type: str
    tokens: int = 1
    """PreSignal: the messages it starts with."""
    hz: float = 0.0
    """MaxFrequency: the most messages it forwards per second."""
    by: str = ""
    """Split: the user stamp that chooses the output (a whole number); empty: in turn."""
    region: tuple[float, ...] = ()
    """Cull: the receiver's region, its minimum corner then its maximum (2k numbers); empty with a
    :attr:`frustum`."""
    frustum: Frustum | None = None
    """Cull: the receiver's view frustum (from its camera's attributes or its view-projection
    matrix), instead of a box region."""
    stamp: str = "bbox"
    """Cull: the user stamp holding each message's bounding box."""
    location: Location | None = None


@dataclass
class ConnectionSpec:
    """``<connection data=... policy=... transport=... buffersize=...>``."""

    src: PortRef
    dest: PortRef
    data: BufferPolicy = BufferPolicy.DATA
    policy: SyncPolicy = SyncPolicy.LOCKED
    transport: str = "LOCAL"
    buffersize: int = 1
    event: bool | None = None
    """Whether a write wakes the destination's triggered activity; None: the input port decides."""
    location: Location | None = None
    shared: bool = False
    """The source hands each value to one of its shared connections instead of all of them (a
    ``<farm>``'s source feeding its workers)."""
    filter: FilterSpec | None = None
    """The filter on the connection's path; None: the policy's plain storage."""
    stamps_only: bool = False
    """``stamps_only="true"``: the connection carries each message's stamp, not its payload
    (FlowVR's dashed connections); its reader reads :class:`~coco_core.stamps.Stamp` values."""
    codec: str = "plain"
    """How the payload crosses the network when the two ends are on two hosts
    (:data:`coco_core.hosts.channel.CODECS`)."""

    def wakes(self) -> bool | None:
        """Whether a write wakes the reader, wherever the two ends run: a ``Greedy`` connection does
        not unless :attr:`event` says so (its reader runs at its own rate and takes the newest when it
        runs), the others as :attr:`event` says; None: the input port decides."""
        if self.event is None and self.filter is not None and self.filter.type == "Greedy":
            return False
        return self.event


@dataclass
class ScheduleSpec:
    """``<schedule>`` (``<schedulepolicy>`` in the per-activity layout) of one activity."""

    type: str = "triggered"
    """``periodic`` or ``triggered``."""
    period_ms: float | None = None
    """From ``period`` or ``value``, in milliseconds; required for periodic activities."""
    activity: str = "parallel"
    """``parallel`` (own thread) or ``sequential`` (kept for compatibility; runs as parallel)."""
    main: bool = False
    """Run this activity in the launcher's main thread (needed by e.g. some GUI toolkits)."""
    realtime: str = "none"
    """``none``, ``FIFO`` or ``RR`` (scheduling class), ``DEADLINE`` is not available from Python."""
    spin_ms: float | None = None
    """Periodic: milliseconds before each deadline at which the thread stops sleeping and spins
    (:attr:`Schedule.spin <coco_core.schedule.Schedule.spin>`); None: the runtime's default."""
    min_period_ms: float = 0.0
    """Triggered: milliseconds from the start of one cycle to the start of the next, at least
    (:attr:`Schedule.min_period <coco_core.schedule.Schedule.min_period>`); 0: no bound."""
    priority: int | None = None
    nice: int | None = None
    affinity: list[int] = field(default_factory=list)
    exclusive_affinity: list[int] = field(default_factory=list)
    location: Location | None = None

    @property
    def spin(self) -> float:
        """Seconds of :attr:`spin_ms`, the runtime's default when the file gives none: what the
        builder gives the activity and what the deployment plan prints."""
        return DEFAULT_SPIN if self.spin_ms is None else self.spin_ms / 1e3


@dataclass
class ActivitySpec:
    """An activity: a thread that runs its components, in order, periodically or when triggered."""

    name: str
    schedule: ScheduleSpec
    components: list[str] = field(default_factory=list)
    location: Location | None = None
    process: str = ""
    """The ``<process>`` that runs it; empty: the launcher's own process."""
    host: str = ""
    """The ``<host>`` that runs it (the first host when the file declares hosts and the activity is in
    none); empty: the file declares no host."""


@dataclass
class ProcessSpec:
    """``<process>``: a child process of the launcher running the activities declared inside it."""

    name: str
    affinity: list[int] = field(default_factory=list)
    """Cores the whole process may run on; empty: any."""
    nice: int | None = None
    """Nice value of the whole process (-20..19)."""
    lock_memory: bool = False
    """Whether the process locks its memory in RAM (mlockall): no page fault in a real-time loop."""
    gc: str = "auto"
    """``auto`` (CPython's collector as usual) or ``between_cycles`` (see :mod:`coco_core.garbage`)."""
    location: Location | None = None
    host: str = ""
    """The ``<host>`` the process runs on; empty: the file declares no host."""


@dataclass
class HostSpec:
    """``<host>``: one machine of the application; every host runs the same file with ``--host NAME``
    (:mod:`coco_core.hosts`)."""

    name: str
    location: Location | None = None


@dataclass
class LogSpec:
    """``<log>`` / ``<logconfig>``: CoCo's logging switches, mapped onto Python logging."""

    levels: list[int] = field(default_factory=list)
    types: list[str] = field(default_factory=list)
    outfile: str = ""
    location: Location | None = None


def _identity() -> list[list[float]]:
    return [[1.0 if row == column else 0.0 for column in range(4)] for row in range(4)]


@dataclass
class FrameSpec:
    """``<frame name="..."/>`` in ``<transforms>``: a frame that exists even if no edge names it."""

    name: str
    location: Location | None = None


@dataclass
class EdgeSpec:
    """A declared edge of the transformation graph: ``<static>``, ``<dynamic>`` or ``<axis>``.

    ``origin`` is ``T_parent_child`` of a static edge, or the fixed origin of an axis edge, as a 4x4
    homogeneous matrix in nested lists (the loader computes it from ``xyz``/``rpy``/``quaternion``),
    so that the model stays plain data.
    """

    kind: str
    """``static``, ``dynamic`` or ``axis`` (the values of :class:`~coco_core.transforms.EdgeKind`)."""
    parent: str
    child: str
    origin: list[list[float]] = field(default_factory=_identity)
    joint: str = ""
    """Axis edges: the joint name that drives the edge (``set_joint``, JointState names)."""
    joint_type: str = ""
    """Axis edges: ``revolute``, ``continuous`` or ``prismatic``."""
    axis: tuple[float, ...] = (0.0, 0.0, 1.0)
    """Axis edges: the joint axis in the child frame (not normalised; the graph normalises it)."""
    value: float = 0.0
    """Axis edges: the initial joint value (radians or metres)."""
    dh: tuple[float, ...] | None = None
    """Axis edges given by classic Denavit-Hartenberg parameters ``(d, theta, r, alpha)`` instead of
    ``origin`` and ``axis``."""
    history: int | None = None
    """Dynamic edges: how many samples the edge keeps; None: the section's (or the graph's) default."""
    location: Location | None = None

    @property
    def name(self) -> str:
        return f"{self.parent}->{self.child}"


@dataclass
class UrdfSpec:
    """``<urdf file=...>``: a robot whose joints join the graph, optionally attached to a frame."""

    file: str
    """An absolute path (the loader resolves relative ones) or a ``package://``/``file://`` URL."""
    name: str = ""
    """The model's name in the graph; empty: ``prefix`` + the robot's name."""
    prefix: str = ""
    """Prepended to the URDF's link names to make frame names."""
    joint_prefix: str = ""
    """Prepended to the URDF's joint names (two copies of one robot in a graph)."""
    attach: str = ""
    """A frame the URDF's root link is joined to by a static edge; empty: not attached."""
    origin: list[list[float]] = field(default_factory=_identity)
    """``T_attach_root`` of that static edge."""
    location: Location | None = None


@dataclass
class TransformsSpec:
    """``<transforms>``: the declared structure of the application's transformation graph.

    Present only when a file declares it; the sections of every file (includes too) are merged.
    """

    strict: bool = True
    """Writing an edge that is not declared is an error (instead of creating a dynamic edge)."""
    history: int | None = None
    """Capacity of dynamic edges that do not give their own; None: the graph's default."""
    frames: list[FrameSpec] = field(default_factory=list)
    edges: list[EdgeSpec] = field(default_factory=list)
    urdfs: list[UrdfSpec] = field(default_factory=list)
    location: Location | None = None
    """The first ``<transforms>`` element read."""


@dataclass
class CompositeSpec:
    """``<composite name=... file=...>``: one instance of a composite component, a sub-application
    in a file of its own (FlowVR's composite). Its components, activities and processes are in the
    application's lists under scoped names (``cam1/mesher``); this records the instance itself, for
    ``--check``'s tree and for the outer connections that name its exposed ports."""

    name: str
    """The scoped instance name (``cam1``, ``cam1/left`` for an instance inside another)."""
    file: str
    """The composite's file, absolute."""
    args: dict[str, str] = field(default_factory=dict)
    """The final values of the composite's ``<arg>`` declarations for this instance."""
    ports: dict[str, PortRef] = field(default_factory=dict)
    """Each exposed port (``<ports><port name=...>``) and the scoped inner port it stands for."""
    components: list[str] = field(default_factory=list)
    """The scoped names of the instance's own top-level components (not those of nested instances)."""
    activities: list[str] = field(default_factory=list)
    """The scoped names of the instance's own activities."""
    location: Location | None = None
    """The instantiating ``<composite>`` element."""


@dataclass(frozen=True)
class ArgDeclaration:
    """One ``<arg>`` as declared: what the ROS launcher declares as a node parameter of the same name."""

    name: str
    value: str
    """Its final value (given, a parameter, ``value=`` or ``default=``)."""
    choices: tuple[str, ...] = ()
    doc: str = ""
    fixed: bool = False
    """Declared with ``value=``: nothing from outside changes it."""
    location: Location | None = None
    min: float | None = None
    """``min=``: the least value it takes (a number), the low end of its ROS parameter's range."""
    max: float | None = None
    """``max=``: the greatest value it takes, the high end of its ROS parameter's range."""


@dataclass(frozen=True)
class TopicMirrorSpec:
    """One ``<topic>``: an output port mirrored on a ROS topic by the ROS launcher (``coco_ros.mirror``);
    ``coco-launch`` has no node and leaves it alone."""

    component: str
    port: str
    topic: str = ""
    """The topic's name; empty: ``~/<component>/<port>`` (under the launcher's node)."""
    type: str = ""
    """The ROS message type (``std_msgs/msg/ColorRGBA``); empty: chosen from the port's values."""
    data: BufferPolicy = BufferPolicy.DATA
    """The mirror connection's policy, which the topic's QoS follows."""
    buffersize: int = 1
    location: Location | None = None
    frame: str = ""
    """The ``header.frame_id`` of values that carry no frame (a device's position, a force)."""
    hz: float = 0.0
    """Publish the newest value at most this often (a 1 kHz loop seen by a viewer); 0: every value."""


@dataclass
class AppSpec:
    """A whole application after includes, substitutions and conditions were applied."""

    name: str = ""
    file: str = ""
    components: list[ComponentSpec] = field(default_factory=list)
    """Top-level components in file order (peers are inside their owners)."""
    connections: list[ConnectionSpec] = field(default_factory=list)
    activities: list[ActivitySpec] = field(default_factory=list)
    processes: list[ProcessSpec] = field(default_factory=list)
    """Child processes declared by ``<process>``; activities name theirs in ``ActivitySpec.process``."""
    hosts: list[HostSpec] = field(default_factory=list)
    """The machines declared by ``<host>``, in file order (the first is the application's clock and
    runs what no host names); empty: one machine."""
    part_of: str = ""
    """The host this is the part of (:func:`coco_core.hosts.part.host_part`: its own activities,
    processes, components and connections, :attr:`hosts` still all of them); empty: the whole
    application."""
    between_hosts: list[HostChannel] = field(default_factory=list)
    """In one host's part: the connections between it and another host, in file order."""
    file_connections: list[ConnectionSpec] = field(default_factory=list)
    """In one host's part, whose :attr:`connections` are its own: every connection of the file, in file order, those between hosts included (a Split's
    outputs are numbered among all of them; a filter on a connection from another host runs on
    this one); empty otherwise."""
    other_hosts: dict[str, str] = field(default_factory=dict)
    """In one host's part: every component of another host -> its address (``process@host``), so
    that its operations are called by name as across processes."""
    paths: list[str] = field(default_factory=list)
    """Resource search paths (``<paths>``, ``<resourcespaths>``), absolute, in file order."""
    args: dict[str, str] = field(default_factory=dict)
    """Final values of the ``<arg>`` declarations."""
    arg_declarations: dict[str, ArgDeclaration] = field(default_factory=dict)
    """The ``<arg>`` declarations by name, in file order (given but undeclared args are not here)."""
    on_error: str = ""
    """The ``<package>``'s ``on_error``; empty when the file gives none (:class:`~coco_core.application.Application`
    then continues after a component's error but stops when a component refuses its configuration)."""
    log: LogSpec | None = None
    transforms: TransformsSpec | None = None
    """The declared transformation graph structure; None when no file has ``<transforms>``."""
    composites: list[CompositeSpec] = field(default_factory=list)
    """Every composite instance, outer ones before the instances inside them, in document order."""
    warnings: list[str] = field(default_factory=list)
    """``file:line: message`` for what was accepted but ignored (settings the original CoCo
    ignores, components left unchecked); the launchers print them."""
    topics: list[TopicMirrorSpec] = field(default_factory=list)
    """The ports the file mirrors on ROS topics (``<topics>``), in document order."""

    def all_components(self) -> list[ComponentSpec]:
        """Every component, peers included, depth first."""
        found: list[ComponentSpec] = []
        stack = list(reversed(self.components))
        while stack:
            spec = stack.pop()
            found.append(spec)
            stack.extend(reversed(spec.peers))
        return found
