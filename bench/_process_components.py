"""Components of ``bench_processes.py``, imported by ``module:Class`` in the launcher and in its
child processes (the benchmark puts this folder on PYTHONPATH)."""

from __future__ import annotations

import time

from coco_core import Attribute, Component, InputPort, OutputPort, Stamped


class Tick(Component):
    """Does nothing but run: the 1 kHz activity whose period error is measured."""

    def on_update(self) -> None:
        pass


class Burn(Component):
    """Pure-Python work that holds the GIL for ``work`` seconds per update."""

    work = Attribute(float, 0.01, "seconds of pure-Python work per update")

    def on_update(self) -> None:
        end = time.perf_counter() + self.work
        while time.perf_counter() < end:
            pass


class Ping(Component):
    """Writes the time of writing, one sample per update (the wake-up benchmark's writer)."""

    out = OutputPort(Stamped)

    def on_update(self) -> None:
        self.out.write(Stamped(time.perf_counter()))


class Pong(Component):
    """Records, on an event port, the time from each write to the start of the update it woke, and
    writes them to ``path`` at the stop (one number of nanoseconds per line)."""

    path = Attribute(str, "wakeups.txt", "where the wake-up latencies go")
    sample = InputPort(Stamped, event=True)

    def init(self) -> None:
        self.latencies: list[int] = []

    def on_update(self) -> None:
        now = time.perf_counter()
        for sample in self.sample.read_all():
            self.latencies.append(int((now - sample.value) * 1e9))

    def on_stop(self) -> None:
        with open(self.path, "w") as out:
            out.write("\n".join(map(str, self.latencies)) + "\n")
