"""An activity's wake-up across processes: one Linux eventfd, written by any process that holds it.

The launcher makes one eventfd for each activity that a write in another process wakes, and every
child inherits them all (:mod:`coco_core.processes.supervisor`). A :class:`Wakeup` is one process's
hold on such a descriptor. Why not the bare number: in the launcher, writes keep coming after its
activities ended, from threads that outlive them (the host level's receivers, a hung activity's
thread), and the supervisor closes the descriptors at the end of the launch. A write after the
close would fail, or, once the number is reused by a file opened after it, put 8 bytes into that
file (the profile, a bag). Here a write and the close exclude each other, and a write after the
close does nothing: nobody is left to wake.
"""

from __future__ import annotations

import os
import select
import threading


class Wakeup:
    """One eventfd (see the module): :meth:`wake` adds one to its counter, :meth:`wait` blocks until
    the counter is non-zero and takes it (the woken activity's thread, alone)."""

    __slots__ = ("_fd", "_lock")

    def __init__(self, fd: int) -> None:
        self._fd = fd
        self._lock = threading.Lock()

    @classmethod
    def new(cls) -> Wakeup:
        """A new eventfd, not inherited by the processes this one starts unless passed to them."""
        return cls(os.eventfd(0, os.EFD_CLOEXEC))

    @property
    def fd(self) -> int:
        """The descriptor's number, to pass to a child process (-1 once closed)."""
        return self._fd

    def wake(self) -> None:
        """Wake the activity (one more cycle); nothing once closed."""
        with self._lock:
            if self._fd >= 0:
                os.eventfd_write(self._fd, 1)

    @property
    def pending(self) -> bool:
        """Whether a wake-up waits, not taken yet (the counter is non-zero), without taking it."""
        with self._lock:
            return self._fd >= 0 and bool(select.select([self._fd], [], [], 0)[0])

    def wait(self) -> None:
        """Block until woken, and take every wake-up waiting (the counter back to zero). Outside the
        lock: the close comes after the woken activity's thread ended."""
        os.eventfd_read(self._fd)

    def close(self) -> None:
        """Release the descriptor; later wake-ups do nothing."""
        with self._lock:
            fd, self._fd = self._fd, -1
        if fd >= 0:
            os.close(fd)

    def __repr__(self) -> str:
        return f"<Wakeup eventfd {self._fd}>" if self._fd >= 0 else "<Wakeup closed>"
