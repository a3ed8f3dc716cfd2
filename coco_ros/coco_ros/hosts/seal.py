"""The seal (:mod:`coco_core.hosts.auth`) on the messages between hosts: ``coco_interfaces/Sample``
and ``HostMessage`` both carry it in the fields ``sender``, ``session``, ``counter``, ``wall`` and
``mac``, so the writers set them and the readers read them in one place."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any, TypeVar

from coco_core.hosts.auth import Seal, Sealer

M = TypeVar("M")


def sealed(message: M, sealer: Sealer, parts: Iterable[Any]) -> M:
    """``message`` with the seal of its ``parts`` (what the MAC covers besides the topic and the
    seal's own fields) in its fields; the message itself."""
    seal = sealer.seal(parts)
    target: Any = message
    target.sender, target.session, target.counter, target.wall, target.mac = (seal.host, seal.session, seal.counter,
                                                                              seal.wall, seal.mac)
    return message


def seal_of(message: Any) -> Seal:
    """The seal a received message claims (its fields, checked by a
    :class:`~coco_core.hosts.auth.Verifier`)."""
    return Seal(message.sender, message.session, message.counter, message.wall, message.mac)
