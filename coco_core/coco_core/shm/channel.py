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

``dropped`` is derived, as in-process: offered - read - pending. Values cross as pickles (protocol 5);
a value larger than a slot is an error that names the connection and both sizes. Frames do not go
this way: a pooled output's slots live in shared memory (:mod:`coco_core.shm.frames`).

The stores are ordered payload, then stamp, then counter, and the loads the other way round; on
x86-64 (total store order) that is all the ordering needed. CPython does not expose memory fences,
so on weakly ordered CPUs (ARM) a torn read is possible in principle; the stamp check catches the
common case.
"""

from __future__ import annotations

import pickle
from dataclasses import dataclass
from typing import Any

from ..connections import EMPTY, Connection
from ..errors import CocoError
from ..policy import BufferPolicy, ConnectionPolicy
from .segment import Segment

HEADER = 64
OFFERED, STORED, READ, CURSOR, SLOTS, CAPACITY = range(6)
SLOT_HEADER = 16
RETRIES = 10_000
"""Reads of a slot that keeps changing before the reader gives up for this call (a writer that died
half-way through a slot would otherwise keep it spinning)."""
DEFAULT_CAPACITY = 64 * 1024
"""Bytes of one slot: generous, since shared memory is only backed where it is written."""


class ChannelError(CocoError):
    """A value that cannot cross the channel (too large, not picklable)."""


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
        self.view = self.segment.view

    def stamp_view(self, index: int) -> memoryview:
        offset = HEADER + (index % self.slots) * self.stride
        return self.view[offset:offset + SLOT_HEADER].cast("q")

    def close(self) -> None:
        self.counters.release()
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

    @property  # type: ignore[override]
    def written(self) -> int:
        return int(self.ring.counters[OFFERED])

    @property  # type: ignore[override]
    def read(self) -> int:
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
    """The writer's end of a value channel (in the writer's process, on its output port)."""

    __slots__ = ()

    def push(self, value: Any) -> None:
        ring = self.ring
        counters = ring.counters
        try:
            data = pickle.dumps(value, protocol=5)
        except Exception as error:
            raise ChannelError(f"connection {ring.spec.label}: {type(value).__name__} value cannot be sent to "
                               f"another process: {error}") from None
        size = len(data)
        if size > ring.capacity:
            raise ChannelError(f"connection {ring.spec.label}: a value of {size} bytes does not fit its slots of "
                               f"{ring.capacity} bytes (frames go through a pooled output, data=POOL)")
        counters[OFFERED] += 1
        stored = counters[STORED]
        if self.mode is BufferPolicy.BUFFER and stored - counters[CURSOR] >= ring.slots:
            return  # full: the new value is refused, as an in-process BUFFER refuses it
        offset = HEADER + (stored % ring.slots) * ring.stride
        stamp = ring.view[offset:offset + SLOT_HEADER].cast("q")
        stamp[0] = 0  # being written: a reader of this slot retries
        stamp[1] = size
        ring.view[offset + SLOT_HEADER:offset + SLOT_HEADER + size] = data
        stamp[0] = stored + 1
        stamp.release()
        counters[STORED] = stored + 1
        trigger = self.trigger
        if trigger is not None:
            trigger()

    def pop(self) -> Any:
        raise CocoError(f"connection {self.ring.spec.label}: the writer's end cannot be read")


class ShmReader(ShmConnection):
    """The reader's end of a value channel (in the reader's process, on its input port)."""

    __slots__ = ()

    def push(self, value: Any) -> None:
        raise CocoError(f"connection {self.ring.spec.label}: the reader's end cannot be written")

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
            offset = HEADER + (index % slots) * ring.stride
            stamp = ring.view[offset:offset + SLOT_HEADER].cast("q")
            before = stamp[0]
            if before != index + 1:  # being written, or already overwritten: look again
                stamp.release()
                continue
            size = stamp[1]
            data = bytes(ring.view[offset + SLOT_HEADER:offset + SLOT_HEADER + size])
            after = stamp[0]
            stamp.release()
            if after != before:  # overwritten during the copy
                continue
            counters[CURSOR] = index + 1
            counters[READ] += 1
            return pickle.loads(data)
        return EMPTY  # the writer stopped in the middle of a slot (it died): nothing to read


class ChannelStats(ShmConnection):
    """A read-only view of a channel's counters (for a process that holds neither end)."""

    __slots__ = ()

    def push(self, value: Any) -> None:
        raise CocoError("a ChannelStats view cannot be written")

    def pop(self) -> Any:
        raise CocoError("a ChannelStats view cannot be read")
