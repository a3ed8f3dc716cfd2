"""A filter between two processes: on the reader's side, fed from the shared-memory channel.

A filter (:mod:`coco_core.filters`) is the storage of its connection: the writer's thread pushes,
the reader's pops, and what it does between (tokens, a time grid, the newest only, a merge) is
decided at the reader's request. Between processes it stays on the **reader's side**: the writer's
process writes every message, with its stamp, into an ordinary channel (a BUFFER ring of the
connection's ``buffersize``; a DATA ring for a ``Greedy``, which keeps the newest only anyway), and
the reader's process holds the filter, which takes the channel's messages in the reader's thread
each time it is asked (:meth:`FedFilter.pull`). So a ``PreSignal``'s tokens are put into the cycle
where they are taken, a ``MaxFrequency`` times its messages by the clock of the activity it gates,
a ``Greedy`` gives the newest message that reached the reader's process, and a ``Merge`` joins its
inputs whatever process each comes from: the semantics of one process, with no thread of its own.

A routing filter (``Split``, ``Cull``) is the exception: its decision reads the stamp alone, so the
writer's end makes it (:mod:`coco_core.processes.routed`) and only this reader's messages cross;
the reader's side holds the filter all the same (:class:`FedRouter`), for the profile and for the
messages that cannot be routed.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

from ..connections import EMPTY, Connection
from ..errors import CocoError
from ..filters import Filter, Router

if TYPE_CHECKING:
    from ..profiling import MessageAges


class FedFilter(Connection):
    """The reader's end of a connection with a filter between processes: ``filter`` fed from
    ``channel`` (the reader's end of its ring).

    Counters keep the connections' contract as one connection: ``written`` is what the filter added
    (tokens) plus what the writer offered to the channel, ``read`` what the reader took from the
    filter, ``pending`` what waits in either; a message the ring refused or overwrote, or that the
    filter discarded, is ``dropped``."""

    __slots__ = ("filter", "channel")

    def __init__(self, filter: Filter, channel: Connection) -> None:
        super().__init__(filter.policy)
        self.filter = filter
        self.channel = channel

    def measure_ages(self, ages: MessageAges) -> None:
        """The filter records them too: a Merge's other inputs are taken through their filters."""
        super().measure_ages(ages)
        self.filter.age = ages

    def pull(self) -> None:
        """Move every message waiting in the channel into the filter (the reader's thread only: the
        channel has one reader)."""
        channel, push = self.channel, self.filter.push
        while (item := channel.pop()) is not EMPTY:
            push(item)

    def push(self, value: Any) -> None:
        raise CocoError(f"connection {self.label}: the reader's end cannot be written")

    def pop(self) -> Any:
        self.pull()
        return self.filter.pop()

    def pop_newest(self) -> Any:
        self.pull()
        return self.filter.pop_newest()

    def skip(self, count: int = 1) -> None:
        self.filter.skip(count)

    def ready_at(self) -> float | None:
        self.pull()
        return self.filter.ready_at()

    @property
    def written(self) -> int:
        channel = self.channel
        return self.filter.written + channel.written - channel.read  # the channel's read went into the filter

    @property
    def read(self) -> int:
        return self.filter.read

    @property
    def pending(self) -> int:
        return self.filter.pending + self.channel.pending

    @property
    def writer_finished(self) -> bool:
        """Always: a filter's reader does not wait for its writer at a natural stop. Filters close
        cycles between activities (a PreSignal from the consumer's ``endit`` to the producer's
        ``beginit``), where each would wait for the other."""
        return True

    @property
    def label(self) -> str:
        return self.channel.label

    @property
    def stamps_only(self) -> bool:
        return self.channel.stamps_only

    def settings(self) -> str:
        return self.filter.settings()

    def __repr__(self) -> str:
        return f"<{self.describe()} {self.label} (from another process)>"


class RoutedCount(Protocol):
    """What carries the count of messages a writer's end routed away: a ring's reader end (its
    header word), a DDS reader's end (every sample carries the writer's count)."""

    @property
    def routed_away(self) -> int: ...


class FedRouter(FedFilter):
    """The reader's end of a connection with a routing filter (``Split``, ``Cull``) from another
    process or host: the writer's end already routed (:class:`~coco_core.processes.routed.RoutingEnd`),
    so the channel brings this reader's messages only, and those that cannot be routed, which
    ``filter`` counts as written and dropped, as in one process (its own decision agrees with the
    writer's: both read the same stamp).

    The messages routed away are counted where they were routed, and ``count`` carries that count
    (a ring's reader end: its header word, :attr:`coco_core.shm.ShmReader.routed_away`; a DDS
    reader's end: the count in the writer's samples): the policy column shows it as in one process
    (``Split(out0 of 2, in turn), routed away 50``)."""

    __slots__ = ("_count",)

    filter: Router

    def __init__(self, filter: Router, channel: Connection, count: RoutedCount) -> None:
        super().__init__(filter, channel)
        self._count = count

    @property
    def routed_away(self) -> int:
        """Messages routed to the other connections before they crossed."""
        return self.filter.routed_away + self._count.routed_away

    def settings(self) -> str:
        return f"{self.filter.routes()}, routed away {self.routed_away}"
