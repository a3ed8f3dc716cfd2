"""Value channels between processes: one writer process, one reader process, one ring of slots.

The ring lives in one shared-memory segment: a header of counters, then ``slots`` slots of a fixed
capacity. Each slot holds a *stamp* (the index of the item in it, plus one; zero while it is being
written), the length and the pickled value. Each counter has one writer, so no lock is needed:

- the writer process owns ``offered`` (values offered: the ``written`` counter of the profile) and
  ``stored`` (values placed in the ring);
- the reader process owns ``read`` and ``cursor`` (the index of the next item it takes).

The policies keep their in-process meaning:

- BUFFER: ``size`` slots; a value offered while ``size`` are pending is refused (dropped), so the
  writer never overwrites an unread slot;
- CIRCULAR: ``size`` slots; the writer always stores, overwriting the oldest item when the ring is
  full; a reader that was lapped skips to the oldest item still there, and what it skipped counts as
  dropped. A slot overwritten while it is being read is detected by its stamp changing during the
  copy (a sequence lock) and the read is retried;
- DATA: two slots, the reader always takes the newest item once (NEW, then nothing until the next).

``dropped`` is derived, as in-process: offered - read - pending. Values cross as pickles (protocol 5)
whose arrays are written out of band, straight from their memory into the slot (numpy arrays are not
first pickled into bytes); one larger than a slot goes to that slot's overflow segment. Frames do not go this way: a pooled
output's slots live in shared memory and are read in place (:mod:`coco_core.shm.frames`).

The stores are ordered payload, then stamp, then counter, and the loads the other way round; on
x86-64 (total store order) that is all the ordering needed. CPython does not expose memory fences,
so on weakly ordered CPUs (ARM) a torn read is possible in principle; the stamp check catches the
common case.
"""

from __future__ import annotations

import copyreg
import io
import pickle
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..connections import EMPTY, Connection
from ..errors import ChannelError, CocoError
from ..policy import BufferPolicy, ConnectionPolicy
from .segment import Segment, unlink

HEADER = 64
OFFERED, STORED, READ, CURSOR, SLOTS, CAPACITY = range(6)
SLOT_HEADER = 32
"""Per slot: stamp, length, overflow generation (0: the value is in the slot), unused."""
RETRIES = 10_000
"""Reads of a slot that keeps changing before the reader gives up for this call (a writer that died
half-way through a slot would otherwise keep it spinning)."""
DEFAULT_CAPACITY = 4 * 1024
"""Bytes of one slot (larger values go to the slot's overflow segment)."""


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


def overflow_name(spec: ChannelSpec, index: int, generation: int) -> str:
    """The segment of slot ``index``'s large values, generation ``generation``."""
    return f"{spec.segment}.o{index}.g{generation}"


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
        self.words = self.segment.view[HEADER:].cast("q")
        """The ring as 64-bit words: slot ``i``'s header starts at word ``i * stride // 8``, so headers
        are read and written without making a view per access."""
        self.slot_words = self.stride // 8

    def close(self) -> None:
        self.counters.release()
        self.words.release()
        self.segment.close()


class ShmConnection(Connection):
    """What both ends share: the counters in shared memory, read as the profile reads any connection."""

    __slots__ = ("ring", "mode")

    def __init__(self, spec: ChannelSpec) -> None:  # noqa: D107 - the counters are properties here
        self.policy = spec.policy
        self.source = None
        self.sink = None
        self.trigger = None
        self.ring = _Ring(spec)
        self.mode = spec.policy.data

    @property
    def written(self) -> int:  # type: ignore[override]  # the counter lives in shared memory
        return int(self.ring.counters[OFFERED])

    @property
    def read(self) -> int:  # type: ignore[override]  # the counter lives in shared memory
        return int(self.ring.counters[READ])

    @property
    def pending(self) -> int:
        counters = self.ring.counters
        waiting = counters[STORED] - counters[CURSOR]
        if self.mode is BufferPolicy.DATA:
            return 1 if waiting > 0 else 0
        return min(waiting, self.ring.slots)

    @property
    def label(self) -> str:
        source, _, sink = self.ring.spec.label.partition("->")
        return f"{source} -> {sink}"

    def close(self) -> None:
        self.ring.close()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.ring.spec.label} {self.policy}>"


class ShmWriter(ShmConnection):
    """The writer's end of a value channel (in the writer's process, on its output port).

    A value larger than a slot goes into the slot's *overflow* segment, made (or made larger, as a
    new generation) when a value first needs it: a camera image on a plain output port crosses too,
    at the price of one copy each way; frames without copies are what pooled outputs are for."""

    __slots__ = ("_overflows",)

    def __init__(self, spec: ChannelSpec) -> None:
        super().__init__(spec)
        self._overflows: dict[int, tuple[int, Segment]] = {}
        """slot -> (generation, segment) of its overflow segment."""

    def _overflow(self, index: int, size: int) -> int:
        """The generation of slot ``index``'s overflow segment, made large enough for ``size`` bytes."""
        generation, segment = self._overflows.get(index, (0, None))
        if segment is None or segment.size < size:
            if segment is not None:
                segment.close()
                unlink(overflow_name(self.ring.spec, index, generation))
            generation += 1
            segment = Segment(overflow_name(self.ring.spec, index, generation), 1 << (size - 1).bit_length())
            self._overflows[index] = (generation, segment)
        return generation

    def push(self, value: Any) -> None:
        ring = self.ring
        counters = ring.counters
        buffers: list[pickle.PickleBuffer] = []
        try:
            out = io.BytesIO()
            pickler = pickle.Pickler(out, 5, buffer_callback=buffers.append)
            pickler.dispatch_table = _DISPATCH
            pickler.dump(value)
            data = out.getvalue()
            raws = [buffer.raw() for buffer in buffers]
        except Exception as error:
            raise ChannelError(f"connection {ring.spec.label}: {type(value).__name__} value cannot be sent to "
                               f"another process: {error}") from None
        table = struct.pack(f"<I{len(raws) + 1}Q", len(raws), len(data), *(raw.nbytes for raw in raws))
        size = len(table) + len(data) + sum(raw.nbytes for raw in raws)
        counters[OFFERED] += 1
        stored = counters[STORED]
        if self.mode is BufferPolicy.BUFFER and stored - counters[CURSOR] >= ring.slots:
            return  # full: the new value is refused, as an in-process BUFFER refuses it
        index = stored % ring.slots
        words, word = ring.words, index * ring.slot_words
        words[word] = 0  # being written: a reader of this slot retries
        words[word + 1] = size
        if size <= ring.capacity:
            words[word + 2] = 0
            target, at = ring.map, HEADER + index * ring.stride + SLOT_HEADER
        else:  # a large value (a camera image on a plain port): the slot's overflow segment holds it
            words[word + 2] = self._overflow(index, size)
            target, at = self._overflows[index][1].map, 0
        target[at:at + len(table)] = table
        at += len(table)
        target[at:at + len(data)] = data
        at += len(data)
        for raw in raws:  # arrays go from their own memory into the slot: one copy
            target[at:at + raw.nbytes] = raw
            at += raw.nbytes
        words[word] = stored + 1
        counters[STORED] = stored + 1
        trigger = self.trigger
        if trigger is not None:
            trigger()

    def pop(self) -> Any:
        raise CocoError(f"connection {self.ring.spec.label}: the writer's end cannot be read")


class ShmReader(ShmConnection):
    """The reader's end of a value channel (in the reader's process, on its input port)."""

    __slots__ = ("_overflows",)

    def __init__(self, spec: ChannelSpec) -> None:
        super().__init__(spec)
        self._overflows: dict[int, tuple[int, Segment]] = {}

    def _large(self, index: int, generation: int, size: int) -> bytearray | None:
        """The bytes of a large value in slot ``index``'s overflow segment; None when the writer
        replaced that segment meanwhile (the value was overwritten)."""
        known = self._overflows.get(index)
        if known is None or known[0] != generation:
            if known is not None:
                known[1].close()
            try:
                known = self._overflows[index] = (generation, Segment(overflow_name(self.ring.spec, index, generation)))
            except FileNotFoundError:
                return None
        return bytearray(known[1].view[:size])

    def push(self, value: Any) -> None:
        raise CocoError(f"connection {self.ring.spec.label}: the reader's end cannot be written")

    def skip(self, count: int = 1) -> None:
        """Values taken but discarded unused count as dropped (the counting contract of Connection)."""
        self.ring.counters[READ] -= count

    def pop(self) -> Any:
        ring = self.ring
        counters = ring.counters
        slots = ring.slots
        for _ in range(RETRIES):
            stored = counters[STORED]
            cursor = counters[CURSOR]
            if stored == cursor:
                return EMPTY
            if self.mode is BufferPolicy.DATA:
                index = stored - 1  # the newest, once
            elif stored - cursor > slots:
                index = stored - slots  # lapped by the writer: the oldest still in the ring
            else:
                index = cursor
            slot = index % slots
            words, word = ring.words, slot * ring.slot_words
            before = words[word]
            if before != index + 1:  # being written, or already overwritten: look again
                continue
            size, generation = words[word + 1], words[word + 2]
            if generation:
                large = self._large(slot, generation, size)
                if large is None:
                    continue
                data = large
            else:
                start = HEADER + slot * ring.stride + SLOT_HEADER
                data = bytearray(ring.map[start:start + size])
            if words[word] != before:  # overwritten during the copy
                continue
            counters[CURSOR] = index + 1
            counters[READ] += 1
            return _decode(data)
        return EMPTY  # the writer stopped in the middle of a slot (it died): nothing to read


def _array(buffer: Any, dtype: str, shape: tuple[int, ...]) -> np.ndarray:
    """An array over ``buffer`` (the reader's copy of the slot), as :func:`_reduce_array` sent it."""
    return np.frombuffer(buffer, dtype).reshape(shape)


def _reduce_array(array: np.ndarray) -> Any:
    """A contiguous array as its raw memory (out of band), its dtype's code and shape: numpy's own
    reduction pickles the dtype object, which costs most of a small sample's encoding."""
    if array.flags.c_contiguous and not array.dtype.hasobject:
        return _array, (pickle.PickleBuffer(array),  # type: ignore[arg-type]  # an ndarray is a buffer
                        array.dtype.str, array.shape)
    return array.__reduce_ex__(5)


_DISPATCH = {**copyreg.dispatch_table, np.ndarray: _reduce_array}


def _decode(data: bytearray) -> Any:
    """A value from its slot's bytes: the pickle, then the arrays' memory, which the value's arrays
    keep using (they are writable, as the writer's were)."""
    count = struct.unpack_from("<I", data)[0]
    lengths = struct.unpack_from(f"<{count + 1}Q", data, 4)
    view = memoryview(data)
    at = 4 + 8 * (count + 1)
    parts = []
    for length in lengths:
        parts.append(view[at:at + length])
        at += length
    return pickle.loads(parts[0], buffers=parts[1:])


class ChannelStats(ShmConnection):
    """A read-only view of a channel's counters (for a process that holds neither end)."""

    __slots__ = ()

    def push(self, value: Any) -> None:
        raise CocoError("a ChannelStats view cannot be written")

    def pop(self) -> Any:
        raise CocoError("a ChannelStats view cannot be read")
