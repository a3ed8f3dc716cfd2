"""Ctrl-C and SIGTERM for a whole launch, from its first instant to its last.

The handlers are installed before anything is loaded, so a signal at any moment has one defined
effect. A handler only records the signal: it takes no lock and runs no stop. Python runs handlers
in the main thread between two bytecodes, wherever that thread is, possibly inside the stop that the
first signal began, holding one of its locks (an activity's driver, the start gate): a handler that
stopped the application itself waited there for ever on a second signal (``ros2 launch`` sends
SIGINT, then SIGTERM). The stop runs instead in a thread of its own (:class:`SignalWatcher`), which
the interpreter's C-level handler wakes through ``signal.set_wakeup_fd`` once for every signal
delivered (so two quick Ctrl-C are two, where Python's handler may run once for both), and which
may wait for a lock like any other thread. The rules:

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
  a SIGTERM during the stop changes nothing (the stop is already bounded by a second);
- a signal after the launch finished (:meth:`LaunchSignals.finish`, while the interpreter exits)
  leaves at once with 128 + its number (130 when it is the second Ctrl-C). Python gives the default
  action back to both signals as it tears itself down, so they would then kill the process (a
  status of -2 for its parent): the last thing the interpreter runs before (an ``atexit`` function)
  has them ignored (process-wide, native threads included; Python leaves an ignored signal
  ignored), and what comes in those last milliseconds is dropped, leaving the launch's own status.
"""

from __future__ import annotations

import atexit
import contextlib
import logging
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterable, Iterator
from typing import TYPE_CHECKING

from .errors import Interrupted

if TYPE_CHECKING:
    from .application import Application

log = logging.getLogger("coco")

INTERRUPTED = 128 + signal.SIGINT
"""The exit status of a launch ended by Ctrl-C before it ran, or left at once by a second Ctrl-C."""

LOOK_AGAIN = 0
"""What :meth:`SignalWatcher.wake` passes for no signal: act on what was delivered and not acted on."""
SYNC_TIMEOUT = 0.5
"""Seconds the main thread waits for the watcher to have read the signals delivered before (it
reads them at once; the bound is for a watcher that is not running)."""


class SignalWatcher:
    """The thread that acts on a process's signals, outside any handler (see the module).

    ``signal.set_wakeup_fd`` has the interpreter's C-level handler write the number of every
    signal delivered to a pipe, at once, from whichever thread the kernel interrupted (the main
    thread may be inside a long native call); this thread reads the pipe and calls ``act(signum)``
    for each, in order. The C-level handler writes only for a signal that has a Python handler: the
    process keeps handlers that record. One watcher per process (:func:`signal_watcher`): the wakeup
    fd is process-wide."""

    def __init__(self) -> None:
        self.act: Callable[[int], None] = lambda signum: None
        self._read, self._write = os.pipe()
        os.set_blocking(self._write, False)  # what set_wakeup_fd asks: a full pipe drops a byte, never blocks
        self._thread = threading.Thread(target=self._loop, name="coco:signals", daemon=True)
        self._looked = 0
        """How many :data:`LOOK_AGAIN` the watcher has acted on (:meth:`sync` waits for one more)."""
        self._looking = threading.Condition()

    def watch(self, act: Callable[[int], None]) -> None:
        """Call ``act(signum)`` in the watcher's thread for every signal from now on (and
        ``act(LOOK_AGAIN)`` after :meth:`wake`). Call it from the main thread."""
        self.act = act
        if not self._thread.is_alive():
            signal.set_wakeup_fd(self._write, warn_on_full_buffer=False)
            self._thread.start()

    def wake(self) -> None:
        """Have ``act(LOOK_AGAIN)`` called (from any thread: one write, no lock)."""
        try:
            os.write(self._write, bytes([LOOK_AGAIN]))
        except BlockingIOError:  # full: the watcher has bytes to read, and looks again anyway
            pass

    def sync(self, timeout: float = SYNC_TIMEOUT) -> None:
        """Return once the watcher has read every signal delivered before the call (never from a
        signal handler: it waits on a lock). Why: the main thread's handlers run in the order of
        the signals' numbers, the watcher's in the order of their delivery, which decides a
        launch's first signal."""
        if not self._thread.is_alive():
            return
        with self._looking:
            seen = self._looked
        self.wake()
        with self._looking:
            self._looking.wait_for(lambda: self._looked > seen, timeout)

    def _loop(self) -> None:
        while True:
            for signum in os.read(self._read, 64):
                try:
                    self.act(signum)
                except Exception:  # a failed stop must not end the watching
                    log.exception("acting on signal %d failed", signum)
                if signum == LOOK_AGAIN:
                    with self._looking:
                        self._looked += 1
                        self._looking.notify_all()


_watcher: SignalWatcher | None = None


def signal_watcher() -> SignalWatcher:
    """The process's :class:`SignalWatcher` (made at the first call)."""
    global _watcher
    if _watcher is None:
        _watcher = SignalWatcher()
    return _watcher


class LaunchSignals:
    """The launcher's handling of SIGINT and SIGTERM (see the module's documentation)."""

    def __init__(self) -> None:
        self.app: Application | None = None
        self.received: list[int] = []
        """The signals the handler recorded, for the checks between the steps of the launch."""
        self.forced = False
        """A second Ctrl-C came: leave as soon as the stop is done."""
        self.interrupting = False
        """Within :meth:`loading`: a signal raises :class:`Interrupted` where the load is."""
        self.finished = False
        """:meth:`finish` was called: a signal leaves at once."""
        self._delivered: list[int] = []
        """Every signal delivered, in order, as the watcher read them (its thread only)."""
        self._acted = 0
        """How many of :attr:`_delivered` the watcher acted on (it acts once an application is attached)."""
        self._early = 0
        """How many of :attr:`received` came before :meth:`install` (no watcher saw them)."""
        self._watcher = signal_watcher()

    def install(self, early: Iterable[int] = ()) -> LaunchSignals:
        """Handle SIGINT and SIGTERM from now on; ``early``: signals the installed script recorded
        before (they count as received, first)."""
        self.received.extend(early)
        self._early = len(self.received)
        signal.signal(signal.SIGINT, self._handle)
        signal.signal(signal.SIGTERM, self._handle)
        self._watcher.watch(self._act)
        _ignore_at_exit()
        return self

    def _handle(self, signum: int, _frame: object) -> None:
        """Record the signal (the watcher, woken by the C-level handler, acts on it); within
        :meth:`loading`, end the load where it is. No lock, no stop: see the module."""
        self.received.append(signum)
        if self.interrupting:
            self.interrupting = False  # one exception: a second signal must not interrupt its handling
            raise Interrupted(signum)  # :meth:`loading` makes it the launch's first signal

    def _act(self, signum: int) -> None:
        """The watcher's thread: a signal was delivered (or :data:`LOOK_AGAIN`). After the launch
        finished, leave; while an application is attached, stop it; before, nothing (the main
        thread's :meth:`check` ends the launch at its next step)."""
        if signum != LOOK_AGAIN:
            self._delivered.append(signum)
        if self.finished and self._acted < len(self._delivered):
            leave(128 + self._delivered[self._acted])
        app = self.app
        while app is not None and self._acted < len(self._delivered):
            signum = self._delivered[self._acted]
            self._acted += 1
            self._stop(app, signum)

    def _stop(self, app: Application, signum: int) -> None:
        if app.stop_requested and signum == signal.SIGINT:
            self.forced = True  # before reading finished: finish() reads them the other way round
            if self.finished:
                leave(INTERRUPTED)
            print("coco: stopping (at most 1 s), then leaving at once", file=sys.stderr, flush=True)
        app.request_stop(f"received {signal.Signals(signum).name}", hard=True)

    def _first(self) -> int:
        """The launch's first signal (one was received; the main thread, never a handler). Python
        runs the handlers of signals that came while the main thread was in one native call in the
        order of their numbers (SIGINT before an earlier SIGTERM): the watcher's order of delivery
        says which came first, once it has read them all."""
        if self._early:
            return self.received[0]
        if len(self._delivered) < len(self.received):
            self._watcher.sync()
        return self._delivered[0] if self._delivered else self.received[0]

    def check(self) -> None:
        """Raise :class:`Interrupted` when a signal came before the application runs."""
        if self.received and self.app is None:
            raise Interrupted(self._first())

    def attach(self, app: Application) -> None:
        """From now on a signal stops ``app`` (after a last :meth:`check`); one delivered since that
        check, whose handler has not run yet, stops it too."""
        self.check()
        self.app = app
        self._watcher.wake()

    @contextlib.contextmanager
    def loading(self) -> Iterator[None]:
        """A block in which a signal ends the launch at once, by raising :class:`Interrupted` where
        the code is: for reading the application file, which is plain Python of the loader's."""
        self.check()
        self.interrupting = True
        try:
            yield
        except Interrupted:
            self.interrupting = False
            raise Interrupted(self._first()) from None  # the handler raised with the signal it ran for
        finally:
            self.interrupting = False

    def finish(self, status: int) -> int:
        """The launch returned ``status``: its exit status, 130 when a second Ctrl-C came after the
        launcher last looked; from now on a signal leaves at once (see the module)."""
        self.finished = True  # before reading forced: the watcher's _stop writes and reads them the other way round
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
