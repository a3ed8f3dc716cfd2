"""Connections: the storage between one output port and one input port.

A port with several peers has several connections (many-to-many is a set of one-to-one channels, as in
OROCOS), so every connection has exactly one writer thread and one reader thread. That is what makes
the LOCK_FREE variants sound under CPython: the writer only ever appends / swaps a reference and the
reader only ever pops / reads it, and each of those is a single atomic bytecode-level operation.

The hot path is kept to a handful of bytecodes: each combination of buffering and sync policy is its
own small class instead of one class with branches, and the dropped-item counter is derived
(``written - read - pending``) rather than maintained, so neither side pays for it. A port's write
reaches these classes as its *record* (:meth:`Connection.put`: the value and its stamp's fields in
one tuple), which they store as it is: the :class:`~coco_core.stamps.Message` (and the
:class:`~coco_core.stamps.Stamp`) is made only for whoever asks for it, most reads asking for neither.

The LOCKED classes hold a :mod:`~coco_core.mutex` (one token in a ``SimpleQueue``, a third cheaper
to take and give back than a ``threading.Lock``), taken as the first thing in a ``try`` whose
``finally`` gives it back rather than in a ``with`` block: no ``__enter__``/``__exit__`` to look
up and call at each access, and an exception raised after the taking (a signal's, between two
bytecodes) still gives it back. Only an exception raised by ``get`` itself while it waits for the
other side would give back a token not taken; Python raises there only from a signal handler, and
CoCo's handlers only record (:mod:`coco_core.signals`).
"""

from __future__ import annotations

import abc
import logging
import sys
from collections import deque
from typing import TYPE_CHECKING, Any, Callable, ClassVar, Protocol

from .errors import PolicyError
from .mutex import TOKEN, mutex
from .policy import BufferPolicy, ConnectionPolicy, SyncPolicy
from .stamps import Message, Record, item_of, record_of

if TYPE_CHECKING:
    from .profiling import MessageAges

log = logging.getLogger("coco")


class End(Protocol):
    """What a connection knows of the port at one of its ends (an input or output port of
    :mod:`coco_core.ports`, which sets it): its name. A protocol, not the port classes, so that this
    module stays out of the ports' import circle; code that needs the port itself narrows it."""

    @property
    def qualified_name(self) -> str: ...


class SourceEnd(End, Protocol):
    """The output port a connection starts at: it also says whether the connection carries the
    messages' stamps only."""

    def carries_stamps_only(self, connection: Connection) -> bool: ...


class _Empty:
    """Sentinel returned by :meth:`Connection.pop` when nothing new is there (None is a valid value)."""

    __slots__ = ()

    def __repr__(self) -> str:
        return "EMPTY"


EMPTY: Any = _Empty()


class Connection(abc.ABC):
    """One channel from ``source`` to ``sink`` with a :class:`ConnectionPolicy`: the contract every
    connection keeps, in one process (:class:`CountedConnection` and its policies) or between
    processes (:mod:`coco_core.shm`, whose counters live in shared memory).

    Counting contract (every connection class keeps it, because the profile's ``dropped`` column is
    the only place a lost sample shows):

    - ``written``: values offered by the writer (``push``), whether stored or not;
    - ``read``: values the reader took *and used* (``pop``, minus those given back to :meth:`skip`);
    - ``pending``: values stored and not taken yet;
    - ``dropped`` = ``written - read - pending``: everything else, i.e. values the policy discarded
      (DATA overwrote, a full BUFFER refused, CIRCULAR pushed out as oldest) **and** values the
      reader took but discarded unused (:meth:`pop_newest`, or :meth:`skip` after a ``pop``): a read
      that keeps only the newest of several waiting items drops the others.

    The writer only ever touches ``written``, the reader only ``read``, so neither needs the other's
    lock to count. ``trigger`` is called after a value was stored when the sink is an event port, to
    wake the sink's triggered activity.
    """

    __slots__ = ("source", "sink", "policy", "trigger", "age", "reader", "__weakref__")

    carries_stamps: ClassVar[bool] = False
    """Whether the writing port hands this connection :class:`~coco_core.stamps.Message` objects
    (payload and stamp) instead of bare values: the value connections inside one process do, and
    the writer's end of a shared-memory channel to another process (which writes the stamp beside
    the value, :mod:`coco_core.shm.channel`); a pooled output hands over the slot, its stamp in
    :attr:`Slot.message <coco_core.pool.Slot.message>`."""

    def __init__(self, policy: ConnectionPolicy) -> None:
        self.policy = policy
        self.source: SourceEnd | None = None
        self.sink: End | None = None
        self.trigger: Callable[[], None] | None = None
        self.age: MessageAges | None = None
        """The age of each message the reader takes, in a profiled run (None: not measured)."""
        self.reader: str | None = None
        """What reads a connection that has no input port (a ROS topic's mirror), for its label."""

    @abc.abstractmethod
    def push(self, value: Any) -> None:
        """Store ``value`` for the reader; never blocks."""

    @abc.abstractmethod
    def pop(self) -> Any:
        """Take the next value, or :data:`EMPTY` when there is nothing new; never blocks."""

    def put(self, record: Record) -> None:
        """Store a port's write, given as its record (:data:`~coco_core.stamps.Record`): a connection
        that carries stamps gets it as a :class:`~coco_core.stamps.Message`, another the bare value.
        The connections of one process (:class:`PolicyConnection`) store the record itself."""
        self.push(Message(*record) if self.carries_stamps else record[0])

    def take(self) -> Any:
        """What an input port reads: the next item as a record (:func:`~coco_core.stamps.record_of`
        what :meth:`pop` gives: a message's fields, else ``(item,)``), :data:`EMPTY` when there is
        nothing new. A :class:`PolicyConnection` gives the record of a port's write as :meth:`put`
        stored it, whose message nobody made (the port makes it if its reader asks for the stamp)."""
        item = self.pop()
        return EMPTY if item is EMPTY else record_of(item)

    @property
    @abc.abstractmethod
    def written(self) -> int:
        """Values offered by the writer (see the counting contract)."""

    @property
    @abc.abstractmethod
    def read(self) -> int:
        """Values the reader took and used (see the counting contract)."""

    @property
    @abc.abstractmethod
    def pending(self) -> int:
        """Values written and not yet taken by the reader."""

    @abc.abstractmethod
    def skip(self, count: int = 1) -> None:
        """Count ``count`` values the reader took with ``pop`` but discarded unused as dropped.

        Called by the reader's thread only (as ``pop``), so ``read`` still has a single writer."""

    def pop_newest(self) -> Any:
        """Take every value waiting and return the newest (:data:`EMPTY` when none); the older ones
        are skipped, so they count as dropped, not read (the one place a reader's skip is counted)."""
        newest = self.pop()
        if newest is EMPTY:
            return EMPTY
        while (value := self.pop()) is not EMPTY:
            self.skip()
            newest = value
        return newest

    def ready_at(self) -> float | None:
        """When the next value may be taken (``time.perf_counter`` seconds; 0: now), or None when
        there is none: what an activity's ``beginit`` waits for (:mod:`coco_core.iteration`). A
        filter may hold a value back until later (:class:`~coco_core.filters.MaxFrequency`)."""
        return 0.0 if self.pending else None

    def writer_done(self) -> None:
        """The writer's activity finished: nothing more will come. A reader in the same process
        knows it from the stop order (:meth:`Application.stop_order`); only a channel to another
        process has to carry it (:class:`coco_core.shm.ShmWriter`)."""

    @property
    def writer_finished(self) -> bool:
        """Whether the writer is known to have finished, as far as the reader must wait for it: a
        writer in the same process always is by the time the stop order reaches its reader."""
        return True

    @property
    def dropped(self) -> int:
        """Values lost on the way: discarded by the policy (overwritten, refused when full, pushed
        out as oldest) or skipped by the reader (see the class docstring)."""
        return self.written - self.read - self.pending

    @property
    def label(self) -> str:
        """``writer.port -> reader.port``, for the profile."""
        source = self.source.qualified_name if self.source else "?"
        sink = self.sink.qualified_name if self.sink else self.reader or "?"
        return f"{source} -> {sink}"

    def measure_ages(self, ages: MessageAges) -> None:
        """Record the age of what the reader takes into ``ages`` (a profiled run)."""
        self.age = ages

    @property
    def stamps_only(self) -> bool:
        """Whether the connection carries its messages' stamps only (FlowVR's dashed connection):
        its writing port says so in the writer's process; a reader's end from another process knows
        it from its channel."""
        source = self.source
        return source is not None and source.carries_stamps_only(self)

    def settings(self) -> str:
        """What stores the values: the policy, or a filter's name and parameters."""
        return str(self.policy)

    def describe(self) -> str:
        """:meth:`settings`, for ``--check`` and the profile; a stamps-only connection says so after
        them, in the writer's process and in the reader's."""
        return f"{self.settings()}, stamps only" if self.stamps_only else self.settings()

    def counters(self) -> dict[str, int]:
        """Snapshot of the flow counters, for the profiler and diagnostics."""
        return {"written": self.written, "read": self.read, "dropped": self.dropped, "pending": self.pending}

    def __repr__(self) -> str:
        source = self.source.qualified_name if self.source else "?"
        sink = self.sink.qualified_name if self.sink else self.reader or "?"
        return f"<Connection {source} -> {sink} {self.policy}>"


class CountedConnection(Connection):
    """A connection whose two counters are plain fields of this process: every connection in one
    process (each side of it is a thread here), and the ends between processes whose counter only
    this process needs."""

    __slots__ = ("written", "read")

    written: int  # fields here, where the contract only asks for values
    read: int

    def __init__(self, policy: ConnectionPolicy) -> None:
        super().__init__(policy)
        self.written = 0
        self.read = 0

    def skip(self, count: int = 1) -> None:
        self.read -= count


class PolicyConnection(CountedConnection):
    """A connection of one process whose storage is its policy's (DATA, BUFFER, CIRCULAR): it keeps
    records, a port's write as it came (:meth:`put`) and what was pushed as its record (a message's
    fields, else ``(item,)``: :func:`~coco_core.stamps.record_of`), and gives them to the input
    port as they are (:meth:`take`); :meth:`pop` makes the message of a record for the other
    readers (a ROS topic's mirror, an activity's ``beginit``)."""

    __slots__ = ()
    carries_stamps = True

    def push(self, value: Any) -> None:
        self.put(record_of(value))

    @abc.abstractmethod
    def put(self, record: Record) -> None:
        """Store ``record`` (see :meth:`Connection.put`), or count it dropped as the policy says."""

    @abc.abstractmethod
    def take(self) -> Any:
        """The next record stored, or :data:`EMPTY`."""

    def pop(self) -> Any:
        record = self.take()
        return EMPTY if record is EMPTY else item_of(record)


class DataConnection(PolicyConnection):
    """DATA, LOCK_FREE / UNSYNC: the latest record, swapped as one reference. The reader tells a new
    one from the one it took by identity: every write is a new record (a port's, or the one
    :meth:`push` makes), and the one taken stays referenced here, so no other record can be made
    at its address."""

    __slots__ = ("_cell", "_seen")

    def __init__(self, policy: ConnectionPolicy) -> None:
        super().__init__(policy)
        self._cell: Record = ()
        self._seen: Record = ()

    def put(self, record: Record) -> None:
        self.written += 1
        self._cell = record
        if self.trigger is not None:
            self.trigger()

    def take(self) -> Any:
        record = self._cell
        if record is self._seen:
            return EMPTY
        self._seen = record
        self.read += 1
        return record

    @property
    def pending(self) -> int:
        return 0 if self._cell is self._seen else 1


class LockedDataConnection(DataConnection):
    """DATA, LOCKED."""

    __slots__ = ("_mutex",)

    def __init__(self, policy: ConnectionPolicy) -> None:
        super().__init__(policy)
        self._mutex = mutex()

    def put(self, record: Record) -> None:
        guard = self._mutex
        try:
            guard.get()
            self.written += 1
            self._cell = record
        finally:
            guard.put_nowait(TOKEN)
        if self.trigger is not None:
            self.trigger()

    def take(self) -> Any:
        guard = self._mutex
        try:
            guard.get()
            record = self._cell
            if record is self._seen:
                return EMPTY
            self._seen = record
            self.read += 1
            return record
        finally:
            guard.put_nowait(TOKEN)


class BufferConnection(PolicyConnection):
    """BUFFER, LOCK_FREE / UNSYNC: bounded FIFO that refuses new data when full.

    Only the reader shrinks the deque, so the writer's length check can only be pessimistic: the buffer
    never exceeds its size even without a lock.
    """

    __slots__ = ("_queue", "_size")

    def __init__(self, policy: ConnectionPolicy) -> None:
        super().__init__(policy)
        self._queue: deque[Record] = deque()
        self._size = policy.size

    def put(self, record: Record) -> None:
        self.written += 1
        if len(self._queue) < self._size:
            self._queue.append(record)
            if self.trigger is not None:
                self.trigger()

    def take(self) -> Any:
        if self._queue:
            self.read += 1
            return self._queue.popleft()
        return EMPTY

    @property
    def pending(self) -> int:
        return len(self._queue)


class LockedBufferConnection(BufferConnection):
    """BUFFER, LOCKED."""

    __slots__ = ("_mutex",)

    def __init__(self, policy: ConnectionPolicy) -> None:
        super().__init__(policy)
        self._mutex = mutex()

    def put(self, record: Record) -> None:
        guard = self._mutex
        try:
            guard.get()
            self.written += 1
            if len(self._queue) >= self._size:
                return
            self._queue.append(record)
        finally:
            guard.put_nowait(TOKEN)
        if self.trigger is not None:
            self.trigger()

    def take(self) -> Any:
        guard = self._mutex
        try:
            guard.get()
            if self._queue:
                self.read += 1
                return self._queue.popleft()
            return EMPTY
        finally:
            guard.put_nowait(TOKEN)


class CircularConnection(PolicyConnection):
    """CIRCULAR, LOCK_FREE / UNSYNC: bounded FIFO whose append pushes the oldest item out atomically."""

    __slots__ = ("_queue",)

    def __init__(self, policy: ConnectionPolicy) -> None:
        super().__init__(policy)
        self._queue: deque[Record] = deque(maxlen=policy.size)

    def put(self, record: Record) -> None:
        self.written += 1
        self._queue.append(record)
        if self.trigger is not None:
            self.trigger()

    def take(self) -> Any:
        if self._queue:
            self.read += 1
            return self._queue.popleft()
        return EMPTY

    @property
    def pending(self) -> int:
        return len(self._queue)


class LockedCircularConnection(CircularConnection):
    """CIRCULAR, LOCKED."""

    __slots__ = ("_mutex",)

    def __init__(self, policy: ConnectionPolicy) -> None:
        super().__init__(policy)
        self._mutex = mutex()

    def put(self, record: Record) -> None:
        guard = self._mutex
        try:
            guard.get()
            self.written += 1
            self._queue.append(record)
        finally:
            guard.put_nowait(TOKEN)
        if self.trigger is not None:
            self.trigger()

    def take(self) -> Any:
        guard = self._mutex
        try:
            guard.get()
            if self._queue:
                self.read += 1
                return self._queue.popleft()
            return EMPTY
        finally:
            guard.put_nowait(TOKEN)


_CLASSES: dict[tuple[BufferPolicy, bool], type[PolicyConnection]] = {
    (BufferPolicy.DATA, False): DataConnection,
    (BufferPolicy.DATA, True): LockedDataConnection,
    (BufferPolicy.BUFFER, False): BufferConnection,
    (BufferPolicy.BUFFER, True): LockedBufferConnection,
    (BufferPolicy.CIRCULAR, False): CircularConnection,
    (BufferPolicy.CIRCULAR, True): LockedCircularConnection,
}


def _gil_enabled() -> bool:
    """False on a free-threaded CPython build (3.13t and later), where LOCK_FREE would be unsound."""
    check = getattr(sys, "_is_gil_enabled", None)
    return True if check is None else bool(check())


GIL = _gil_enabled()


def make_connection(policy: ConnectionPolicy) -> PolicyConnection:
    """The connection class for a copying policy (POOL connections are made by pooled ports).

    Without a GIL, appends and swaps are no longer atomic: LOCK_FREE then falls back to LOCKED.
    """
    locked = policy.sync is SyncPolicy.LOCKED or (policy.sync is SyncPolicy.LOCK_FREE and not GIL)
    if policy.sync is SyncPolicy.LOCK_FREE and not GIL:
        log.warning("this Python runs without a GIL: the LOCK_FREE connection %s uses a lock instead", policy)
    try:
        cls = _CLASSES[(policy.data, locked)]
    except KeyError:
        raise PolicyError(f"{policy.data.value} connections are made by pooled output ports") from None
    return cls(policy)
