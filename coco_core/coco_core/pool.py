"""Pooled channels: large frames handed from writer to readers by reference, never copied.

A pooled output port owns a :class:`FramePool` of preallocated numpy buffers (*slots*): a
:class:`LocalFramePool` in its process, or the process level's pool in shared memory when a reader
runs in another process (both implement the :class:`FramePool` protocol). The writer
acquires a FREE slot (-> WRITING), fills it in place and publishes it (-> READY). Each reader takes the
newest READY slot (-> READING, counted per reader) and releases it when done; a slot goes back to FREE
once no reader holds it and a newer frame has been published. The cost of a hand-over is a few
pointer operations under one short lock, whatever the frame size.

Nothing blocks: when every slot is busy the writer reuses the newest frame if no reader has taken it
yet (that frame is dropped, as a DATA connection would overwrite it), and when even that is impossible
``acquire`` returns None and counts a stall, so the writer can skip the frame.
"""

from __future__ import annotations

import abc
import enum
import threading
from typing import Any

import numpy as np

from .connections import EMPTY, Connection
from .errors import PoolError
from .policy import BufferPolicy, ConnectionPolicy, SyncPolicy
from .stamps import Message, Stamp


DEFAULT_SLOTS = 4
"""Slots of a pooled output that does not say (one written, one or two read, one spare)."""


class SlotState(enum.Enum):
    """Life cycle of one slot: FREE -> WRITING -> READY -> READING -> (READY or FREE)."""

    FREE = "free"
    WRITING = "writing"
    READY = "ready"
    READING = "reading"


class Slot:
    """One preallocated frame buffer of a pool, with the metadata that travels with it."""

    __slots__ = ("pool", "index", "array", "state", "readers", "seq", "stamp", "message")

    def __init__(self, pool: FramePool, index: int) -> None:
        self.pool = pool
        self.index = index
        self.array: np.ndarray = np.empty(0)
        self.state = SlotState.FREE
        self.readers = 0
        self.seq = 0
        self.stamp: Any = None
        """Free for the writer: e.g. a :class:`~coco_core.stamps.Stamp` of the frame, which is then
        the frame's acquisition stamp (:func:`frame_stamp`)."""
        self.message: Message | None = None
        """The stamp fields of the write that published the frame, user stamps included, set by
        the pooled output port and read by the reader's :attr:`~coco_core.ports.InputPort.stamp`,
        in this process or from shared memory. Its value is not the frame (the slot is) but the
        frame's acquisition stamp (:func:`frame_stamp` of :attr:`stamp`) or None, so that the
        message's stamp times the frame from its acquisition as a ``Stamped`` value's does."""

    def release(self) -> None:
        """Give the slot back after reading; the writer may reuse it."""
        self.pool.release(self)

    def __enter__(self) -> Slot:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def __repr__(self) -> str:
        return f"<Slot {self.index} {self.state.value} seq={self.seq} readers={self.readers}>"


def frame_stamp(stamp: Any) -> Stamp | None:
    """The acquisition stamp a frame's own :attr:`Slot.stamp` carries: the
    :class:`~coco_core.stamps.Stamp` itself, or the one in its ``stamp`` attribute (a ``Stamped``,
    a mesh's ``MeshInfo``); None for anything else (a count, a layout without a stamp). A frame is
    then timed from its acquisition, not from the write that published it, as a ``Stamped`` value
    is (its readers' ``port.stamp`` time and steps, ``port.origin``)."""
    if type(stamp) is Stamp:
        return stamp
    inner = getattr(stamp, "stamp", None)
    return inner if type(inner) is Stamp else None


class FramePool(abc.ABC):
    """The slot protocol of a pooled output, wherever its slots live: in this process
    (:class:`LocalFramePool`) or in shared memory for readers in other processes
    (:class:`coco_core.shm.ShmFramePool`). A pooled output port and its readers use nothing else."""

    __slots__ = ()

    @property
    @abc.abstractmethod
    def count(self) -> int:
        """Slots in the pool (fixed at its making)."""

    @property
    @abc.abstractmethod
    def published(self) -> int:
        """Frames published so far (the sequence number of the newest)."""

    @property
    @abc.abstractmethod
    def stalls(self) -> int:
        """Acquires refused because every slot was in use."""

    @property
    @abc.abstractmethod
    def reused(self) -> int:
        """Frames replaced unread by a newer one (the writer took back the newest READY slot)."""

    @property
    @abc.abstractmethod
    def newest_seq(self) -> int:
        """The sequence number of the newest frame still published, 0 when none (a reader's
        ``pending``)."""

    @abc.abstractmethod
    def acquire(self, shape: tuple[int, ...], dtype: Any = np.uint8) -> Slot | None:
        """A slot to write into (WRITING), with an array of ``shape`` and ``dtype``; None (and a
        stall counted) when every slot is in use."""

    @abc.abstractmethod
    def publish(self, slot: Slot) -> None:
        """Make a written slot the newest frame (WRITING -> READY)."""

    @abc.abstractmethod
    def take(self, after_seq: int) -> Slot | None:
        """The newest frame if it is newer than ``after_seq``, marked READING for one more reader."""

    @abc.abstractmethod
    def release(self, slot: Slot) -> None:
        """One reader is done with ``slot``; the last one returns it to READY (newest) or FREE."""

    @abc.abstractmethod
    def states(self) -> list[SlotState]:
        """State of every slot, for tests and diagnostics."""

    @property
    def live(self) -> bool:
        """Whether the pool is in use: a frame published, or a slot out of FREE. A pooled output's
        pool is chosen before (:meth:`coco_core.ports.PooledOutputPort.use_pool`)."""
        return self.published > 0 or any(state is not SlotState.FREE for state in self.states())


class LocalFramePool(FramePool):
    """A pool whose slots are numpy buffers of this process, shared by one writer and any number of
    readers in it."""

    __slots__ = ("_lock", "slots", "published", "stalls", "reused", "newest")

    published: int  # fields here, where the protocol only asks for values
    stalls: int
    reused: int

    def __init__(self, slots: int) -> None:
        if slots < 2:
            raise PoolError(f"a frame pool needs at least 2 slots (one written, one read), got {slots}")
        self._lock = threading.Lock()
        self.slots = [Slot(self, i) for i in range(slots)]
        self.published = 0
        self.stalls = 0
        self.reused = 0
        self.newest: Slot | None = None

    @property
    def count(self) -> int:
        return len(self.slots)

    @property
    def newest_seq(self) -> int:
        newest = self.newest
        return newest.seq if newest is not None else 0

    def acquire(self, shape: tuple[int, ...], dtype: Any = np.uint8) -> Slot | None:
        """A slot to write into (WRITING), with an array of ``shape`` and ``dtype``.

        Buffers are allocated on first use and only reallocated when the shape or dtype changes, so a
        steady stream allocates nothing. Returns None (and counts a stall) when every slot is in use.
        """
        with self._lock:
            slot = self._free_slot()
            if slot is None:
                self.stalls += 1
                return None
            slot.state = SlotState.WRITING
        array = slot.array
        if array.shape != tuple(shape) or array.dtype != np.dtype(dtype):
            slot.array = np.empty(shape, dtype)
        return slot

    def _free_slot(self) -> Slot | None:
        for slot in self.slots:
            if slot.state is SlotState.FREE:
                return slot
        # Only the newest frame can be READY (publish frees the one before it): if no reader took it,
        # replacing it with a fresher frame is exactly the latest-value semantics.
        newest = self.newest
        if newest is not None and newest.state is SlotState.READY:
            self.reused += 1
            self.newest = None
            return newest
        return None

    def publish(self, slot: Slot) -> None:
        with self._lock:
            if slot.state is not SlotState.WRITING or slot.pool is not self:
                raise PoolError(f"publish() needs a slot acquired from this pool, got {slot!r}")
            self.published += 1
            slot.seq = self.published
            slot.state = SlotState.READY
            previous, self.newest = self.newest, slot
            if previous is not None and previous.state is SlotState.READY:
                previous.state = SlotState.FREE

    def take(self, after_seq: int) -> Slot | None:
        with self._lock:
            slot = self.newest
            if slot is None or slot.seq <= after_seq:
                return None
            slot.readers += 1
            slot.state = SlotState.READING
            return slot

    def release(self, slot: Slot) -> None:
        with self._lock:
            if slot.readers <= 0:
                raise PoolError(f"release() of a slot that is not being read: {slot!r}")
            slot.readers -= 1
            if slot.readers == 0:
                slot.state = SlotState.READY if slot is self.newest else SlotState.FREE

    def states(self) -> list[SlotState]:
        with self._lock:
            return [slot.state for slot in self.slots]


class PoolReader(Connection):
    """The reader's side of a pooled output, wherever the pool and the ``read`` counter live:
    latest-frame semantics over the pool. An input port gives a pooled frame out once only (no
    OLD_DATA of a slot released since); a skipped frame is released."""

    __slots__ = ("pool", "_seen")

    @property
    @abc.abstractmethod
    def read(self) -> int:
        """Frames this reader took and used (a field, or a word of shared memory)."""

    @read.setter
    @abc.abstractmethod
    def read(self, value: int) -> None:
        """Counted by this reader's thread only, in :meth:`pop` and :meth:`skip`."""

    def __init__(self, pool: FramePool, policy: ConnectionPolicy) -> None:
        super().__init__(policy)
        self.pool = pool
        self._seen = 0
        """The sequence number of the last frame this reader took."""

    def pop(self) -> Any:
        slot = self.pool.take(self._seen)
        if slot is None:
            return EMPTY
        self._seen = slot.seq
        self.read += 1
        return slot

    def skip(self, count: int = 1) -> None:
        self.read -= count

    def pop_newest(self) -> Any:
        """The newest frame; a frame published while this one was taken replaces it, and the one it
        replaces is released (a skipped slot held by nobody would be lost to the writer) and
        counted as dropped."""
        newest = self.pop()
        if newest is EMPTY:
            return EMPTY
        while (slot := self.pop()) is not EMPTY:
            self.skip()
            newest.release()
            newest = slot
        return newest

    @property
    def pending(self) -> int:
        return 1 if self.pool.newest_seq > self._seen else 0


class PoolConnection(PoolReader):
    """The reader's side of a pooled output in the writer's process (its pool, its counters here)."""

    __slots__ = ("written", "read")

    written: int  # fields here, where the contract only asks for values
    read: int

    def __init__(self, pool: FramePool, policy: ConnectionPolicy | None = None) -> None:
        super().__init__(pool, policy or ConnectionPolicy(BufferPolicy.POOL, SyncPolicy.LOCKED, pool.count))
        self.written = 0
        self.read = 0

    def push(self, value: Any) -> None:
        # The frame is already in the pool (published by the port); count it and wake the reader.
        self.written += 1
        if self.trigger is not None:
            self.trigger()
