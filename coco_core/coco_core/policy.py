"""The vocabulary of data flow: connection policies and read results.

Names follow the original CoCo and OROCOS RTT, so that application files and habits carry over:
a connection has a *buffering* policy (what happens to values the reader has not taken yet) and a
*sync* policy (how writer and reader threads are kept apart).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from .errors import PolicyError


class ReadStatus(enum.IntEnum):
    """Result of reading an input port, as CoCo's ``FlowStatus``.

    Ordered so that ``if status:`` means "a value came back" and ``status is NEW_DATA`` means it has
    not been seen before.
    """

    NO_DATA = 0
    OLD_DATA = 1
    NEW_DATA = 2


NO_DATA = ReadStatus.NO_DATA
OLD_DATA = ReadStatus.OLD_DATA
NEW_DATA = ReadStatus.NEW_DATA


class BufferPolicy(enum.Enum):
    """What a connection keeps for its reader."""

    DATA = "DATA"
    """Latest value only; a write overwrites what the reader has not taken."""
    BUFFER = "BUFFER"
    """Bounded FIFO; a write to a full buffer is dropped (the old data wins)."""
    CIRCULAR = "CIRCULAR"
    """Bounded FIFO; a write to a full buffer drops the oldest item (the new data wins)."""
    POOL = "POOL"
    """Latest value of a pooled output port: frames are handed over by reference, never copied."""


class SyncPolicy(enum.Enum):
    """How a connection protects its storage between the writer's and the reader's threads."""

    LOCKED = "LOCKED"
    """A mutex around every access: correct for any pair of threads."""
    LOCK_FREE = "LOCK_FREE"
    """No mutex: relies on the operations CPython performs atomically (one reference swap, deque
    append/popleft), which is sound because each connection has exactly one writer and one reader."""
    UNSYNC = "UNSYNC"
    """No protection at all; only valid when writer and reader run in the same activity."""


@dataclass(frozen=True)
class ConnectionPolicy:
    """Buffering, sync and size of one connection (``buffersize`` in the XML)."""

    data: BufferPolicy = BufferPolicy.DATA
    sync: SyncPolicy = SyncPolicy.LOCKED
    size: int = 1

    def __post_init__(self) -> None:
        if self.data in (BufferPolicy.BUFFER, BufferPolicy.CIRCULAR) and self.size < 1:
            raise PolicyError(f"a {self.data.value} connection needs a buffer size >= 1, got {self.size}")

    def __str__(self) -> str:
        sized = self.data in (BufferPolicy.BUFFER, BufferPolicy.CIRCULAR)
        return f"{self.data.value}/{self.sync.value}" + (f"[{self.size}]" if sized else "")
