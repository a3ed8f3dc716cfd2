"""DescriptorTrigger: a component's triggered activity woken when a file descriptor is readable.

A component that receives from outside the application (a ZeroMQ or a plain socket) would otherwise
poll it from a periodic activity: every message then waits half the period on average before it is
read, and the activity's thread spins before each deadline. Instead its triggered activity is woken by
the kernel: a thread of the component blocks in ``poll(2)`` (the interpreter lock released) on the
descriptors, wakes the activity (:meth:`Activity.wake <coco_core.activity.Activity.wake>`) when one
is readable, then waits until the component has taken what was there (:meth:`rearm`) before it polls
again. The reads stay in the activity's thread, with the component's ports and counters: this
thread only polls the descriptors, never reads them, so a socket that is not thread-safe (ZeroMQ's)
is still used by one thread.

Waiting for :meth:`rearm` is what keeps the thread from spinning: a descriptor stays readable until
the component reads it. A ZeroMQ socket's ``ZMQ_FD`` is readable when the socket's events may have
changed, and is reset when the socket's own thread reads until ``EAGAIN`` (ZeroMQ then processes
its commands): the component reads so before it rearms. A cycle that stops before it took
everything (a bound on one cycle's work) rearms with ``more=True``: the activity is woken again at
once, without polling, since the descriptor may not signal what is already waiting.
"""

from __future__ import annotations

import select
import threading
from typing import Callable, Sequence

from .wakeup import Wakeup


class DescriptorTrigger:
    """Wakes ``wake`` (a triggered activity's) each time one of ``descriptors`` becomes readable, once
    per :meth:`rearm`; from :meth:`start` until :meth:`close`."""

    def __init__(self, name: str, descriptors: Sequence[int], wake: Callable[[], None]) -> None:
        self._wake = wake
        self._poll = select.poll()
        for descriptor in descriptors:
            self._poll.register(descriptor, select.POLLIN)
        self._close = Wakeup.new()
        """Ends the poll at :meth:`close` (the descriptors are the component's, not to be closed here)."""
        self._poll.register(self._close.fd, select.POLLIN)
        self._armed = threading.Event()
        self._more = False
        self._closed = False
        self.wakes = 0
        """Wake-ups given to the activity (one per readable descriptor seen, or per ``more``)."""
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)

    def start(self) -> None:
        self._thread.start()

    def rearm(self, more: bool = False) -> None:
        """The component took what was readable (or, ``more``, it left some for another cycle): watch
        the descriptors again, or wake the activity again at once."""
        self._more = more
        self._armed.set()

    def close(self) -> None:
        """End the thread and wait for it; before the component closes the descriptors (a closed one
        would make the poll return at once, for ever). Once: a second call does nothing (its eventfd
        is released once, :class:`~coco_core.wakeup.Wakeup`)."""
        if self._closed:
            return
        self._closed = True
        self._close.wake()
        self._armed.set()
        if self._thread.is_alive():
            self._thread.join()
        self._close.close()

    def _loop(self) -> None:
        while not self._closed:
            if not self._more:
                self._poll.poll()  # blocks with the interpreter lock released
                if self._closed:
                    return
            self._armed.clear()  # before the wake-up: the cycle it starts may rearm at once
            self.wakes += 1
            self._wake()
            self._armed.wait()
