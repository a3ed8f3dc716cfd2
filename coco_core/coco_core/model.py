"""The application model: what an application file describes, before anything is instantiated.

The XML loader (``coco_core.xml``) produces an :class:`AppSpec`; the builder turns it into a running
:class:`~coco_core.application.Application`. Keeping the two apart lets a file be checked (and its
errors reported with file:line) without importing any component, and lets tools read applications.
Every spec keeps the :class:`~coco_core.errors.Location` of the element it came from.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .errors import Location
from .policy import BufferPolicy, SyncPolicy


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
    """``<src task="..." port="..."/>`` or ``<dest .../>``: a port of a component instance."""

    component: str
    port: str
    location: Location | None = None

    def __str__(self) -> str:
        return f"{self.component}.{self.port}"


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
    priority: int | None = None
    nice: int | None = None
    affinity: list[int] = field(default_factory=list)
    exclusive_affinity: list[int] = field(default_factory=list)
    location: Location | None = None


@dataclass
class ActivitySpec:
    """An activity: a thread that runs its components, in order, periodically or when triggered."""

    name: str
    schedule: ScheduleSpec
    components: list[str] = field(default_factory=list)
    location: Location | None = None


@dataclass
class LogSpec:
    """``<log>`` / ``<logconfig>``: CoCo's logging switches, mapped onto Python logging."""

    levels: list[int] = field(default_factory=list)
    types: list[str] = field(default_factory=list)
    outfile: str = ""
    location: Location | None = None


@dataclass
class AppSpec:
    """A whole application after includes, substitutions and conditions were applied."""

    name: str = ""
    file: str = ""
    components: list[ComponentSpec] = field(default_factory=list)
    """Top-level components in file order (peers are inside their owners)."""
    connections: list[ConnectionSpec] = field(default_factory=list)
    activities: list[ActivitySpec] = field(default_factory=list)
    paths: list[str] = field(default_factory=list)
    """Resource search paths (``<paths>``, ``<resourcespaths>``), absolute, in file order."""
    args: dict[str, str] = field(default_factory=dict)
    """Final values of the ``<arg>`` declarations."""
    on_error: str = "continue"
    log: LogSpec | None = None

    def all_components(self) -> list[ComponentSpec]:
        """Every component, peers included, depth first."""
        found: list[ComponentSpec] = []
        stack = list(reversed(self.components))
        while stack:
            spec = stack.pop()
            found.append(spec)
            stack.extend(reversed(spec.peers))
        return found
