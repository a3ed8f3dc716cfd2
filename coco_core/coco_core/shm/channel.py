"""Value channels between processes: one writer process, one reader process, one ring of slots.

The ring lives in one shared-memory segment: a header of counters, then ``slots`` slots of a fixed
capacity. Each slot holds a *stamp* (the index of the item in it, plus one; zero while it is being
written), the length, the message's stamp fields (what the writing port stamped: its number, the
iteration, the time) and the pickled value. Its layout, in 64-bit words (native byte order):

============  ==============  ==============================================================
where         word            meaning
============  ==============  ==============================================================
header        ``OFFERED``     values offered by the writer (the profile's ``written``)
header        ``STORED``      values placed in the ring (the next item's index)
header        ``READ``        values the reader took and used (the profile's ``read``)
header        ``CURSOR``      the index of the next item the reader takes
header        ``FINISHED``    1 once the writer's activity finished
header        ``ROUTED``      messages the writer's end routed away (a Split or Cull decided on
                              the writer's side: :mod:`coco_core.processes.routed`); never stored
header        (2 words)       unused; the header is ``HEADER`` bytes
slot          ``STAMP``       the item's index + 1; 0 while the slot is being written
slot          ``LENGTH``      bytes of the value (its table of parts, pickle and arrays)
slot          ``LARGE``       0: the value follows in the slot; 1: in a segment of its own
slot          ``NUM``         the message's number on its port (its stamp's ``seq``); 0: a bare value
slot          ``IT``          the iteration of the writing activity (the stamp's ``it``)
slot          ``TIME``        when it was written (the stamp's time, a float64); the header is
                              ``SLOT_HEADER`` bytes
slot          (capacity)      the value, when it fits
============  ==============  ==============================================================

Slot ``i`` starts at byte ``HEADER + i * (SLOT_HEADER + capacity)``. Each counter has one writer,
so no lock is needed:

- the writer process owns ``offered`` (values offered: the ``written`` counter of the profile),
  ``stored`` (values placed in the ring) and ``routed`` (messages routed away before the ring);
- the reader process owns ``read`` and ``cursor`` (the index of the next item it takes).

The policies keep their in-process meaning:

- BUFFER: ``size`` slots; a value offered while ``size`` are pending is refused (dropped), so the
  writer never overwrites an unread slot;
- CIRCULAR: ``size`` slots; the writer always stores, overwriting the oldest item when the ring is
  full; a reader that was lapped skips to the oldest item still there, and what it skipped counts as
  dropped. A slot overwritten while it is being read is detected by its stamp changing during the
  copy (a sequence lock) and the read is retried;
- DATA: two slots, the reader always takes the newest item once (NEW, then nothing until the next).

The message's stamp (:class:`~coco_core.stamps.Message`: what the writing port made of the write)
crosses in the slot's header, in the same seqlock as the value, so that the reader's port reads the
same :attr:`~coco_core.ports.InputPort.stamp` as in one process; its source (the writing port) is the
channel's, in its label, and a :class:`~coco_core.stamps.Stamped` value's own stamp travels inside the
value. A bare value pushed without a message (``NUM`` 0) arrives bare.

``dropped`` is derived, as in-process: offered - read - pending. Values cross as pickles (protocol 5)
whose arrays are written out of band, straight from their memory into the slot (numpy arrays are not
first pickled into bytes). Frames do not go this way: a pooled output's slots live in shared memory
and are read in place (:mod:`coco_core.shm.frames`).

A value larger than a slot goes to a segment of its own (``<channel>.v<item index>``), written with
one ``pwritev`` and read with one ``preadv`` (no mapping, no page faults in Python). Once the reader
has its copy the segment becomes one of two *spares* (a rename), which the writer renames back for a
later large value, so that its pages are reused rather than allocated and zeroed by the kernel
again; a spare replaced by a newer one goes. The writer unlinks an item nobody read when it
overwrites it (CIRCULAR, DATA). So /dev/shm holds the pending large values and two spares, whatever
the size of the ring: a reader that keeps up keeps it at the ring plus the two last values. When
/dev/shm (or the process's file-size limit) cannot take a value, the write fails with a
:class:`ChannelError` saying so, and the value counts as dropped; nothing is left half-written.

The stores are ordered payload, then stamp, then counter, and the loads the other way round; on
x86-64 (total store order) that is all the ordering needed. CPython exposes no memory fence, so on
CPUs that may reorder stores (ARM, POWER, RISC-V) a ring takes the *locked* path: both sides make
every access to its shared words under the segment's lock (:class:`~.segment.SegmentLock`), as the
launch decided in the channel's description (:mod:`.ordering`; ``COCO_SHM_LOCKED=1`` forces it).
"""

from __future__ import annotations

import copyreg
import errno
import functools
import io
import os
import pickle
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..connections import EMPTY, Connection
from ..errors import ChannelError, CocoError, FileWriteError
from ..policy import BufferPolicy, ConnectionPolicy
from ..stamps import Message
from .segment import SHM_DIR, Segment, SegmentLock, rename, shm_open, unlink

HEADER = 64
"""Bytes of the ring's header (its counters, then unused words)."""
OFFERED, STORED, READ, CURSOR, FINISHED, ROUTED = range(6)
"""The header's words (see the module's docstring)."""
SLOT_HEADER = 48
"""Bytes of a slot's header, before its value."""
STAMP, LENGTH, LARGE, NUM, IT, TIME = range(6)
"""The words of a slot's header: the item's index + 1 (0 while written), the value's bytes, where
the value is (0: in the slot, 1: in a segment of its own), and the message's stamp: its number on
the writing port (0: a bare value, no message), the writing activity's iteration and the time of
the write (a float64, through :attr:`_Ring.times`)."""
RETRIES = 10_000
"""Reads of a slot that keeps changing before the reader gives up for this call (a writer that died
half-way through a slot would otherwise keep it spinning)."""
DEFAULT_CAPACITY = 4 * 1024
"""Bytes of one slot (larger values go to a segment of their own)."""
IOV_MAX = 1024
"""Buffers one ``pwritev`` takes (Linux's limit)."""


@dataclass(frozen=True)
class ChannelSpec:
    """What a process needs to attach to one channel: made by the launcher, sent to the children."""

    segment: str
    label: str
    """``src.port->dest.port``, for errors and the profile."""
    policy: ConnectionPolicy
    slots: int
    capacity: int
    frames: bool = False
    readers: int = 0
    """Frames: the readers in other processes than the writer's, each with its counter in the pool's
    control segment (one pool for every reader of a pooled output)."""
    reader: int = 0
    """Frames: this connection's reader number, its counter's place."""
    locked: bool = False
    """Values: whether both ends take the ring's locked path (decided once per launch, by the CPU:
    :func:`coco_core.shm.ordering.rings_locked`)."""
    stamps_only: bool = False
    """Values: the writer puts each message's stamp into the ring, not its payload (a stamps-only
    connection): what the reader's process's profile says beside the policy."""


def large_name(spec: ChannelSpec, index: int) -> str:
    """The segment of item ``index``'s value, when it is larger than a slot."""
    return f"{spec.segment}.v{index}"


SPARES = 2
"""Segments of large values already read, kept for their pages (item ``i`` becomes spare ``i % 2``
once read, and item ``i`` is written into that spare if there is one)."""


def spare_name(spec: ChannelSpec, index: int) -> str:
    return f"{spec.segment}.spare{index % SPARES}"


def layout(policy: ConnectionPolicy, capacity: int | None) -> tuple[int, int]:
    """(slots, capacity) of a value channel with ``policy``."""
    slots = 2 if policy.data is BufferPolicy.DATA else max(1, policy.size)
    capacity = ((capacity or DEFAULT_CAPACITY) + 7) // 8 * 8
    return slots, capacity


def ring_size(slots: int, capacity: int) -> int:
    return HEADER + slots * (SLOT_HEADER + capacity)


class _Ring:
    """The mapped ring of one channel, as one side sees it."""

    def __init__(self, spec: ChannelSpec) -> None:
        self.spec = spec
        self.segment = Segment(spec.segment)
        self.counters = self.segment.view[:HEADER].cast("q")
        self.slots = spec.slots
        self.capacity = spec.capacity
        self.stride = SLOT_HEADER + spec.capacity
        self.map = self.segment.map
        self.bytes = self.segment.view
        """The segment's bytes as a view: a slice of it is copied once into the reader's value."""
        self.words = self.segment.view[HEADER:].cast("q")
        """The ring as 64-bit words: slot ``i``'s header starts at word ``i * stride // 8``, so headers
        are read and written without making a view per access."""
        self.times = self.segment.view[HEADER:].cast("d")
        """The same words as float64: the slots' ``TIME``."""
        self.slot_words = self.stride // 8
        self.lock = SegmentLock(self.segment) if spec.locked else None
        """The locked path's critical section (None: the unlocked path, on a CPU that keeps stores
        in order)."""

    def close(self) -> None:
        self.counters.release()
        self.words.release()
        self.times.release()
        self.segment.close()


class ShmConnection(Connection):
    """What both ends share: the counters in shared memory, read as the profile reads any connection."""

    __slots__ = ("ring", "mode")

    def __init__(self, spec: ChannelSpec) -> None:
        super().__init__(spec.policy)
        self.ring = _Ring(spec)
        self.mode = spec.policy.data

    @property
    def written(self) -> int:
        return int(self.ring.counters[OFFERED])

    @property
    def read(self) -> int:
        return int(self.ring.counters[READ])

    @property
    def pending(self) -> int:
        lock = self.ring.lock
        if lock is None:
            return self._pending()
        with lock:
            return self._pending()

    def _pending(self) -> int:
        counters = self.ring.counters
        waiting = counters[STORED] - counters[CURSOR]
        if self.mode is BufferPolicy.DATA:
            return 1 if waiting > 0 else 0
        return min(waiting, self.ring.slots)

    @property
    def routed_away(self) -> int:
        """Messages the writer's end routed away before the ring (:meth:`ShmWriter.route_away`):
        the reader's process shows them after its filter, as in one process."""
        return int(self.ring.counters[ROUTED])

    @property
    def writer_finished(self) -> bool:
        """Whether the writer's activity has finished (the writer process set ``FINISHED``): a natural
        stop lets the reader's activity stop only then, so that the last values are read (on the
        locked path, the values stored before are then visible too)."""
        lock = self.ring.lock
        if lock is None:
            return bool(self.ring.counters[FINISHED])
        with lock:
            return bool(self.ring.counters[FINISHED])

    @property
    def label(self) -> str:
        source, _, sink = self.ring.spec.label.partition("->")
        return f"{source} -> {sink}"

    @property
    def stamps_only(self) -> bool:
        return self.ring.spec.stamps_only or super().stamps_only

    def close(self) -> None:
        self.ring.close()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.ring.spec.label} {self.policy}>"


class ShmWriter(ShmConnection):
    """The writer's end of a value channel (in the writer's process, on its output port).

    A value larger than a slot goes into a segment of its own, a spare one once read (see the
    module's docstring): a camera image on a plain output port crosses too, at the price of one copy
    each way and a few system calls; frames without copies are what pooled outputs are for."""

    __slots__ = ("_out", "_parts", "_pickler")
    carries_stamps = True

    def __init__(self, spec: ChannelSpec) -> None:
        super().__init__(spec)
        self._out = io.BytesIO()
        self._parts: list[pickle.PickleBuffer] = []
        """The arrays of the value being encoded, out of band (emptied once it is stored)."""
        self._pickler = pickle.Pickler(self._out, 5, buffer_callback=self._parts.append)
        """One pickler for every value of this end, its memo cleared before each: making a pickler
        and its buffer per value was a third of the encoding of a small sample. An output port is
        written by its own activity's thread only, so one end never encodes two values at once."""
        self._pickler.dispatch_table = _DISPATCH

    def writer_done(self) -> None:
        """Tell the reader's process that nothing more will come (see :attr:`writer_finished`)."""
        lock = self.ring.lock
        if lock is None:
            self.ring.counters[FINISHED] = 1
            return
        with lock:
            self.ring.counters[FINISHED] = 1

    def route_away(self) -> None:
        """Count a message the writer's end routed to another connection (it never enters the
        ring, and is not offered to it: see :attr:`routed_away`)."""
        lock = self.ring.lock
        if lock is None:
            self.ring.counters[ROUTED] += 1
            return
        with lock:
            self.ring.counters[ROUTED] += 1

    def _store_large(self, index: int, parts: list[Any], size: int) -> None:
        """Item ``index``'s value (``parts``, ``size`` bytes) in a segment of its own; a
        :class:`ChannelError` when it cannot be stored whole (nothing of it is left then)."""
        name = large_name(self.ring.spec, index)
        try:
            fd = shm_open(name) if rename(spare_name(self.ring.spec, index), name) else shm_open(name, create=True)
        except OSError as error:
            unlink(name)
            raise self._unstored(size, error) from None
        try:
            os.ftruncate(fd, size)  # a spare of a larger value gives back what this one does not use
            _write_all(fd, parts)
        except OSError as error:
            unlink(name)
            raise self._unstored(size, error) from None
        finally:
            os.close(fd)

    def _unstored(self, size: int, error: OSError) -> ChannelError:
        try:
            stats = os.statvfs(SHM_DIR)
            free = f"{stats.f_bavail * stats.f_frsize / 2**20:.1f} MiB free there"
        except OSError:
            free = "free space unknown"
        return ChannelError(f"connection {self.ring.spec.label}: a value of {size / 2**20:.1f} MiB does not fit in "
                            f"{SHM_DIR} ({free}; {error.strerror}): it was dropped. Values larger than a slot "
                            f"wait there until read: read faster, send less, or use a pooled output")

    def push(self, value: Any) -> None:
        ring = self.ring
        message = value if type(value) is Message else None
        if message is not None:
            value = message.crossing()  # user stamps travel in the payload, the fixed fields in the slot
        out, parts, pickler = self._out, self._parts, self._pickler
        try:
            out.seek(0)
            out.truncate()
            try:
                pickler.dump(value)
            except Exception as error:
                raise ChannelError(f"connection {ring.spec.label}: {type(value).__name__} value cannot be sent to "
                                   f"another process: {error}") from None
            data = out.getvalue()  # a copy of the pickle (its arrays are out of band): no export of the
            # BytesIO outlives the call, which a view kept by a failure's traceback would be
            raws = [part.raw() for part in parts]
            table = _table(len(raws)).pack(len(raws), len(data), *(raw.nbytes for raw in raws))
            lock = ring.lock
            if lock is None:
                stored = self._store(table, data, raws, message)
            else:
                with lock:
                    stored = self._store(table, data, raws, message)
        finally:  # nothing of the value is kept alive by this end, nor referred to by the next one
            parts.clear()
            pickler.clear_memo()
        trigger = self.trigger
        if stored and trigger is not None:
            trigger()

    def _store(self, table: bytes, data: bytes, raws: list[memoryview], message: Message | None) -> bool:
        """Place one encoded value and its message's stamp in the ring (the seqlock's writer side);
        False when a full BUFFER refused it."""
        ring = self.ring
        counters = ring.counters
        size = len(table) + len(data) + sum(raw.nbytes for raw in raws)
        counters[OFFERED] += 1
        stored = counters[STORED]
        if self.mode is BufferPolicy.BUFFER and stored - counters[CURSOR] >= ring.slots:
            return False  # full: the new value is refused, as an in-process BUFFER refuses it
        large = size > ring.capacity
        if large:  # stored before the slot changes: a value that does not fit leaves the ring as it was
            self._store_large(stored, [table, data, *raws], size)
        index = stored % ring.slots
        words, word = ring.words, index * ring.slot_words
        if words[word + LARGE] and words[word + STAMP] > counters[CURSOR]:  # a large item nobody read goes
            unlink(large_name(ring.spec, words[word + STAMP] - 1))
        words[word + STAMP] = 0  # being written: a reader of this slot retries
        words[word + LENGTH] = size
        words[word + LARGE] = large
        if message is None:
            words[word + NUM] = 0
        else:
            words[word + NUM] = message.seq
            words[word + IT] = message.it
            ring.times[word + TIME] = message.time
        if not large:
            target, at = ring.map, HEADER + index * ring.stride + SLOT_HEADER
            target[at:at + len(table)] = table
            at += len(table)
            target[at:at + len(data)] = data
            at += len(data)
            for raw in raws:  # arrays go from their own memory into the slot: one copy
                target[at:at + raw.nbytes] = raw
                at += raw.nbytes
        words[word + STAMP] = stored + 1
        counters[STORED] = stored + 1
        return True

    def pop(self) -> Any:
        raise CocoError(f"connection {self.ring.spec.label}: the writer's end cannot be read")

    def skip(self, count: int = 1) -> None:
        raise CocoError(f"connection {self.ring.spec.label}: the writer's end cannot be read")


_COUNT = struct.Struct("<I")
"""The first word of a value's table: how many arrays follow its pickle."""


@functools.lru_cache(maxsize=64)
def _table(arrays: int) -> struct.Struct:
    """The table of parts that leads a value of ``arrays`` out-of-band arrays: their count, then
    the pickle's length and each array's (one compiled format per count, not one per value)."""
    return struct.Struct(f"<I{arrays + 1}Q")


def _write_all(fd: int, parts: list[Any]) -> None:
    """Write ``parts`` one after the other from the start of file ``fd``: one ``pwritev`` unless
    the kernel takes less (then again from there, so that a refusal comes with its own errno)."""
    pending = [view for view in (memoryview(part).cast("B") for part in parts) if view.nbytes]
    offset = 0
    while pending:
        done = os.pwritev(fd, pending[:IOV_MAX], offset)
        if not done:  # the kernel took nothing: as full as ENOSPC says (caught by _store_large)
            raise FileWriteError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        offset += done
        while pending and done >= pending[0].nbytes:
            done -= pending.pop(0).nbytes
        if done:
            pending[0] = pending[0][done:]


class ShmReader(ShmConnection):
    """The reader's end of a value channel (in the reader's process, on its input port): a value
    the writer's port stamped comes out as a :class:`~coco_core.stamps.Message` with that stamp, as
    from a connection inside one process, its source the channel's writing port."""

    __slots__ = ("origin",)

    def __init__(self, spec: ChannelSpec) -> None:
        super().__init__(spec)
        self.origin = spec.label.partition("->")[0]
        """The writing port (``component.port``): the source of every message of the channel."""

    def _large(self, index: int, size: int) -> memoryview | None:
        """A copy of item ``index``'s value from its own segment, in memory that is not zeroed first
        (the kernel's copy is the only pass over it); None when the writer overwrote the item
        meanwhile (its segment is gone, or was being replaced)."""
        try:
            fd = shm_open(large_name(self.ring.spec, index), write=False)
        except FileNotFoundError:
            return None
        try:
            data = np.empty(size, np.uint8).data
            return data if os.preadv(fd, [data], 0) == size else None
        finally:
            os.close(fd)

    def push(self, value: Any) -> None:
        raise CocoError(f"connection {self.ring.spec.label}: the reader's end cannot be written")

    def skip(self, count: int = 1) -> None:
        """Values taken but discarded unused count as dropped (the counting contract of Connection)."""
        self.ring.counters[READ] -= count

    def pop(self) -> Any:
        lock = self.ring.lock
        if lock is None:
            taken = self._take()
        else:
            with lock:
                taken = self._take()
        if taken is None:
            return EMPTY
        data, num, it, at = taken
        if not num:
            return _decode(data)
        return Message.crossed(_decode(data), at, num, self.origin, it)

    def _take(self) -> tuple[bytearray | memoryview, int, int, float] | None:
        """The next item's bytes and its message's number, iteration and time, as the policy picks
        it (the seqlock's reader side); None when there is none, or when the writer stopped in the
        middle of a slot (it died)."""
        ring = self.ring
        counters = ring.counters
        slots = ring.slots
        for _ in range(RETRIES):
            stored = counters[STORED]
            cursor = counters[CURSOR]
            if stored == cursor:
                return None
            if self.mode is BufferPolicy.DATA:
                index = stored - 1  # the newest, once
            elif stored - cursor > slots:
                index = stored - slots  # lapped by the writer: the oldest still in the ring
            else:
                index = cursor
            slot = index % slots
            words, word = ring.words, slot * ring.slot_words
            before = words[word + STAMP]
            if before != index + 1:  # being written, or already overwritten: look again
                continue
            size, large = words[word + LENGTH], words[word + LARGE]
            num, it, at = words[word + NUM], words[word + IT], ring.times[word + TIME]
            data: bytearray | memoryview | None
            if large:
                data = self._large(index, size)
                if data is None:
                    continue
            else:
                start = HEADER + slot * ring.stride + SLOT_HEADER
                data = bytearray(ring.bytes[start:start + size])  # one copy (slicing the mmap made two)
            if words[word + STAMP] != before:  # overwritten during the copy
                continue
            counters[CURSOR] = index + 1
            counters[READ] += 1
            if large:  # read: its segment is a spare now, its pages kept for a later value
                rename(large_name(ring.spec, index), spare_name(ring.spec, index))
            if self.mode is BufferPolicy.DATA:  # the item before, if skipped, will never be read either
                other = (index - 1) % slots * ring.slot_words
                if words[other + STAMP] == index and words[other + LARGE]:
                    unlink(large_name(ring.spec, index - 1))
            return data, num, it, at
        return None  # the writer stopped in the middle of a slot (it died): nothing to read


def _array(buffer: Any, dtype: str, shape: tuple[int, ...]) -> np.ndarray:
    """An array over ``buffer`` (the reader's copy of the slot), as :func:`_reduce_array` sent it."""
    return np.frombuffer(buffer, dtype).reshape(shape)


def _typed_array(buffer: Any, dtype: np.dtype, shape: tuple[int, ...]) -> np.ndarray:
    """An array of a dtype that its code does not describe whole (fields, datetimes, byte order):
    its bytes viewed as that dtype."""
    return np.frombuffer(buffer, np.uint8).view(dtype).reshape(shape)


def _reduce_array(array: np.ndarray) -> Any:
    """A contiguous array as its raw memory (out of band), its dtype's code and shape: numpy's own
    reduction pickles the dtype object, which costs most of a small sample's encoding. Only the
    built-in dtypes go by code; any other (a structured array's fields, datetime64, which no buffer
    may carry) goes as the dtype itself, over the array's bytes."""
    if array.flags.c_contiguous and not array.dtype.hasobject:
        dtype = array.dtype
        if dtype.isbuiltin == 1:
            return _array, (pickle.PickleBuffer(array),  # type: ignore[arg-type]  # an ndarray is a buffer
                            dtype.str, array.shape)
        return _typed_array, (pickle.PickleBuffer(array.reshape(-1).view(np.uint8)),  # type: ignore[arg-type]
                              dtype, array.shape)
    return array.__reduce_ex__(5)


_DISPATCH = {**copyreg.dispatch_table, np.ndarray: _reduce_array}


def _decode(data: bytearray | memoryview) -> Any:
    """A value from its slot's bytes: the pickle, then the arrays' memory, which the value's arrays
    keep using (they are writable, as the writer's were)."""
    table = _table(_COUNT.unpack_from(data)[0])  # one compiled format for the count and the lengths
    _, pickled, *lengths = table.unpack_from(data)
    view = memoryview(data)
    at = table.size + pickled
    parts = []
    for length in lengths:
        parts.append(view[at:at + length])
        at += length
    return pickle.loads(view[table.size:table.size + pickled], buffers=parts)


class ChannelStats(ShmConnection):
    """A read-only view of a channel's counters (for a process that holds neither end)."""

    __slots__ = ()

    def skip(self, count: int = 1) -> None:
        raise CocoError("a ChannelStats view cannot be read")

    def push(self, value: Any) -> None:
        raise CocoError("a ChannelStats view cannot be written")

    def pop(self) -> Any:
        raise CocoError("a ChannelStats view cannot be read")
