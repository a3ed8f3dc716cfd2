"""Ctrl-C and SIGTERM for a whole launch, from its first instant to its last.

The handlers are installed before anything is loaded, so a signal at any moment has one defined
effect, and none of them ever raises into the interrupted code (a library that swallows
``KeyboardInterrupt``, or a native thread torn down by an exception, cannot turn a Ctrl-C into
nothing or into an abort):

- before the application runs (the file is being read, components built, child processes started),
  the signal is recorded and the launch ends at the next step with exit status 128 + the signal
  number (130 for Ctrl-C, 143 for SIGTERM), having started nothing. While the application file is
  read (:meth:`LaunchSignals.loading`: the loader's own Python, which nothing swallows and no native
  thread shares) the signal ends the load at once: a file that takes long to read does not delay it;
- while it runs, the first Ctrl-C or SIGTERM stops it cleanly: every activity finishes its cycle and
  runs ``on_stop`` within a second, outputs are flushed, and the status is the application's own
  (0, or 1 for a failure);
- a second Ctrl-C during that stop does not interrupt the flushing: the stop, bounded by a second,
  completes, and then the launcher leaves at once (no waiting for other threads) with status 130;
- a signal after the launch finished (:meth:`LaunchSignals.finish`, while the interpreter exits)
  leaves at once with 128 + its number. Python gives the default action back to both signals as it
  tears itself down, so they would then kill the process (a status of -2 for its parent): the last
  thing the interpreter runs before (an ``atexit`` function) has them ignored (process-wide, native
  threads included; Python leaves an ignored signal ignored), and what comes in those last
  milliseconds is dropped, leaving the launch's own status.
"""

from __future__ import annotations

import atexit
import contextlib
import logging
import os
import signal
import sys
from collections.abc import Iterator
from typing import TYPE_CHECKING

from .errors import Interrupted

if TYPE_CHECKING:
    from .application import Application

log = logging.getLogger("coco")

INTERRUPTED = 128 + signal.SIGINT
"""The exit status of a launch ended by Ctrl-C before it ran, or left at once by a second Ctrl-C."""


class LaunchSignals:
    """The launcher's handling of SIGINT and SIGTERM (see the module's documentation)."""

    def __init__(self) -> None:
        self.app: Application | None = None
        self.received: list[int] = []
        self.forced = False
        """A second Ctrl-C came: leave as soon as the stop is done."""
        self.interrupting = False
        """Within :meth:`loading`: a signal raises :class:`Interrupted` where the load is."""
        self.finished = False
        """:meth:`finish` was called: a signal leaves at once."""

    def install(self) -> LaunchSignals:
        signal.signal(signal.SIGINT, self._handle)
        signal.signal(signal.SIGTERM, self._handle)
        _ignore_at_exit()
        return self

    def _handle(self, signum: int, _frame: object) -> None:
        self.received.append(signum)
        if self.finished:
            leave(128 + signum)
        if self.interrupting:
            self.interrupting = False  # one exception: a second signal must not interrupt its handling
            raise Interrupted(signum)
        app = self.app
        if app is None:
            return  # checked between the steps of the launch
        if app.stop_requested and signum == signal.SIGINT:
            self.forced = True
            print("coco: stopping (at most 1 s), then leaving at once", file=sys.stderr, flush=True)
        app.request_stop(f"received {signal.Signals(signum).name}", hard=True)

    def check(self) -> None:
        """Raise :class:`Interrupted` when a signal came before the application runs."""
        if self.received and self.app is None:
            raise Interrupted(self.received[0])

    def attach(self, app: Application) -> None:
        """From now on a signal stops ``app`` (after a last :meth:`check`)."""
        self.check()
        self.app = app

    @contextlib.contextmanager
    def loading(self) -> Iterator[None]:
        """A block in which a signal ends the launch at once, by raising :class:`Interrupted` where
        the code is: for reading the application file, which is plain Python of the loader's."""
        self.check()
        self.interrupting = True
        try:
            yield
        finally:
            self.interrupting = False

    def finish(self, status: int) -> int:
        """The launch returned ``status``: its exit status, 130 when a second Ctrl-C came after the
        launcher last looked; from now on a signal leaves at once (see the module)."""
        self.finished = True
        return INTERRUPTED if self.forced else status


_ignoring_registered = False


def _ignore_at_exit() -> None:
    """Register, once, the ignoring of SIGINT and SIGTERM as the last ``atexit`` function (they run
    in reverse order, so the first registered runs last), just before Python would give the signals
    their default action back."""
    global _ignoring_registered
    if not _ignoring_registered:
        atexit.register(_ignore)
        _ignoring_registered = True


def _ignore() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def leave(status: int) -> None:
    """Exit with ``status`` now, after flushing what Python buffers, without waiting for threads
    (a hung activity, rclpy's or Mesa's native threads) or running interpreter teardown."""
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)
