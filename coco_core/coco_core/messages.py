"""The messages that every link between two parts of a launch carries, whatever the level.

A launcher and its child processes (:mod:`coco_core.processes.messages` adds their control
messages) and the hosts of one application (:mod:`coco_core.hosts.messages` adds heartbeats and the
clock exchange) ask each other for the same things: an operation of a component that the other
side runs (:class:`Call`, answered by a :class:`Result` that carries its :class:`Outcome`), and a
word that damaged input was found (:class:`Damage`), for every part's summary and exit status. They
live here, beside neither level, so that each level reads the other's calls and damage reports
without importing the other (:mod:`coco_core.levels`); the value types cross between hosts in the
typed encoding of :mod:`coco_core.wire`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from .wire import value_type


@dataclass(frozen=True)
class Message:
    """Base of every message between two parts of a launch (processes or hosts)."""


@dataclass(frozen=True)
class Request(Message):
    """A message answered by a :class:`Result` carrying its ``id`` (set by whoever sends it)."""

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


@value_type
@dataclass(frozen=True)
class Damage(Message):
    """Damaged input found by one process, for every process's summary and exit status."""

    what: str


@value_type
@dataclass(frozen=True)
class Call(Request):
    """An operation of ``component`` in ``process`` (a child asks the launcher, which runs it or
    passes it on; the launcher asks the child that runs the component; a host asks the host of an
    address ``process@host``)."""

    process: str = ""
    component: str = ""
    operation: str = ""
    args: tuple[Any, ...] = ()
    kwargs: dict[str, Any] = field(default_factory=dict)
