"""The mutex of a LOCKED connection: one token in a :class:`queue.SimpleQueue`.

Holding the mutex is holding the token: ``get()`` takes it, waiting while the other side holds it
(asleep on the queue's own lock, not spinning), and ``put_nowait(TOKEN)`` gives it back. That is a
binary semaphore, which is what :class:`threading.Lock` is too (not reentrant, not bound to the
thread that took it).

Why not :class:`threading.Lock`: a LOCKED round (a port's write and a read) takes the mutex twice,
and on CPython 3.11 ``Lock.acquire`` is a call whose arguments are parsed as a tuple and keywords,
which the interpreter cannot specialise: an acquire and release cost ~69 ns there against ~45 ns
for ``SimpleQueue.get`` and ``put_nowait``, which take theirs as a fast call. The ~50 ns a round
saved are a seventh of bench_ports's floor (issue 34: a LOCKED round within 1.5x of it). A
``SimpleQueue`` is thread-safe on a free-threaded build as well, where LOCK_FREE falls back to
LOCKED.
"""

from __future__ import annotations

from queue import SimpleQueue

TOKEN = True
"""What the mutex's queue holds while nobody holds the mutex."""


def mutex() -> SimpleQueue[bool]:
    """A new mutex, free."""
    free: SimpleQueue[bool] = SimpleQueue()
    free.put_nowait(TOKEN)
    return free
