"""Pooled frames between processes: a pooled output's slots in shared memory, read without a copy.

The same protocol as :class:`coco_core.pool.FramePool` (FREE -> WRITING -> READY -> READING ->
release), kept in a *control* segment that every process of the pool maps: per slot its state,
reader count, sequence number, the shape and dtype of its frame, its stamp and its message's stamp
(user stamps included); then, per reader in another process, its ``read`` counter (in shared
memory, so that the launcher still has a reader's figures when that reader's process died). One
pool serves every reader of a pooled output, in any process, with the slot count the port declares,
as the in-process pool does. A slot's pixels live in a segment of their own, made by the writer
when the frame size first needs it (and made anew, under a new generation number, when the size
changes: readers that still hold the old one keep their mapping). A reader gets a numpy array
*over* the slot's segment: no copy, whatever the frame size.

State changes are short critical sections under a ``flock`` on the control segment (between
processes) and a thread lock (between threads of one process, which share the flock):
:class:`~.segment.SegmentLock`, whose kernel lock orders the pixels written before a publish
before the reads after a take on any CPU.
"""

from __future__ import annotations

import pickle
from typing import Any

import numpy as np

from ..connections import CountedConnection
from ..errors import CocoError, PoolError
from ..pool import FramePool, PoolReader, Slot, SlotState, frame_stamp
from ..stamps import NO_USER_STAMPS, Message
from .channel import ChannelSpec
from .segment import Segment, SegmentLock, unlink

HEADER = 64
PUBLISHED, STALLS, REUSED, NEWEST, SLOTS = range(5)
RECORD = 1024
"""Bytes of one slot's record: 16 int64 fields, the dtype string, the pickled stamp, the pickled user
stamps of the frame's message."""
STATE, READERS, SEQ, GENERATION, NBYTES, NDIM, SHAPE = 0, 1, 2, 3, 4, 5, 6
MAX_NDIM = 6
NUM, IT, TIME = SHAPE + MAX_NDIM, SHAPE + MAX_NDIM + 1, SHAPE + MAX_NDIM + 2
"""The record's words of the frame's message stamp (:attr:`Slot.message <coco_core.pool.Slot.message>`):
its number on the port (0: none), the writing activity's iteration, the time of the write (float64)."""
DTYPE_AT, DTYPE_SIZE = 128, 32
STAMP_AT = DTYPE_AT + DTYPE_SIZE
USER_AT = 512
STAMP_SIZE = USER_AT - STAMP_AT
USER_SIZE = RECORD - USER_AT
"""The record's area of the frame message's user stamps (``out.write(slot, stamps=...)``): their
length (8 bytes, 0: none), then their pickle. FlowVR's user stamps are small named values (a box,
a part number): a frame's own data belongs in its pixels or its ``Slot.stamp``."""
STATES = [SlotState.FREE, SlotState.WRITING, SlotState.READY, SlotState.READING]
CODE = {state: code for code, state in enumerate(STATES)}


def control_size(slots: int, readers: int) -> int:
    return HEADER + slots * RECORD + readers * 8


class ShmFramePool(FramePool):
    """A frame pool whose slots live in shared memory: the writer's process gives it to its pooled
    output port (:meth:`~coco_core.ports.PooledOutputPort.use_pool`); every reader process attaches
    one to read from it."""

    def __init__(self, spec: ChannelSpec) -> None:
        self.spec = spec
        self.control = Segment(spec.segment)
        self.header = self.control.view[:HEADER].cast("q")
        self._count = int(self.header[SLOTS])
        at = HEADER + self._count * RECORD
        self.reads = self.control.view[at:at + spec.readers * 8].cast("q")
        """The ``read`` counter of every reader in another process (each has one writer: its reader)."""
        self._locked = SegmentLock(self.control)
        self._data: dict[tuple[int, int], Segment] = {}
        """(slot, generation) -> its mapped pixel segment, in this process."""

    # --- the counters of the FramePool protocol -------------------------------------------------
    @property
    def count(self) -> int:
        return self._count

    @property
    def published(self) -> int:
        return int(self.header[PUBLISHED])

    @property
    def stalls(self) -> int:
        return int(self.header[STALLS])

    @property
    def reused(self) -> int:
        return int(self.header[REUSED])

    @property
    def newest_seq(self) -> int:
        with self._locked:  # the newest slot and its sequence number, as one publish left them
            index = int(self.header[NEWEST])
            return int(self._record(index)[SEQ]) if index >= 0 else 0

    def states(self) -> list[SlotState]:
        with self._locked:
            return [STATES[self._record(index)[STATE]] for index in range(self._count)]

    def _record(self, index: int) -> memoryview:
        offset = HEADER + index * RECORD
        return self.control.view[offset:offset + DTYPE_AT].cast("q")

    def _times(self, index: int) -> memoryview[float]:
        """Slot ``index``'s record as float64 words (its ``TIME``)."""
        offset = HEADER + index * RECORD
        return self.control.view[offset:offset + DTYPE_AT].cast("d")

    def _bytes(self, index: int, at: int, size: int) -> memoryview:
        offset = HEADER + index * RECORD + at
        return self.control.view[offset:offset + size]

    # --- the protocol ---------------------------------------------------------------------------
    def acquire(self, shape: tuple[int, ...], dtype: Any = np.uint8) -> Slot | None:
        """A slot to write into (WRITING), its array a view of shared memory; None (a stall) when
        every slot is in use."""
        shape, dtype = tuple(int(n) for n in shape), np.dtype(dtype)
        if len(shape) > MAX_NDIM:
            raise CocoError(f"connection {self.spec.label}: frames have at most {MAX_NDIM} dimensions, got {shape}")
        with self._locked:
            index = self._free_slot()
            if index is None:
                self.header[STALLS] += 1
                return None
            record = self._record(index)
            record[STATE] = CODE[SlotState.WRITING]
            nbytes = int(np.prod(shape)) * dtype.itemsize
            same = (record[NDIM] == len(shape) and tuple(record[SHAPE:SHAPE + len(shape)]) == shape
                    and bytes(self._bytes(index, DTYPE_AT, DTYPE_SIZE)).rstrip(b"\0") == dtype.str.encode())
            if not same or record[NBYTES] < nbytes or record[GENERATION] == 0:
                self._reallocate(index, record, shape, dtype, nbytes)
            generation = int(record[GENERATION])
        slot = Slot(self, index)
        slot.state = SlotState.WRITING
        slot.array = self._array(index, generation, shape, dtype)
        return slot

    def _free_slot(self) -> int | None:
        for index in range(self._count):
            if self._record(index)[STATE] == CODE[SlotState.FREE]:
                return index
        newest = int(self.header[NEWEST])  # only the newest frame can be READY: replace it if unread
        if newest >= 0 and self._record(newest)[STATE] == CODE[SlotState.READY]:
            self.header[REUSED] += 1
            self.header[NEWEST] = -1
            return newest
        return None

    def _reallocate(self, index: int, record: memoryview, shape: tuple[int, ...], dtype: np.dtype,
                    nbytes: int) -> None:
        """A new pixel segment for slot ``index`` (a new generation); the old one's name goes."""
        old = int(record[GENERATION])
        if old:
            unlink(self._data_name(index, old))
        generation = old + 1
        Segment(self._data_name(index, generation), max(nbytes, 1)).close()
        record[GENERATION], record[NBYTES], record[NDIM] = generation, nbytes, len(shape)
        for axis in range(MAX_NDIM):
            record[SHAPE + axis] = shape[axis] if axis < len(shape) else 0
        code = dtype.str.encode()
        target = self._bytes(index, DTYPE_AT, DTYPE_SIZE)
        target[:] = code + b"\0" * (DTYPE_SIZE - len(code))

    def _data_name(self, index: int, generation: int) -> str:
        return f"{self.spec.segment}.s{index}.g{generation}"

    def _array(self, index: int, generation: int, shape: tuple[int, ...], dtype: np.dtype) -> np.ndarray:
        key = (index, generation)
        segment = self._data.get(key)
        if segment is None:
            for stale in [k for k in self._data if k[0] == index]:
                self._data.pop(stale).close()
            segment = self._data[key] = Segment(self._data_name(index, generation))
        return np.ndarray(shape, dtype, buffer=segment.map)

    def publish(self, slot: Slot) -> None:
        """Make a written slot the newest frame (WRITING -> READY), with its stamp and its message's
        user stamps (pickled only when there are some)."""
        stamp = pickle.dumps(slot.stamp, protocol=5)
        if len(stamp) > STAMP_SIZE - 8:
            raise CocoError(f"connection {self.spec.label}: a frame's stamp of {len(stamp)} bytes is larger than "
                            f"{STAMP_SIZE - 8}")
        message = slot.message
        user = pickle.dumps(message.user, protocol=5) if message is not None and message.user else b""
        if len(user) > USER_SIZE - 8:
            raise CocoError(f"connection {self.spec.label}: a frame's user stamps of {len(user)} bytes pickled are "
                            f"larger than {USER_SIZE - 8} (small named values: put larger data in the frame or its "
                            "Slot.stamp)")
        with self._locked:
            record = self._record(slot.index)
            if slot.pool is not self or record[STATE] != CODE[SlotState.WRITING]:
                raise PoolError(f"publish() needs a slot acquired from this pool, got {slot!r}")
            self.header[PUBLISHED] += 1
            slot.seq = record[SEQ] = int(self.header[PUBLISHED])
            record[STATE] = CODE[SlotState.READY]
            record[NUM] = 0 if message is None else message.seq
            if message is not None:
                record[IT] = message.it
                self._times(slot.index)[TIME] = message.time
            for at, size, data in ((STAMP_AT, STAMP_SIZE, stamp), (USER_AT, USER_SIZE, user)):
                target = self._bytes(slot.index, at, size)
                target[:8] = len(data).to_bytes(8, "little")
                target[8:8 + len(data)] = data
            previous = int(self.header[NEWEST])
            self.header[NEWEST] = slot.index
            if previous >= 0 and previous != slot.index and self._record(previous)[STATE] == CODE[SlotState.READY]:
                self._record(previous)[STATE] = CODE[SlotState.FREE]
        slot.state = SlotState.READY

    def take(self, after_seq: int) -> Slot | None:
        """The newest frame if newer than ``after_seq``, READING for one more reader, its array a view
        of the shared pixels."""
        with self._locked:
            index = int(self.header[NEWEST])
            if index < 0:
                return None
            record = self._record(index)
            if record[SEQ] <= after_seq:
                return None
            record[READERS] += 1
            record[STATE] = CODE[SlotState.READING]
            seq, generation, ndim = int(record[SEQ]), int(record[GENERATION]), int(record[NDIM])
            shape = tuple(int(n) for n in record[SHAPE:SHAPE + ndim])
            dtype = np.dtype(bytes(self._bytes(index, DTYPE_AT, DTYPE_SIZE)).rstrip(b"\0").decode())
            stamp, user = self._pickled(index, STAMP_AT, STAMP_SIZE), self._pickled(index, USER_AT, USER_SIZE)
            num, it, at = int(record[NUM]), int(record[IT]), self._times(index)[TIME]
        slot = Slot(self, index)
        slot.state, slot.seq, slot.readers = SlotState.READING, seq, 1
        slot.stamp = pickle.loads(stamp) if stamp else None
        if num:
            slot.message = Message(frame_stamp(slot.stamp), at, num, self.spec.label.partition("->")[0], it,
                                   pickle.loads(user) if user else NO_USER_STAMPS)
        slot.array = self._array(index, generation, shape, dtype)
        return slot

    def _pickled(self, index: int, at: int, size: int) -> bytes:
        """The bytes of the pickle in slot ``index``'s record area at ``at`` (its length first);
        empty when none."""
        area = self._bytes(index, at, size)
        length = int.from_bytes(area[:8], "little")
        return bytes(area[8:8 + length])

    def release(self, slot: Slot) -> None:
        """One reader is done with ``slot``; the last one returns it to READY (newest) or FREE."""
        with self._locked:
            record = self._record(slot.index)
            if record[READERS] <= 0:
                raise PoolError(f"release() of a slot that is not being read: {slot!r}")
            record[READERS] -= 1
            if record[READERS] == 0:
                newest = int(self.header[NEWEST]) == slot.index
                record[STATE] = CODE[SlotState.READY if newest else SlotState.FREE]
        slot.state = SlotState.FREE

    def unlink_slots(self) -> None:
        """Remove the pixel segments' names (the launcher's arena removes the control segment)."""
        for index in range(self._count):
            generation = int(self._record(index)[GENERATION])
            if generation:
                unlink(self._data_name(index, generation))

    def close(self) -> None:
        for segment in self._data.values():
            segment.close()
        self._data.clear()
        self.header.release()
        self.reads.release()
        self.control.close()


class ShmPoolReader(PoolReader):
    """The reader's end of a pooled channel: the newest frame, once, as a slot over shared memory.
    The same :class:`PoolReader` as a reader in the writer's process, its pool and its ``read``
    counter in shared memory (so that the launcher has the figures of a reader whose process died)."""

    __slots__ = ("spec",)

    pool: ShmFramePool

    def __init__(self, spec: ChannelSpec) -> None:
        super().__init__(ShmFramePool(spec), spec.policy)
        self.spec = spec

    @property
    def written(self) -> int:
        return self.pool.published

    @property
    def label(self) -> str:
        source, _, sink = self.spec.label.partition("->")
        return f"{source} -> {sink}"

    @property
    def read(self) -> int:
        return int(self.pool.reads[self.spec.reader])

    @read.setter
    def read(self, value: int) -> None:
        self.pool.reads[self.spec.reader] = value

    def push(self, value: Any) -> None:
        raise CocoError(f"connection {self.spec.label}: the reader's end cannot be written")


class FrameStats(CountedConnection):
    """A read-only view of one pooled channel's counters, for the launcher when the reader's process
    died: frames published, the reader's ``read`` from shared memory, nothing pending (the reader
    is gone)."""

    __slots__ = ("spec",)

    def __init__(self, spec: ChannelSpec) -> None:
        super().__init__(spec.policy)
        self.spec = spec
        pool = ShmFramePool(spec)
        try:
            self.written, self.read = pool.published, int(pool.reads[spec.reader])
        finally:
            pool.close()

    @property
    def label(self) -> str:
        source, _, sink = self.spec.label.partition("->")
        return f"{source} -> {sink}"

    def push(self, value: Any) -> None:
        raise CocoError("a FrameStats view cannot be written")

    def pop(self) -> Any:
        raise CocoError("a FrameStats view cannot be read")

    @property
    def pending(self) -> int:
        return 0


class ShmFrameNotifier(CountedConnection):
    """The writer's end of a pooled channel: the frame is already in the shared pool (published by
    the port), so a write only counts and wakes the reader's process."""

    __slots__ = ()

    def __init__(self, spec: ChannelSpec) -> None:
        super().__init__(spec.policy)

    def push(self, value: Any) -> None:
        self.written += 1
        if self.trigger is not None:
            self.trigger()

    def pop(self) -> Any:
        raise CocoError("the writer's end of a pooled channel cannot be read")

    @property
    def pending(self) -> int:
        return 0
