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
:class:`StopRequest` (a child's component stopped the application), ``Damage`` (damaged input
found somewhere, passed on to every process), :class:`SetPeriod`, :class:`Pause` (a managed
node's deactivate and activate), and the two requests,
:class:`~coco_core.messages.Call` (an operation of a component in another process) and
:class:`ProfileRequest`, each answered by a :class:`~coco_core.messages.Result` with the request's
``id``. The call, its result and the damage report are the messages every link of a launch carries,
between hosts too: they live in :mod:`coco_core.messages`, beside neither level.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from ..messages import Message, Request

if TYPE_CHECKING:
    from ..deployment import HostDeployment
    from ..levels import HostEnds
    from ..report import ProfileSnapshot
    from .channels import ChannelPlan


# --- launcher -> child ------------------------------------------------------------------------
@dataclass(frozen=True)
class HostConfig:
    """What every child of a launch host needs beyond the plan: nothing for the plain host; another
    launch host sends a frozen subclass with its own typed fields (the ROS launcher: the node's
    name, the ROS arguments)."""


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
    hosts: HostEnds | None = None
    """How the child attaches its ends of the connections between hosts, when the application has
    several (the host level's, which the launch gives the process level); None otherwise."""
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
