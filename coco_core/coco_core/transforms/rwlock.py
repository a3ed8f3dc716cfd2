"""A readers-writer lock: many concurrent lookups, one writer at a time, writers not starved.

Re-entrant for readers: a thread that already reads (e.g. inside ``TransformGraph.reading()``) or
writes may read again without waiting, so it cannot deadlock against a writer queued in between.
"""

from __future__ import annotations

import threading
from contextlib import contextmanager
from typing import Iterator


class ReadWriteLock:
    """Readers share the lock; a waiting writer blocks new readers so updates are not starved."""

    def __init__(self) -> None:
        self._condition = threading.Condition(threading.Lock())
        self._readers = 0
        self._writer: int | None = None
        """Thread id of the writer holding the lock."""
        self._writers_waiting = 0
        self._local = threading.local()

    def _depth(self) -> int:
        return getattr(self._local, "depth", 0)

    @contextmanager
    def read(self) -> Iterator[None]:
        if self._depth() or self._writer == threading.get_ident():
            self._local.depth = self._depth() + 1  # already inside: never wait for queued writers
            try:
                yield
            finally:
                self._local.depth -= 1
            return
        with self._condition:
            while self._writer is not None or self._writers_waiting:
                self._condition.wait()
            self._readers += 1
        self._local.depth = 1
        try:
            yield
        finally:
            self._local.depth = 0
            with self._condition:
                self._readers -= 1
                if self._readers == 0:
                    self._condition.notify_all()

    @contextmanager
    def write(self) -> Iterator[None]:
        if self._depth():
            raise RuntimeError("a thread that reads the transformation graph cannot write it inside the read")
        me = threading.get_ident()
        if self._writer == me:  # nested write by the same thread
            yield
            return
        with self._condition:
            self._writers_waiting += 1
            while self._writer is not None or self._readers:
                self._condition.wait()
            self._writers_waiting -= 1
            self._writer = me
        try:
            yield
        finally:
            with self._condition:
                self._writer = None
                self._condition.notify_all()
