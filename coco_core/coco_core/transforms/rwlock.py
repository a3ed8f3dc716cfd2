"""A readers-writer lock: many concurrent lookups, one writer at a time, writers not starved.

Re-entrant for readers: a thread that already reads (e.g. inside ``TransformGraph.reading()``) or
writes may read again without waiting, so it cannot deadlock against a writer queued in between.

It is on the path of every edge update and every lookup after a change, so ``read()`` and
``write()`` hand out one reusable guard object each (a class with ``__enter__``/``__exit__``, not a
generator context manager) and nobody is notified when nobody waits: an uncontended write costs two
short critical sections and no ``notify_all``.
"""

from __future__ import annotations

import threading
from threading import get_ident

from ..errors import UsageError


class ReadWriteLock:
    """Readers share the lock; a waiting writer blocks new readers so updates are not starved."""

    def __init__(self) -> None:
        self._mutex = threading.Lock()
        """The condition's lock, taken directly (``with lock._mutex``): a raw lock's context manager
        is C code, the condition's two Python frames more per section."""
        self._condition = threading.Condition(self._mutex)
        self._readers = 0
        self._writer: int | None = None
        """Thread id of the writer holding the lock."""
        self._write_depth = 0
        """Nested writes of the writer thread (only that thread touches it)."""
        self._writers_waiting = 0
        self._waiting = 0
        """Threads waiting on the condition (readers or writers): notify only when there are some."""
        self._local = threading.local()
        self._read_guard = _ReadGuard(self)
        self._write_guard = _WriteGuard(self)

    def read(self) -> _ReadGuard:
        """``with lock.read():`` shares the lock with other readers."""
        return self._read_guard

    def write(self) -> _WriteGuard:
        """``with lock.write():`` holds the lock alone (nested writes by the same thread are fine)."""
        return self._write_guard

    def _wait(self) -> None:
        self._waiting += 1
        try:
            self._condition.wait()
        finally:
            self._waiting -= 1


class _ReadGuard:
    __slots__ = ("lock",)

    def __init__(self, lock: ReadWriteLock) -> None:
        self.lock = lock

    def __enter__(self) -> None:
        lock = self.lock
        local = lock._local
        depth = getattr(local, "depth", 0)
        if depth or lock._writer == get_ident():
            local.depth = depth + 1  # already inside: never wait for queued writers
            return
        with lock._mutex:
            while lock._writer is not None or lock._writers_waiting:
                lock._wait()
            lock._readers += 1
        local.depth = 1
        local.counted = True

    def __exit__(self, *exc: object) -> None:
        lock = self.lock
        local = lock._local
        local.depth -= 1
        if local.depth or not getattr(local, "counted", False):
            return
        local.counted = False
        with lock._mutex:
            lock._readers -= 1
            if lock._readers == 0 and lock._waiting:
                lock._condition.notify_all()


class _WriteGuard:
    __slots__ = ("lock",)

    def __init__(self, lock: ReadWriteLock) -> None:
        self.lock = lock

    def __enter__(self) -> None:
        lock = self.lock
        if lock._readers and getattr(lock._local, "depth", 0):  # no reader at all: this thread is none
            raise UsageError("a thread that reads the transformation graph cannot write it inside the read")
        me = get_ident()
        if lock._writer == me:  # nested write by the same thread
            lock._write_depth += 1
            return
        with lock._mutex:
            if lock._writer is not None or lock._readers:
                lock._writers_waiting += 1
                try:
                    while lock._writer is not None or lock._readers:
                        lock._wait()
                finally:
                    lock._writers_waiting -= 1
            lock._writer = me
        lock._write_depth = 1

    def __exit__(self, *exc: object) -> None:
        lock = self.lock
        lock._write_depth -= 1
        if lock._write_depth:
            return
        with lock._mutex:
            lock._writer = None
            if lock._waiting:
                lock._condition.notify_all()
