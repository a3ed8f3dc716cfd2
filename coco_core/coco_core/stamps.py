"""Message stamps (FlowVR's term): where and when a piece of data was born.

A stamp travels with data through every port, so latency can be measured end to end, from the
acquisition of a sample to whatever output it produced, whatever components and threads it crossed.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

from .errors import WrongTypeError

T = TypeVar("T")


class UserStamps(Mapping[str, Any]):
    """FlowVR's user stamps of one message: small named values, read-only (a message is shared by
    its readers), picklable (they cross to other processes with the message)."""

    __slots__ = ("_stamps",)

    def __init__(self, stamps: Mapping[str, Any] | None = None) -> None:
        self._stamps = dict(stamps or {})

    def __getitem__(self, name: str) -> Any:
        return self._stamps[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._stamps)

    def __len__(self) -> int:
        return len(self._stamps)

    def __hash__(self) -> int:  # a Stamp (frozen) hashes its fields; values that cannot be hashed say so then
        return hash(tuple(self._stamps.items()))

    def __reduce__(self) -> tuple[type[UserStamps], tuple[dict[str, Any]]]:
        return UserStamps, (self._stamps,)

    def __repr__(self) -> str:
        return f"UserStamps({self._stamps!r})"


NO_USER_STAMPS = UserStamps()
"""The user stamps of a message that has none (shared: read-only)."""


def user_stamps(stamps: Mapping[str, Any] | None) -> UserStamps:
    """A copy of the user stamps a writer gave (so that changing its dict later changes no message
    already written); their names must be non-empty strings, as FlowVR's stamp names are."""
    if not stamps:
        return NO_USER_STAMPS
    if not isinstance(stamps, Mapping):
        raise WrongTypeError(f"user stamps are a mapping of names to small values, got {type(stamps).__name__}")
    for name in stamps:
        if not isinstance(name, str) or not name:
            raise WrongTypeError(f"a user stamp's name is a non-empty string, got {name!r}")
    return UserStamps(stamps)


@dataclass(frozen=True, slots=True)
class Stamp:
    """Acquisition time (``time.perf_counter`` seconds in this process), sequence number and source.

    The stamp of a *message* (what an output port made of a write, :class:`Message`) has FlowVR's
    fields: ``seq`` is the message's number on its port (FlowVR's ``num``), ``source`` the writing
    port (``component.port``) and ``it`` the iteration of the writing activity (FlowVR's ``it``), so
    that a filter or a reader can route, sample and check messages without reading their payload."""

    time: float
    seq: int = 0
    source: str = ""
    steps: tuple[tuple[str, float], ...] = ()
    """Named times (``perf_counter`` seconds) the data passed on its way from the acquisition, in
    order, appended by the stages that choose to (FlowVR's stamps carry such fields too): a latency
    from the acquisition to an output is then split step by step where it was spent (the remote
    palpation app: sent, received, meshed, built, frame start, drawn, read back)."""
    it: int = -1
    """The iteration (cycle number, from 0) of the activity whose component wrote the message; -1:
    not written through a port, or by a component no activity runs."""
    user: UserStamps = field(default_factory=lambda: NO_USER_STAMPS)
    """FlowVR's user stamps: small named values the writing component attached to the message
    (``out.write(value, stamps={"bbox": (...)})``), e.g. a bounding box that a ``Cull`` filter routes
    by, read without the payload. Read-only; empty when the writer gave none."""

    @classmethod
    def now(cls, seq: int = 0, source: str = "") -> Stamp:
        return cls(time.perf_counter(), seq, source)

    def age(self) -> float:
        """Seconds since acquisition."""
        return time.perf_counter() - self.time

    def step(self, name: str, at: float | None = None) -> Stamp:
        """This stamp with the step ``name`` passed at ``at`` (default: now) appended to ``steps``."""
        return Stamp(self.time, self.seq, self.source, (*self.steps, (name, time.perf_counter() if at is None else at)),
                     self.it, self.user)

    def intervals(self) -> list[tuple[str, float]]:
        """Seconds from each step's predecessor (the acquisition for the first) to it, by step name."""
        times = [self.time, *(at for _, at in self.steps)]
        return [(name, times[index + 1] - times[index]) for index, (name, _) in enumerate(self.steps)]


@dataclass(frozen=True, slots=True)
class Stamped(Generic[T]):
    """A value with its stamp, the usual payload of a port that carries measurements."""

    value: T
    stamp: Stamp = field(default_factory=Stamp.now)


def unstamped(value: T | Stamped[T]) -> tuple[T, Stamp | None]:
    """``(value, stamp)`` of a :class:`Stamped` value, ``(value, None)`` of a plain one.

    Lets an input take both, so a producer can start stamping its values (for end-to-end latency)
    without breaking the consumers that were written for plain ones."""
    if isinstance(value, Stamped):
        return value.value, value.stamp
    return value, None


@dataclass(frozen=True, slots=True)
class UserStamped:
    """A payload and its message's user stamps, as they cross to another process inside one pickle
    (:meth:`Message.crossing`); never seen by a component."""

    value: object
    user: UserStamps


Record = tuple[Any, ...]
"""A port's write as it travels inside one process, before anyone asks for its stamp: the
arguments of its :class:`Message`, ``(value, time, seq, source, it, user)``, in one tuple, which is
made in a fraction of a message's time (:meth:`OutputPort.write <coco_core.ports.OutputPort.write>`,
:meth:`Connection.put <coco_core.connections.Connection.put>`); ``Message(*record)`` is the message.
A write without user stamps leaves ``user`` out (the message's default): one field less at most
writes.
A message pushed whole becomes its record again (:func:`record_of`), anything else ``(item,)``:
the first field of a record is always the value a reader gets."""


def item_of(record: Record) -> Any:
    """What ``record`` stands for: the message of a port's write, or the item pushed as ``(item,)``."""
    return record[0] if len(record) == 1 else Message(*record)


def record_of(item: Any) -> Record:
    """The record of what a connection gives (:func:`item_of` undone): a message's fields, or
    ``(item,)`` for anything else (a bare value, a pooled frame)."""
    if type(item) is Message:
        return item.value, item.time, item.seq, item.source, item.it, item.user
    return (item,)


class Message:
    """A value as it travels on a connection inside one process: the payload and the fields of the
    stamp the writing port gave it. The port wraps and the reading port unwraps, so components see
    the plain value (a :class:`Stamped` one included, unchanged) and the stamp is read beside it
    (:attr:`InputPort.stamp <coco_core.ports.InputPort.stamp>`), or alone by a filter.

    The :class:`Stamp` object is made only when asked for (:attr:`stamp`), and the message itself
    only for whoever reads it as one (a filter, a channel to another process, the reader of a
    stamp): a connection of one process carries the write's :data:`Record`, since most messages are
    read without their stamp."""

    __slots__ = ("value", "time", "seq", "source", "it", "user")

    def __init__(self, value: object, time: float, seq: int, source: str, it: int,
                 user: UserStamps = NO_USER_STAMPS) -> None:
        self.value = value
        self.time = time
        """When it was written (``perf_counter`` seconds)."""
        self.seq = seq
        self.source = source
        self.it = it
        self.user = user
        """The user stamps the writer attached (read-only, :func:`user_stamps`)."""

    @property
    def stamp(self) -> Stamp:
        """The message's stamp: the acquisition time and steps of a :class:`Stamped` value, or of a
        :class:`Stamp` value (a stamps-only connection's message, :meth:`stamps_only`), else the time
        of the write."""
        value = self.value
        if isinstance(value, Stamped):
            return Stamp(value.stamp.time, self.seq, self.source, value.stamp.steps, self.it, self.user)
        if type(value) is Stamp:
            return Stamp(value.time, self.seq, self.source, value.steps, self.it, self.user)
        return Stamp(self.time, self.seq, self.source, (), self.it, self.user)

    def stamps_only(self) -> Message:
        """This message without its payload, for a stamps-only connection (FlowVR's dashed ones):
        its value is its :class:`Stamp`, which its reader reads (and the same stamp beside it)."""
        return Message(self.stamp, self.time, self.seq, self.source, self.it, self.user)

    def crossing(self) -> object:
        """What a channel to another process pickles as the payload: the value, or, when the
        message has user stamps, the value and its user stamps together (:class:`UserStamped`),
        so that they travel in the slot's payload and the ring's fixed stamp words stay as they are."""
        return self.value if not self.user else UserStamped(self.value, self.user)

    @staticmethod
    def crossed(payload: object, time: float, seq: int, source: str, it: int) -> Message:
        """The message a channel's reader makes of a payload that :meth:`crossing` gave."""
        if type(payload) is UserStamped:
            return Message(payload.value, time, seq, source, it, payload.user)
        return Message(payload, time, seq, source, it)

    def __repr__(self) -> str:
        user = f" {dict(self.user)}" if self.user else ""
        return f"<Message it={self.it} seq={self.seq} from {self.source}{user}>"
