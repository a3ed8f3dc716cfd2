"""The control link between the launcher and one child process: small messages both ways.

A ``socketpair`` made by the launcher; the child inherits its end as a file descriptor. Messages are
dicts with a ``kind`` (``config``, ``built``, ``start``, ``stop``, ``profile``, ``call``, ...) sent
with :mod:`multiprocessing.connection`'s framing (``configured`` and ``run`` carry the start gate
across processes: :mod:`coco_core.lifecycle`). Data never goes this way: connections between
processes are shared-memory channels; this link carries only the life cycle, profiles, period
changes and operation calls.
"""

from __future__ import annotations

import os
import socket
import threading
from multiprocessing.connection import Connection
from typing import Any, Callable

from ..errors import ConnectionClosedError


class ControlLink:
    """One end of a control link; ``send`` and ``request`` may be called from any thread. ``peer``
    names the other end in errors (``the launcher``, ``process haptics``)."""

    def __init__(self, fd: int, peer: str) -> None:
        self._connection = Connection(fd)
        self._lock = threading.Lock()
        self.peer = peer
        self._requests = threading.Lock()
        self._next = 0
        self._pending: dict[int, Callable[[dict[str, Any]], None]] = {}
        """What to do with the ``result`` of each request sent, by request id."""

    @classmethod
    def pair(cls, peer: str) -> tuple[ControlLink, int]:
        """The launcher's end, and the descriptor to hand to the child (inheritable)."""
        ours, theirs = socket.socketpair()
        fd = theirs.detach()
        os.set_inheritable(fd, True)
        return cls(ours.detach(), peer), fd

    def request(self, kind: str, done: Callable[[dict[str, Any]], None], **fields: Any) -> None:
        """Send a request; ``done(result message)`` runs when the other end answers it
        (:meth:`answered`), or with an error result when it is gone (:meth:`abandon`)."""
        with self._requests:
            self._next += 1
            ident = self._next
            self._pending[ident] = done
        if not self.send(kind, id=ident, **fields):
            with self._requests:
                self._pending.pop(ident, None)
            done(failed("ProcessError", f"{self.peer} is gone"))

    def answered(self, message: dict[str, Any]) -> None:
        """A ``result`` message arrived: run what its request asked for."""
        with self._requests:
            done = self._pending.pop(message["id"], None)
        if done is not None:
            done(message)

    def abandon(self, why: str) -> None:
        """The other end is gone: every request still waiting gets an error result saying ``why``."""
        with self._requests:
            orphans, self._pending = list(self._pending.values()), {}
        for done in orphans:
            done(failed("ProcessError", why))

    def send(self, kind: str, **fields: Any) -> bool:
        """Send a message; False when the other side is gone."""
        try:
            with self._lock:
                self._connection.send({"kind": kind, **fields})
            return True
        except (OSError, ValueError):
            return False

    def receive(self, timeout: float | None = None) -> dict[str, Any] | None:
        """The next message; None on timeout. Raises EOFError when the other side closed."""
        if timeout is not None and not self._connection.poll(timeout):
            return None
        try:
            message: dict[str, Any] = self._connection.recv()
        except OSError as error:
            raise ConnectionClosedError(str(error)) from None
        return message

    def close(self) -> None:
        self._connection.close()


def failed(type_name: str, message: str) -> dict[str, Any]:
    """A ``result`` message for a request that did not run."""
    return {"ok": False, "type": type_name, "message": message, "traceback": ""}
