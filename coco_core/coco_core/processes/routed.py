"""Routing on the writer's side: a Split or Cull to another process or host decides before the channel.

A routing filter (:class:`~coco_core.filters.Router`: ``Split``, ``Cull``) decides from a message's
stamp alone whether the message is for its connection's reader. Inside one process that decision is
the connection's ``push``, in the writer's thread. Between processes and hosts the other filters stay
on the reader's side (:mod:`coco_core.processes.filtered`), where what they decide depends on the
reader (its clock, its requests); a router's decision does not, so it is made where the message is
written: the writer's end of the channel (:class:`RoutingEnd`) asks the connection's router, and a
message routed away never enters the channel (no pickle, no ring slot, no DDS sample), which saves
one copy per reader that was not to get it. The reader's side still holds the filter (fed from the
channel, :class:`~coco_core.processes.filtered.FedRouter`): it names it in the profile, and counts
as dropped a message that cannot be routed (a stamp missing or malformed), which the writer's end
lets through for that, as one process does.
"""

from __future__ import annotations

from typing import Any, Callable

from ..connections import Connection
from ..errors import CocoError
from ..filters import Router


class RoutingEnd(Connection):
    """The writer's end of a connection with a routing filter to another process or host: ``end``
    (the channel's writer: a ring's or a DDS topic's) behind ``router`` (the connection's Split or
    Cull, made by the writer's builder, :attr:`Application.outgoing_routers
    <coco_core.application.Application.outgoing_routers>`).

    A message the router keeps goes into ``end``; one it routes away is counted in the router's
    :attr:`~coco_core.filters.Router.routed_away` and told to ``routed`` (a ring keeps the count in
    its header, for the reader's process: :meth:`coco_core.shm.ShmWriter.route_away`); one it cannot
    route goes into ``end`` too, for the reader's filter to count as written and dropped. The
    counters are ``end``'s: what was offered to the channel."""

    __slots__ = ("router", "end", "_routed")
    carries_stamps = True

    def __init__(self, router: Router, end: Connection, routed: Callable[[], None]) -> None:
        super().__init__(end.policy)
        self.router = router
        self.end = end
        self._routed = routed

    def push(self, value: Any) -> None:
        if self.router.keeps(value) is False:
            self.router.routed_away += 1
            self._routed()
            return
        self.end.push(value)

    def pop(self) -> Any:
        raise CocoError(f"connection {self.label}: the writer's end cannot be read")

    def skip(self, count: int = 1) -> None:
        raise CocoError(f"connection {self.label}: the writer's end cannot be read")

    def writer_done(self) -> None:
        self.end.writer_done()

    @property
    def written(self) -> int:
        return self.end.written

    @property
    def read(self) -> int:
        return self.end.read

    @property
    def pending(self) -> int:
        return self.end.pending

    @property
    def label(self) -> str:
        return self.end.label

    def describe(self) -> str:
        return f"{self.router.describe()}, {self.end.describe()}"

    def __repr__(self) -> str:
        return f"<{self.describe()} {self.label} (routed on the writer's side)>"
