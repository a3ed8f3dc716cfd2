"""Walk a bag as a replay does, independent of where the messages go (ports, DDS, a test).

A *pass* covers ``[start, start + duration)`` of the bag, ``start = bag start + start_offset``.
Every pass begins with the latched messages logged before ``start`` (``/tf_static`` and other
transient-local topics, see :meth:`BagReader.latched`): a late subscriber of the recording would
have had them, so a replay from an offset, or the second pass of a loop, delivers them too, due at
once. Then the messages of the pass follow in log-time order, each due at its log time on the
:class:`PlaybackClock`.

Two ways to consume it:
- ``for played in player:`` blocks until each message is due (the CLI);
- ``player.poll()`` returns the messages due now, never blocking (a component's ``on_update``).

A damaged bag: the readable messages are replayed, then the :class:`BagError` (file and byte
offset) is recorded in :attr:`Player.errors` and passed once to ``on_error``; a loop goes on.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Iterator, Sequence
from typing import Callable, NamedTuple

from coco_core.errors import BagError, ReplayError, did_you_mean

from ..bag import BagMessage, BagReader
from .clock import PlaybackClock


class Played(NamedTuple):
    """One message to deliver: when (bag ns), what, and on which (remapped) topic."""

    due_time: int
    message: BagMessage
    topic: str
    latched: bool = False
    """Delivered at the start of a pass because a late subscriber would have had it."""


def parse_remaps(remaps: Iterable[str] | dict[str, str] | None) -> dict[str, str]:
    """``["/a:=/b", ...]`` (as ``ros2 bag play --remap``) -> ``{"/a": "/b"}``."""
    if remaps is None:
        return {}
    if isinstance(remaps, dict):
        return dict(remaps)
    result: dict[str, str] = {}
    for item in remaps:
        source, sep, target = item.partition(":=")
        if not sep or not source.strip() or not target.strip():
            raise ReplayError(f"expected a remapping like '/from:=/to', got {item!r}")
        result[source.strip()] = target.strip()
    return result


class Player:
    """Replay ``reader``'s messages; see the module docstring."""

    def __init__(
        self,
        reader: BagReader,
        rate: float = 1.0,
        start_offset: float = 0.0,
        duration: float | None = None,
        loop: bool = False,
        topics: Sequence[str] | None = None,
        remap: dict[str, str] | Iterable[str] | None = None,
        *,
        clock: PlaybackClock | None = None,
        on_error: Callable[[BagError], None] | None = None,
    ) -> None:
        self.reader = reader
        if start_offset < 0:
            raise ReplayError(f"start offset must be >= 0 s, got {start_offset}")
        if duration is not None and duration <= 0:
            raise ReplayError(f"duration must be > 0 s (None: to the end), got {duration}")
        self.topics = list(dict.fromkeys(topics)) if topics else list(reader.topics)
        for name in self.topics:
            if name not in reader.topics:
                raise BagError(reader.path, f"no topic {name!r} in the bag; {did_you_mean(name, reader.topics)}")
        self.remap = parse_remaps(remap)
        self.clock = clock or PlaybackClock(rate)
        self.loop = loop
        self.start_offset = start_offset
        self.duration = duration
        self.on_error = on_error
        self.errors: list[BagError] = []
        self.passes = 0
        """Passes begun so far."""
        self.delivered = 0
        self._stop = threading.Event()
        self._source: Iterator[Played] | None = None
        self._next: Played | None = None
        self._finished = False

    # -- the unpaced sequence --------------------------------------------------------------------
    def out_topic(self, topic: str) -> str:
        """The topic a bag topic is delivered on, after remapping."""
        return self.remap.get(topic, topic)

    @property
    def start_time(self) -> int:
        """Bag time (ns) where a pass begins."""
        return self.reader.start_time + int(round(self.start_offset * 1e9))

    @property
    def end_time(self) -> int:
        """Bag time (ns) where a pass ends (inclusive bound of the last message)."""
        if self.duration is None:
            return self.reader.end_time
        return min(self.reader.end_time, self.start_time + int(round(self.duration * 1e9)))

    def _pass(self, offset: float) -> Iterator[Played]:
        start = self.reader.start_time + int(round(offset * 1e9))
        end = None if self.duration is None else start + int(round(self.duration * 1e9))
        self.passes += 1
        self.clock.reset(start)
        for message in self.reader.latched(self.topics, before=start):
            yield Played(start, message, self.out_topic(message.topic), True)
        try:
            for message in self.reader.messages(self.topics, start=start, end=end):
                yield Played(message.log_time, message, self.out_topic(message.topic))
        except BagError as error:
            self._report(error)

    def _report(self, error: BagError) -> None:
        if any(str(e) == str(error) for e in self.errors):
            return
        self.errors.append(error)
        if self.on_error is not None:
            self.on_error(error)

    def _sequence(self, offset: float) -> Iterator[Played]:
        """Passes from ``offset`` (the first) then from ``start_offset`` (the loop's next ones)."""
        while True:
            empty = True
            for played in self._pass(offset):
                empty = False
                yield played
            if not self.loop or self._stop.is_set() or empty:
                return
            offset = self.start_offset

    def _peek(self) -> Played | None:
        if self._next is None and not self._finished:
            if self._source is None:
                self._source = self._sequence(self.start_offset)
            self._next = next(self._source, None)
            if self._next is None:
                self._finished = True
        return self._next

    def _take(self) -> Played:
        played = self._next
        assert played is not None
        self._next = None
        self.delivered += 1
        return played

    # -- consuming -------------------------------------------------------------------------------
    @property
    def finished(self) -> bool:
        """True once every message was delivered (never with ``loop``, unless stopped)."""
        return self._finished or self._stop.is_set()

    def poll(self, limit: int | None = None) -> list[Played]:
        """The messages due now (at most ``limit``); never blocks."""
        due: list[Played] = []
        while not self._stop.is_set() and (limit is None or len(due) < limit):
            played = self._peek()
            if played is None or not self.clock.release(played.due_time):
                break
            due.append(self._take())
        return due

    def __iter__(self) -> Iterator[Played]:
        return self.iterate()

    def iterate(self, idle: Callable[[], None] | None = None) -> Iterator[Played]:
        """Yield each message when it is due (blocking); ``idle`` is called while waiting."""
        while not self._stop.is_set():
            played = self._peek()
            if played is None:
                return
            if not self.clock.wait(played.due_time, self._stop, idle):
                return
            yield self._take()

    def next_delay(self) -> float | None:
        """Seconds until the next message is due (None when finished, ``inf`` while paused)."""
        played = self._peek()
        return None if played is None else self.clock.delay(played.due_time)

    # -- control ---------------------------------------------------------------------------------
    def stop(self) -> None:
        """End the replay; a blocked :meth:`iterate` returns within the clock's max sleep."""
        self._stop.set()

    def pause(self) -> None:
        self.clock.pause()

    def resume(self) -> None:
        self.clock.resume()

    def step(self, count: int = 1) -> None:
        """Deliver the next ``count`` messages now, then stay paused."""
        self.clock.step(count)

    def seek(self, offset: float) -> None:
        """Continue from ``offset`` seconds after the bag start (latched messages first again).

        Takes effect before the next message; call it from the thread that consumes the player.
        """
        if offset < 0:
            raise ReplayError(f"seek offset must be >= 0 s, got {offset}")
        self._next = None
        self._finished = False
        self._source = self._sequence(offset)

    def progress(self) -> tuple[float, float]:
        """(current time, end time) in seconds after the bag start."""
        begin = self.reader.start_time
        return (max(0, self.clock.now() - begin) / 1e9, (self.end_time - begin) / 1e9)
