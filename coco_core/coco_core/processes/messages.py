"""The control protocol between the launcher and its child processes, as typed messages.

Each message is a small frozen dataclass sent over a :class:`~coco_core.processes.control.ControlLink`
(pickled by :mod:`multiprocessing.connection`'s framing); one dispatcher (``ControlLink.serve``) runs
the handler registered for each type, on both sides. A field misspelt or missing is a ``TypeError``
where the message is made, not a ``KeyError`` in another process later, and the protocol is read in
one place: this module.

The life of a launch, in order: the launcher sends :class:`Config`; the child answers
:class:`Built` (or :class:`BuildFailed`); once every child has built, :class:`Start` (configure and
start the activities), the child answers :class:`Configured` when all of its own are; once every
process has, :class:`Run` opens the start gate (:mod:`coco_core.lifecycle`). At the end,
:class:`Stop`, and the child's :class:`Stopped` with its last profile. At any time:
:class:`StopRequest` (a child's component stopped the application), :class:`Damage` (damaged input
found somewhere, passed on to every process), :class:`SetPeriod`, :class:`Pause` (a managed
node's deactivate and activate), and the two requests,
:class:`Call` (an operation of a component in another process) and :class:`ProfileRequest`, each
answered by a :class:`Result` with the request's ``id``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..wire import value_type

if TYPE_CHECKING:
    from ..deployment import HostDeployment
    from ..hosts.clock import ClockOffset
    from ..hosts.key import AppKey
    from ..report import ProfileSnapshot
    from .channels import ChannelPlan


@dataclass(frozen=True)
class Message:
    """Base of every control message."""


@dataclass(frozen=True)
class Request(Message):
    """A message answered by a :class:`Result` carrying its ``id`` (set by ``ControlLink.request``)."""

    id: int = 0


@value_type
@dataclass(frozen=True)
class Outcome:
    """What a request came to: its value, or the exception's type name, text and traceback."""

    ok: bool
    value: Any = None
    type: str = ""
    message: str = ""
    traceback: str = ""

    @classmethod
    def failure(cls, type_name: str, message: str) -> Outcome:
        """The outcome of a request that did not run (the other end is gone, no such process)."""
        return cls(False, type=type_name, message=message)


@value_type
@dataclass(frozen=True)
class Result(Message):
    """The answer to the request with this ``id``."""

    id: int
    outcome: Outcome


# --- launcher -> child ------------------------------------------------------------------------
@dataclass(frozen=True)
class HostConfig:
    """What every child of a launch host needs beyond the plan: nothing for the plain host; another
    launch host sends a frozen subclass with its own typed fields (the ROS launcher: the node's
    name, the ROS arguments)."""


@dataclass(frozen=True)
class HostsLink:
    """What a child of one host of an application over several needs to reach the others."""

    clock: ClockOffset
    """This host's clock against the application's: a child with ends of connections between hosts
    puts its stamps on the application's clock."""
    key: AppKey
    """The application's key (:mod:`coco_core.hosts.key`): the child's ends of connections between
    hosts seal and check their samples with it (this pipe is inside one host: one trust domain)."""
    timeout: float
    """Seconds a child waits for the readers of its connections to other hosts (``--host-timeout``)."""


@dataclass(frozen=True)
class Config(Message):
    """Everything a child needs to build and run its part: sent first, once."""

    process: str
    launch: str
    """The launch's id (its shared-memory segments' names start with it)."""
    wakes: dict[str, int]
    """Activity -> the eventfd that wakes it (inherited descriptors), for the plan's wake sets."""
    plans: list[ChannelPlan]
    """The channels between processes, made from the plan's crossings."""
    deployment: HostDeployment
    """This host's part of the launch's one deployment plan (the file's part included)."""
    log_level: int
    host: HostConfig = field(default_factory=HostConfig)
    """What the child's launch host needs beyond the plan (its own subclass of :class:`HostConfig`)."""
    hosts: HostsLink | None = None
    """The other hosts, when the application has several; None otherwise."""
    measure_ages: bool = False
    """Whether the child's readers record the age of what they take (a profiled launch)."""


@dataclass(frozen=True)
class Start(Message):
    """Every process has built its part: configure and start the activities."""


@dataclass(frozen=True)
class Run(Message):
    """Every activity of every process is configured: the start gate opens."""


@dataclass(frozen=True)
class Pause(Message):
    """Hold every activity's cycles, or let them run again (``Application.pause``)."""

    paused: bool


@dataclass(frozen=True)
class Stop(Message):
    """Stop the application (``hard``: within a second; else let the activities drain)."""

    reason: str
    hard: bool = True


@dataclass(frozen=True)
class SetPeriod(Message):
    activity: str
    period: float


@dataclass(frozen=True)
class ProfileRequest(Request):
    """The child's profile now (answered with a :class:`~coco_core.report.ProfileSnapshot`)."""


# --- child -> launcher ------------------------------------------------------------------------
@dataclass(frozen=True)
class Built(Message):
    """The child built its part and attached its channels."""


@dataclass(frozen=True)
class BuildFailed(Message):
    text: str


@dataclass(frozen=True)
class Configured(Message):
    """Every activity of the child is configured."""


@dataclass(frozen=True)
class StopRequest(Message):
    """A stop that began in the child (a component's error policy) stops the whole application."""

    reason: str
    hard: bool = True


@dataclass(frozen=True)
class Stopped(Message):
    """The child's application stopped: how, and its last profile."""

    clean: bool
    failed: bool
    snapshot: ProfileSnapshot


# --- both ways --------------------------------------------------------------------------------
@value_type
@dataclass(frozen=True)
class Damage(Message):
    """Damaged input found by one process, for every process's summary and exit status."""

    what: str


@value_type
@dataclass(frozen=True)
class Call(Request):
    """An operation of ``component`` in ``process`` (a child asks the launcher, which runs it or
    passes it on; the launcher asks the child that runs the component)."""

    process: str = ""
    component: str = ""
    operation: str = ""
    args: tuple[Any, ...] = ()
    kwargs: dict[str, Any] = field(default_factory=dict)
