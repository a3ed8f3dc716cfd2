"""The control link between the launcher and one child process: small messages both ways.

A ``socketpair`` made by the launcher; the child inherits its end as a file descriptor. Messages are
the typed messages of :mod:`.messages`, sent with :mod:`multiprocessing.connection`'s framing, and
both ends read them with one dispatcher, :meth:`ControlLink.serve`. Data never goes this way:
connections between processes are shared-memory channels; this link carries only the life cycle
(the start gate across processes: :mod:`coco_core.lifecycle`), profiles, period changes, damage
and operation calls.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import socket
import threading
from multiprocessing.connection import Connection
from typing import Any, Callable, Mapping

from ..errors import ConnectionClosedError
from ..messages import Message, Outcome, Request, Result

log = logging.getLogger("coco")

Handlers = Mapping[type, Callable[[Any], object]]
"""Message type -> what to do with a message of that type (see :meth:`ControlLink.serve`)."""


class ControlLink:
    """One end of a control link; ``send`` and ``request`` may be called from any thread. ``peer``
    names the other end in errors (``the launcher``, ``process haptics``)."""

    def __init__(self, fd: int, peer: str) -> None:
        self._connection = Connection(fd)
        self._lock = threading.Lock()
        self.peer = peer
        self._requests = threading.Lock()
        self._next = 0
        self._pending: dict[int, Callable[[Outcome], None]] = {}
        """What to do with the ``result`` of each request sent, by request id."""
        self.unexpected = 0
        """Messages of a type the protocol does not send this way (each logged)."""

    @classmethod
    def pair(cls, peer: str) -> tuple[ControlLink, int]:
        """The launcher's end, and the descriptor to hand to the child (inheritable)."""
        ours, theirs = socket.socketpair()
        fd = theirs.detach()
        os.set_inheritable(fd, True)
        return cls(ours.detach(), peer), fd

    def request(self, message: Request, done: Callable[[Outcome], None]) -> None:
        """Send a request; ``done(outcome)`` runs when the other end answers it (a :class:`Result`
        that :meth:`serve` hands to :meth:`answered`), or with a failure when it is gone
        (:meth:`abandon`)."""
        with self._requests:
            self._next += 1
            ident = self._next
            self._pending[ident] = done
        if not self.send(dataclasses.replace(message, id=ident)):
            with self._requests:
                self._pending.pop(ident, None)
            done(Outcome.failure("ProcessError", f"{self.peer} is gone"))

    def answer(self, request: Request, outcome: Outcome) -> bool:
        """Send the answer to ``request``; False when the other side is gone."""
        return self.send(Result(request.id, outcome))

    def answered(self, result: Result) -> None:
        """A :class:`Result` arrived: run what its request asked for."""
        with self._requests:
            done = self._pending.pop(result.id, None)
        if done is not None:
            done(result.outcome)

    def abandon(self, why: str) -> None:
        """The other end is gone: every request still waiting gets a failure saying ``why``."""
        with self._requests:
            orphans, self._pending = list(self._pending.values()), {}
        for done in orphans:
            done(Outcome.failure("ProcessError", why))

    def send(self, message: Message) -> bool:
        """Send a message; False when the other side is gone."""
        try:
            with self._lock:
                self._connection.send(message)
            return True
        except (OSError, ValueError):
            return False

    def receive(self, timeout: float | None = None) -> Message | None:
        """The next message; None on timeout. Raises EOFError when the other side closed."""
        if timeout is not None and not self._connection.poll(timeout):
            return None
        try:
            message: Message = self._connection.recv()
        except OSError as error:
            raise ConnectionClosedError(str(error)) from None
        return message

    def serve(self, handlers: Handlers, until: tuple[type[Message], ...] = ()) -> Message | None:
        """The one dispatcher of both ends: read messages and run the handler of each one's type,
        until a message of a type in ``until`` (returned, after its handler if it has one) or the
        other side closes the link (None). Results go to the requests that wait for them; any other
        message without a handler here is counted (:attr:`unexpected`) and logged (the protocol does
        not send it this way)."""
        while True:
            try:
                message = self.receive()
            except EOFError:
                return None
            assert message is not None  # no timeout: a message, or the end of the link
            if isinstance(message, Result):
                self.answered(message)
                continue
            handler = handlers.get(type(message))
            if handler is not None:
                handler(message)
            elif not isinstance(message, until):
                self.refuse(message)
            if isinstance(message, until):
                return message

    def refuse(self, message: Message) -> None:
        """A message that the protocol does not send this way: counted and logged, never silent."""
        self.unexpected += 1
        log.error("control link with %s: unexpected %r (%d so far)", self.peer, message, self.unexpected)

    def close(self) -> None:
        self._connection.close()

