"""The messages between the hosts of one application, beside the process level's own.

Hosts exchange the typed messages every link of a launch carries (:mod:`coco_core.messages`: an
operation :class:`~coco_core.messages.Call`, its :class:`~coco_core.messages.Result`, a
:class:`~coco_core.messages.Damage` report) and these: each host's :class:`Heartbeat`, several times a second, which carries its stage of the
launch (every stage is a barrier: no host configures before every host is built, none runs before
every host is configured), its stop and why; and the clock exchange that puts every host on the
first host's clock (:mod:`coco_core.hosts.clock`). A heartbeat says the whole state, not a change, so
that a message lost or sent before the other host listened changes nothing: the next one says it
again.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from ..messages import Message, Request
from ..wire import value_type


@value_type
class Stage(enum.IntEnum):
    """How far a host is in the launch; the stages are ordered."""

    JOINED = 0
    """Its launcher runs and listens: it can answer the clock exchange."""
    BUILT = 1
    """Its part is built, its child processes too."""
    CONFIGURED = 2
    """Every activity of its part is configured."""
    RUNNING = 3
    STOPPING = 4
    """It stops: :attr:`Heartbeat.reason` says why; every other host stops too."""


@value_type
@dataclass(frozen=True)
class Heartbeat(Message):
    """A host's state, sent several times a second (:data:`coco_core.hosts.session.BEAT`)."""

    stage: Stage
    reason: str = ""
    """Why it stops (:attr:`Stage.STOPPING`)."""
    hard: bool = True
    """Whether its stop is hard (a signal, a fault) rather than natural (its work is done)."""
    failed: bool = False
    """It stops because something failed (a component's error policy, damaged input, a lost host)."""


@value_type
@dataclass(frozen=True)
class ClockRequest(Request):
    """What time is it on the first host's clock: answered with (receive time, send time) there."""

    sent: float = 0.0
