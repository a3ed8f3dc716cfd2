"""Typed input and output ports.

Ports are declared on the component class (``image = InputPort(Image, event=True)``); each component
instance gets its own bound copy under the same attribute name. Writing and reading never block:
the connection's policy decides what happens to data the reader has not taken.
"""

from __future__ import annotations

import copy
from time import perf_counter
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Callable

from .connections import EMPTY, Connection
from .errors import PolicyError, PoolError
from .policy import NEW_DATA, NO_DATA, OLD_DATA, ReadStatus
from .pool import DEFAULT_SLOTS, FramePool, LocalFramePool, PoolConnection, PoolReader, Slot, frame_stamp
from .stamps import Message, Record, Stamp, Stamped, item_of, record_of, user_stamps

if TYPE_CHECKING:
    from .activity import Activity
    from .component import Component


def type_name(tp: Any) -> str:
    """Readable name of a port type, for error messages."""
    return getattr(tp, "__qualname__", None) or repr(tp)


class Port:
    """What input and output ports share: a name, a Python type, an owner and connections.

    Ports have slots: a write and a read touch a few of their fields each time, which a slot serves
    faster than an instance dictionary (a bound port is a copy, whose dictionary Python keeps in its
    slowest form)."""

    __slots__ = ("type", "doc", "name", "owner", "connections")

    def __init__(self, type_: Any = object, doc: str = "") -> None:
        self.type = type_
        self.doc = doc
        self.name = ""
        self.owner: Component | None = None
        self.connections: list[Connection] = []

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def bind(self, owner: Component, name: str | None = None) -> Port:
        """A copy of this declaration belonging to one component instance."""
        port = copy.copy(self)
        port.owner = owner
        port.name = name or self.name
        port.connections = []
        return port

    @property
    def qualified_name(self) -> str:
        return f"{self.owner.name if self.owner else '?'}.{self.name}"

    @property
    def connected(self) -> bool:
        return bool(self.connections)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.qualified_name}: {type_name(self.type)}>"


class OutputPort(Port):
    """Sends values to every connected input; a write with no connection is a no-op.

    Connections made *shared* (:meth:`share`) take turns instead: each value goes to one of them.
    That is how a farm's source feeds its workers, each of which then processes different values.

    Every write is stamped (FlowVR's stamp list, :attr:`stamp`): the message's number on this port,
    this port as its source, the iteration of the writing activity, and the acquisition time (a
    :class:`~coco_core.stamps.Stamped` value's own, else the time of the write). The connections
    inside the process carry the stamp beside the value, as the write's
    :data:`~coco_core.stamps.Record` (a tuple: the :class:`~coco_core.stamps.Message` and its
    :class:`~coco_core.stamps.Stamp` are made only for the reader, filter or channel to another
    process that reads them, :meth:`Connection.put <coco_core.connections.Connection.put>`; the
    ages only in a profiled run). A write may attach user stamps
    (``write(value, stamps={"bbox": box})``, FlowVR's user stamps), which travel in the stamp.

    A *stamps-only* connection (FlowVR's dashed ones, :meth:`add_connection`) gets each message
    without its payload: its reader reads the :class:`~coco_core.stamps.Stamp` as the value, and
    between processes the payload does not travel.
    """

    __slots__ = ("_every", "_shared", "_stamps_only", "_route", "_turn", "_written", "_source", "activity", "_last")

    def __init__(self, type_: Any = object, doc: str = "") -> None:
        super().__init__(type_, doc)
        self._every: list[Connection] = []
        """The connections that receive every value."""
        self._shared: list[Connection] = []
        self._stamps_only: list[Connection] = []
        """The connections that receive each message's stamp only."""
        self._route: Connection | None = None
        """The connection a write goes straight to while it is the port's only one (the common case,
        where walking the lists would cost a write a tenth of the bench's floor); None: through
        the lists (:meth:`_plan`)."""
        self._turn = 0
        self._written = 0
        self._source = ""
        """``component.port``, the source of this port's messages (set by :meth:`bind`)."""
        self.activity: Activity | None = None
        """The activity whose cycle number stamps this port's messages: its component's, which the
        component keeps here (:attr:`Component.activity <coco_core.component.Component.activity>`)
        so that a write reads one field instead of asking the component (and its owner) each time."""
        self._last: Record | None = None
        """The record of the last write (:attr:`last` is its message); None before the first."""

    def bind(self, owner: Component, name: str | None = None) -> OutputPort:
        port = super().bind(owner, name)
        assert isinstance(port, OutputPort)
        port._every, port._shared, port._turn, port._written, port._last = [], [], 0, 0, None
        port._stamps_only, port._route = [], None
        port.activity = None  # its component gives it its own (Component._add_port)
        port._source = port.qualified_name
        return port

    def write(self, value: Any, stamps: Mapping[str, Any] | None = None) -> None:
        """Offer ``value`` to every connection, and to one of the shared ones; never blocks.
        ``stamps``: user stamps (small named values, e.g. ``{"bbox": (x0, y0, x1, y1)}``) the
        message carries in its stamp, which readers and filters read without the payload."""
        self._written = seq = self._written + 1  # _record, inlined: a call would cost a tenth of the floor
        activity = self.activity
        record: Record = (value, perf_counter(), seq, self._source, -1 if activity is None else activity.stats.cycles)
        if stamps is not None:
            record += (user_stamps(stamps),)
        self._last = record
        route = self._route
        if route is not None:
            route.put(record)
            return
        for connection in self._every:
            connection.put(record)
        if self._stamps_only:
            self._put_stamps_only(record)
        if self._shared:
            self._hand_over(record)

    def _plan(self) -> None:
        """Let writes go straight to the port's one connection while it is the only one given every
        write (none stamps-only or shared beside it; a muted one is given nothing), else through
        the lists."""
        every = self._every
        alone = len(every) == 1 and not self._stamps_only and not self._shared
        self._route = every[0] if alone else None

    def _record(self, value: Any, stamps: Mapping[str, Any] | None = None) -> Record:
        """The record of a write of ``value`` (kept as the last): the fields of its stamp."""
        self._written = seq = self._written + 1
        activity = self.activity
        record: Record = (value, perf_counter(), seq, self._source, -1 if activity is None else activity.stats.cycles)
        if stamps is not None:
            record += (user_stamps(stamps),)
        self._last = record
        return record

    def _put_stamps_only(self, record: Record) -> None:
        """Give the stamps-only connections the message of ``record`` without its payload."""
        stamp_message = Message(*record).stamps_only()
        for connection in self._stamps_only:
            connection.push(stamp_message if connection.carries_stamps else stamp_message.value)

    @property
    def last(self) -> Message | None:
        """The last message written (made from its record when asked); None before the first."""
        record = self._last
        return None if record is None else Message(*record)

    @property
    def stamp(self) -> Stamp | None:
        """The stamp of the last message written; None before the first."""
        last = self.last
        return None if last is None else last.stamp

    def add_connection(self, connection: Connection, stamps_only: bool = False) -> None:
        """Attach a connection; ``stamps_only``: it gets each message's stamp, not its payload."""
        connection.source = self
        self.connections.append(connection)
        (self._stamps_only if stamps_only else self._every).append(connection)
        self._plan()

    def carries_stamps_only(self, connection: Connection) -> bool:
        """Whether ``connection`` (one of this port's) gets the messages' stamps only."""
        return connection in self._stamps_only

    def mute(self, connection: Connection, muted: bool) -> None:
        """Stop (``muted``) or resume giving ``connection`` (one of this port's, given every message)
        this port's writes. A reader that wants the values only at times (a ROS topic's mirror while
        nobody subscribes, :mod:`coco_ros.mirror`) then costs a write nothing, where an idle
        connection would still cost a push. The list is replaced, never changed in place, and the
        direct route is cleared first (:meth:`_plan`): a write in another thread keeps the route or
        the list it took, and the other connections miss nothing."""
        if connection not in self.connections or connection in self._stamps_only or connection in self._shared:
            raise PolicyError(f"{connection!r} is not a connection of {self.qualified_name} given every message")
        every = [other for other in self._every if other is not connection]
        self._route = None
        self._every = every if muted else [*every, connection]
        self._plan()

    def share(self, connection: Connection) -> None:
        """Let ``connection`` (one of this port's) take turns with the other shared connections."""
        if connection not in self._every:
            raise PolicyError(f"{connection!r} is not a connection of {self.qualified_name}")
        self._every.remove(connection)
        self._shared.append(connection)
        self._plan()

    def _hand_over(self, record: Record) -> None:
        """Give the write of ``record`` to the next shared connection with nothing pending (a worker
        that is free, as the original CoCo's farm prefers), or else to the next in turn, whose
        policy then decides (a full buffer refuses it, which its counters show as a drop)."""
        shared = self._shared
        count = len(shared)
        chosen = shared[self._turn % count]
        for offset in range(count):
            candidate = shared[(self._turn + offset) % count]
            if not candidate.pending:
                chosen = candidate
                break
        self._turn = (shared.index(chosen) + 1) % count
        chosen.put(record)


class PooledOutputPort(OutputPort):
    """An output whose frames live in a :class:`FramePool`: ``acquire`` a slot, fill it, ``write`` it.

    Readers receive the :class:`Slot` itself and must ``release()`` it (or use it as a context
    manager). ``slots`` should be at least 2 + the number of readers that hold a frame at once
    (a stamps-only connection's reader holds none: it reads the frames' stamps).

    Each bound port starts with a :class:`LocalFramePool` of its own; the process level gives it its
    pool in shared memory, when a reader runs in another process, through :meth:`use_pool`, the one
    way a port's pool changes, before any frame went through it.
    """

    __slots__ = ("slots", "_pool")

    def __init__(self, slots: int = DEFAULT_SLOTS, doc: str = "") -> None:
        super().__init__(Slot, doc)
        self.slots = slots
        self._pool: FramePool = LocalFramePool(slots)

    def bind(self, owner: Component, name: str | None = None) -> PooledOutputPort:
        port = super().bind(owner, name)
        assert isinstance(port, PooledOutputPort)
        port._pool = LocalFramePool(self.slots)
        return port

    @property
    def pool(self) -> FramePool:
        """The pool every frame of this port goes through (read-only: see :meth:`use_pool`)."""
        return self._pool

    def use_pool(self, pool: FramePool) -> None:
        """Make ``pool`` this port's pool, for its readers in this process too: the process level's
        pool in shared memory, attached between the building of the application and its start.
        Refused once a frame went through the port (a reader may hold a slot of the old pool), and
        for a pool of another slot count than the port's (the readers in other processes were
        planned from the declaration)."""
        if self._pool.live:
            raise PoolError(f"{self.qualified_name}: its pool is in use (frames published or held); a pooled "
                            "output's pool is chosen before the application starts")
        if pool.count != self.slots:
            raise PoolError(f"{self.qualified_name} has {self.slots} slots, the pool given to it "
                            f"{pool.count}: a pooled output read from another process keeps the slot count "
                            "of its declaration")
        self._pool = pool
        for connection in self.connections:  # the readers in this process, made by connection()
            if isinstance(connection, PoolConnection):
                connection.pool = pool

    def acquire(self, shape: tuple[int, ...], dtype: Any = "uint8") -> Slot | None:
        """A slot to fill in place, or None when every slot is busy (skip this frame)."""
        return self.pool.acquire(shape, dtype)

    def write(self, slot: Slot, stamps: Mapping[str, Any] | None = None) -> None:
        """Publish a filled slot to every reader: the slot is handed over as it is, the stamp of
        this write with it (:attr:`Slot.message <coco_core.pool.Slot.message>`, across processes in
        the pool's shared records), which its readers' :attr:`InputPort.stamp` reads. ``stamps``:
        user stamps, as on a plain output (across processes in the slot's record, small values).
        A frame whose own :attr:`Slot.stamp <coco_core.pool.Slot.stamp>` carries a
        :class:`~coco_core.stamps.Stamp` (:func:`~coco_core.pool.frame_stamp`) is timed from it, as
        a ``Stamped`` value is. A stamps-only connection gets the stamp, never the slot: no reader
        holds a slot for it."""
        record = self._record(frame_stamp(slot.stamp), stamps)
        slot.message = Message(*record)
        self.pool.publish(slot)
        for connection in self._every:
            connection.push(slot)
        if self._stamps_only:
            self._put_stamps_only(record)

    def share(self, connection: Connection) -> None:
        """Refused: a pooled frame is published to every reader of the pool."""
        raise PolicyError(f"{self.qualified_name} is a pooled output: its frames go to every reader and "
                          "cannot be shared out one per connection (a farm's source writes a plain output)")

    def connection(self) -> PoolConnection:
        """A new reader-side connection on this port's pool."""
        return PoolConnection(self.pool)


class InputPort(Port):
    """Receives from any number of connections, read round-robin.

    An *event* input wakes the triggered activity of its component whenever a value arrives.
    """

    __slots__ = ("event", "_next", "_taken", "_keeps_last", "_wake", "_triggering", "_only")

    def __init__(self, type_: Any = object, event: bool = False, doc: str = "") -> None:
        super().__init__(type_, doc)
        self.event = event
        self._next = 0
        self._taken: Record | None = None
        """What the last new value came as: the record its connection gave
        (:meth:`Connection.take <coco_core.connections.Connection.take>`); None before the first.
        Its value is also the last value, which a read without a new one returns as OLD_DATA: one
        field kept by every new read, where a copy of the value beside it would cost each read a
        twentieth of the bench's floor."""
        self._keeps_last = True
        """Whether a read without a new value returns the last one (not from a pool, whose slot
        may be reused once released)."""
        self._wake: Callable[[], None] | None = None
        self._triggering: list[Connection] = []
        """The connections whose writes wake this port's activity."""
        self._only: Connection | None = None
        """The connection while it is the only one (the common case, which :meth:`read` takes
        without counting and indexing the list); None with none or several."""

    def bind(self, owner: Component, name: str | None = None) -> InputPort:
        port = super().bind(owner, name)
        assert isinstance(port, InputPort)
        port._next, port._taken, port._keeps_last, port._wake = 0, None, True, None
        port._triggering = []
        port._only = None
        return port

    def add_connection(self, connection: Connection, event: bool | None = None) -> None:
        """Attach a connection; ``event`` overrides the port's own event flag for this connection."""
        connection.sink = self
        if isinstance(connection, PoolReader):
            # A pooled frame may be reused once released: never hand it out again as OLD_DATA.
            self._keeps_last = False
        if event if event is not None else self.event:
            connection.trigger = self._wake
            self._triggering.append(connection)
        self.connections.append(connection)
        self._only = connection if len(self.connections) == 1 else None

    def set_wake(self, wake: Callable[[], None] | None) -> None:
        """Install the function that wakes this port's activity on its triggering connections."""
        self._wake = wake
        for connection in self._triggering:
            connection.trigger = wake

    @property
    def pending(self) -> int:
        """How many new values wait on this port's connections (a reader that takes the backlog it
        found, and no more, reads this first)."""
        return sum(connection.pending for connection in self.connections)

    @property
    def triggers(self) -> bool:
        """Whether any connection into this port wakes the component's activity."""
        return bool(self._triggering)

    @property
    def triggering(self) -> list[Connection]:
        """The connections into this port whose writes wake the component's activity."""
        return list(self._triggering)

    def read(self) -> tuple[ReadStatus, Any]:
        """``(NEW_DATA, value)``, ``(OLD_DATA, last value)`` or ``(NO_DATA, None)``; never blocks.

        With several connections, reading starts after the connection that delivered last time, so
        every source gets its turn.
        """
        connection = self._only
        if connection is not None:
            record = connection.take()
            if record is not EMPTY:
                if connection.age is not None:
                    connection.age.took(item_of(record))
                self._taken = record
                return NEW_DATA, record[0]
        elif connections := self.connections:
            count = len(connections)
            start = self._next
            for offset in range(count):
                index = (start + offset) % count
                connection = connections[index]
                record = connection.take()
                if record is not EMPTY:
                    if connection.age is not None:
                        connection.age.took(item_of(record))
                    self._next = (index + 1) % count
                    self._taken = record
                    return NEW_DATA, record[0]
        return self._old()

    def _old(self) -> tuple[ReadStatus, Any]:
        """What a read without a new value gives: the last value (OLD_DATA), unless none came yet or
        the port reads from a pool (NO_DATA)."""
        taken = self._taken
        if taken is None or not self._keeps_last:
            return NO_DATA, None
        return OLD_DATA, taken[0]

    @property
    def stamp(self) -> Stamp | None:
        """The stamp of the value the last read returned (new or old): the message's stamp inside
        one process and from another (the channels carry it), a pooled frame's write's (user
        stamps included; its time and steps the frame's own acquisition stamp's, when its
        :attr:`Slot.stamp <coco_core.pool.Slot.stamp>` has one), a
        :class:`~coco_core.stamps.Stamped` value's own otherwise (a value pushed into a connection
        without a port); None for a plain value that came without one. Made when asked, from what
        the read kept."""
        return None if self._taken is None else _stamp_of(item_of(self._taken))

    @property
    def origin(self) -> Stamp | None:
        """Where the data of the value the last read returned began, what a latency is measured
        from: a :class:`~coco_core.stamps.Stamped` value's own stamp (its acquisition, the source
        that acquired it, the steps of its way), a pooled frame's own acquisition stamp (its
        :attr:`Slot.stamp <coco_core.pool.Slot.stamp>`'s, :func:`~coco_core.pool.frame_stamp`), else
        the stamp of the message that carried it (:attr:`stamp`: its write, in this process or
        another; a pooled frame's write), so that a plain value written through a port has an
        origin too. None only for a plain value pushed into a connection without a port.

        It differs from :attr:`stamp` only in the fields FlowVR's stamp list gives the carrying
        message: ``seq`` and ``source`` stay the acquisition's, as the latency split by source
        (the sensor-to-display figures) needs; the time and the steps are the same."""
        if self._taken is None:
            return None
        item = item_of(self._taken)
        value = item.value if type(item) is Message else item
        if isinstance(value, Stamped):
            return value.stamp
        if type(value) is Slot and value.message is not None and type(value.message.value) is Stamp:
            return value.message.value  # the frame's own acquisition stamp (frame_stamp)
        return _stamp_of(item)

    def read_all_origins(self) -> list[tuple[Any, Stamp | None]]:
        """Like :meth:`read_all`, each value with its :attr:`origin`: a reader that takes the whole
        backlog in one update and measures each value's latency (the stamp of the last read alone
        would stand for every value)."""
        taken: list[tuple[Any, Stamp | None]] = []
        while True:
            status, value = self.read()
            if status is not NEW_DATA:
                return taken
            taken.append((value, self.origin))

    def read_newest(self) -> tuple[ReadStatus, Any]:
        """Like :meth:`read`, for a consumer that wants only the newest value: everything waiting is
        taken and only the newest returned; every older value skipped counts as *dropped* on its
        connection (:meth:`Connection.pop_newest`), so the profile shows what this reader missed.

        With several connections, each one's newest is a candidate and the last in round-robin order
        wins (there is no common clock to order them); the other candidates count as dropped too (a
        skipped pooled frame is released).
        """
        newest: Any = EMPTY
        newest_connection: Connection | None = None
        count = len(self.connections)
        for offset in range(count):
            connection = self.connections[(self._next + offset) % count]
            value = connection.pop_newest()
            if value is EMPTY:
                continue
            if newest_connection is not None:
                newest_connection.skip()
                if isinstance(newest, Slot):
                    newest.release()
            newest, newest_connection = value, connection
        if newest_connection is not None:
            if newest_connection.age is not None:
                newest_connection.age.took(newest)
            self._taken = taken = record_of(newest)
            return NEW_DATA, taken[0]
        return self._old()

    def read_all(self) -> list[Any]:
        """Every value waiting on every connection, in round-robin order; empty when none."""
        values: list[Any] = []
        while True:
            status, value = self.read()
            if status is not NEW_DATA:
                return values
            values.append(value)


def _stamp_of(item: Any) -> Stamp | None:
    """The stamp of what an input port took (see :attr:`InputPort.stamp`)."""
    if type(item) is Message:
        return item.stamp
    if type(item) is Slot:
        return None if item.message is None else item.message.stamp
    return item.stamp if isinstance(item, Stamped) else None
