"""Components of the channel tests (``test_process_channels.py``) and of ``bench/soak_channels.py``:
a writer of numbered values or frames whose payloads say their number, and a reader that checks each
payload and records what it got. The launcher and its child processes import them by
``module:Class`` (this folder is on their PYTHONPATH), so the same application runs in one process
or spread over several and the two runs can be compared value by value."""

from __future__ import annotations

import os
import signal
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np

from coco_core import NEW_DATA, OLD_DATA, Attribute, Component, InputPort, OutputPort, PooledOutputPort, Slot

RECORD = np.dtype([("number", "<i8"), ("time", "M8[ns]"), ("ratio", ">f4"), ("name", "U4")])
"""A structured dtype with a datetime, a byte-swapped float and text: what ``dtype.str`` cannot carry."""


def payload(kind: str, size: int, number: int) -> Any:
    """The value number ``number`` of a writer of ``kind`` with about ``size`` bytes of payload."""
    if kind == "int":
        return number
    if kind == "array":
        return np.full(max(1, size // 8), number, np.int64)
    if kind == "records":
        records = np.zeros(max(1, size // RECORD.itemsize), RECORD)
        records["number"] = number
        records["time"] = np.datetime64("2026-01-01T00:00:00", "ns") + np.timedelta64(number, "ms")
        records["ratio"] = number / 7
        records["name"] = f"n{number % 1000}"
        return {"records": records, "stamps": records["time"].copy()}
    raise ValueError(f"unknown payload kind {kind!r}: int, array or records")


def same(a: Any, b: Any) -> bool:
    """Whether two payloads are equal, arrays with their dtypes and shapes."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape and bool(np.array_equal(a, b))
    return bool(a == b)


class Source(Component):
    """Writes values 0 .. count-1, ``batch`` per update, then nothing; each is ``(number, payload)``.
    Once the last write returned it makes the file ``done`` (a connection counts a value as written
    before it stores it, so ``written`` alone does not say that the last one is in)."""

    count = Attribute(int, 100, "values to write")
    batch = Attribute(int, 1, "values per update")
    kind = Attribute(str, "int", "payload: int, array or records")
    size = Attribute(int, 0, "payload bytes (array, records)")
    done = Attribute(str, "", "file made once every value was written")
    out = OutputPort(object)

    def init(self) -> None:
        self.next = 0

    def on_update(self) -> None:
        for _ in range(min(self.batch, self.count - self.next)):
            self.out.write((self.next, payload(self.kind, self.size, self.next)))
            self.next += 1
            if self.next == self.count and self.done:
                Path(self.done).touch()


class FrameSource(Component):
    """Publishes frames 0 .. count-1 (int64 arrays of ``size`` bytes filled with their number),
    ``batch`` per update; a frame no free slot could take is tried again at the next update. At
    stop it writes its pool's slot states to ``path``."""

    count = Attribute(int, 100, "frames to publish")
    batch = Attribute(int, 1, "frames per update")
    size = Attribute(int, 64, "bytes per frame")
    path = Attribute(str, "", "where the slot states go at stop")
    done = Attribute(str, "", "file made once every frame was published")
    frames = PooledOutputPort()

    def init(self) -> None:
        self.next = 0

    def on_update(self) -> None:
        for _ in range(min(self.batch, self.count - self.next)):
            slot = self.frames.acquire((max(1, self.size // 8),), np.int64)
            if slot is None:
                return
            slot.array[:] = self.next
            slot.stamp = self.next
            self.frames.write(slot)
            self.next += 1
            if self.next == self.count and self.done:
                Path(self.done).touch()

    def on_stop(self) -> None:
        if self.path:
            states = " ".join(state.value for state in self.frames.pool.states())
            Path(self.path).write_text(f"slots {self.frames.pool.count}\nstates {states}\n")


class FrameSource8(FrameSource):
    """A frame source whose pool has 8 slots."""

    frames = PooledOutputPort(slots=8)


class _Reader(Component):
    """Reads its ``value`` input by ``mode`` (read, read_all, read_newest), checks every payload and,
    once it got the last value (or, as a BUFFER may refuse that one, once the writer is done:
    ``source_done`` exists, and nothing is pending), releases what it holds and writes ``path``: the
    numbers it got, one a line, then ``old``, ``bad``, and (with ``watch``) the launch's /dev/shm
    bytes at the end, once everything was read."""

    count = Attribute(int, 100, "values the writer writes")
    mode = Attribute(str, "read_all", "read, read_all or read_newest")
    kind = Attribute(str, "int", "the writer's payload kind (frames: frame)")
    size = Attribute(int, 0, "the writer's payload bytes")
    hold = Attribute(int, 0, "frames held before the oldest is released")
    path = Attribute(str, "reader.txt", "where the result goes")
    watch = Attribute(bool, False, "record the launch's /dev/shm use once everything was read")
    die = Attribute(bool, False, "kill this process (SIGKILL) once done")
    source_done = Attribute(str, "", "the file the writer makes once it wrote everything")

    def init(self) -> None:
        self.got: list[int] = []
        self.old = self.bad = self.shm = 0
        self.held: deque[Slot] = deque()
        self.done = False

    def on_update(self) -> None:
        if self.done:
            return
        port = self.port("value")
        assert isinstance(port, InputPort)
        if self.mode == "read_all":
            values = port.read_all()
        else:
            status, value = port.read() if self.mode == "read" else port.read_newest()
            values = [value] if status is NEW_DATA else []
            self.old += status is OLD_DATA
        for value in values:
            self._check(value)
        connection = port.connections[0]
        last = bool(self.got) and self.got[-1] == self.count - 1
        if last or (connection.written == self.count and Path(self.source_done).exists() and not connection.pending):
            self._finish()

    def _check(self, value: Any) -> None:
        if isinstance(value, Slot):
            number = int(value.stamp)
            self.bad += not (value.array.shape == (max(1, self.size // 8),) and bool((value.array == number).all()))
            self.held.append(value)
            while len(self.held) > self.hold:
                self.held.popleft().release()
        else:
            number, data = value
            self.bad += not same(data, payload(self.kind, self.size, number))
        self.got.append(number)

    def _finish(self) -> None:
        while self.held:
            self.held.popleft().release()
        self.done = True
        if self.watch:  # the launcher's pid names the launch's segments
            in_child = self.activity is not None and self.activity.process
            self.shm = shm_bytes(os.getppid() if in_child else os.getpid())
        lines = [str(number) for number in self.got] + [f"old {self.old}", f"bad {self.bad}", f"shm {self.shm}"]
        Path(self.path).write_text("\n".join(lines) + "\n")
        if self.die:
            os.kill(os.getpid(), signal.SIGKILL)


class Reader(_Reader):
    """A reader whose event input is declared on the class."""

    value = InputPort(object, event=True)


class LateReader(_Reader):
    """A reader whose event input is made in ``init()`` (as coco_ros's interface makes its inputs)."""

    def init(self) -> None:
        super().init()
        self.add_input("value", object, event=True)


def shm_bytes(launcher: int) -> int:
    """Bytes in /dev/shm of the launch of ``launcher`` (its segments start with the launcher's pid)."""
    prefix = f"coco.{launcher}-"
    total = 0
    with os.scandir("/dev/shm") as entries:
        for entry in entries:
            if entry.name.startswith(prefix):
                try:
                    total += entry.stat().st_blocks * 512
                except FileNotFoundError:
                    pass
    return total
