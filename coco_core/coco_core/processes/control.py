"""The control link between the launcher and one child process: small messages both ways.

A ``socketpair`` made by the launcher; the child inherits its end as a file descriptor. Messages are
dicts with a ``kind`` (``config``, ``built``, ``start``, ``stop``, ``profile``, ``call``, ...) sent
with :mod:`multiprocessing.connection`'s framing. Data never goes this way: connections between
processes are shared-memory channels; this link carries only the life cycle, profiles, period
changes and operation calls.
"""

from __future__ import annotations

import socket
import threading
from multiprocessing.connection import Connection
from typing import Any


class ControlLink:
    """One end of a control link; ``send`` may be called from any thread."""

    def __init__(self, fd: int) -> None:
        self._connection = Connection(fd)
        self._lock = threading.Lock()

    @classmethod
    def pair(cls) -> tuple[ControlLink, int]:
        """The launcher's end, and the descriptor to hand to the child (inheritable)."""
        ours, theirs = socket.socketpair()
        fd = theirs.detach()
        import os

        os.set_inheritable(fd, True)
        return cls(ours.detach()), fd

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
            raise EOFError(str(error)) from None
        return message

    def close(self) -> None:
        self._connection.close()
