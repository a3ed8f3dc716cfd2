"""Components for the process-level tests: each child process imports them by ``module:Class``
(the tests put this folder on PYTHONPATH), so they run in real child processes of the launcher."""

from __future__ import annotations

import ctypes
import os
import signal
import threading
import time
from pathlib import Path

from coco_core import Attribute, Component, InputPort, OutputPort, Stamped, operation


class Ticker(Component):
    """Writes 0, 1, 2, ... stamped, one per update; records its pid in ``pid_file`` at config."""

    pid_file = Attribute(str, "", "where to write this process's pid")
    fault = Attribute(str, "", "after `fault_after` updates: `segfault`, `exit` or `raise_init` (at init)")
    fault_after = Attribute(int, 5, "updates before the fault")
    first_update_file = Attribute(str, "", "where to write the monotonic time of the first update")
    stop_after = Attribute(int, 0, "updates after which the application stops itself (0: never)")
    damage_at = Attribute(int, 0, "the update at which the ticker reports damaged input (0: never)")
    last_after = Attribute(float, 0.0, "seconds on_stop works before it writes a last value, -1 "
                           "(a component that flushes at its stop); 0: no last value")
    linger = Attribute(float, 0.0, "seconds a thread that on_stop leaves running keeps its process from "
                       "ending after the part stopped (a ROS child releasing its node); 0: none")
    out = OutputPort(Stamped)

    def init(self) -> None:
        if self.fault == "raise_init":
            raise RuntimeError("this component refuses to start")
        self.count = 0

    def on_config(self) -> None:
        if self.pid_file:
            Path(self.pid_file).write_text(str(os.getpid()))

    def on_update(self) -> None:
        if self.count == 0 and self.first_update_file:
            Path(self.first_update_file).write_text(repr(time.monotonic()))
        if self.stop_after and self.count == self.stop_after:
            if self.app is not None and not self.app.stop_requested:
                self.app.request_stop(f"{self.name}: {self.count} values written")
            return
        self.out.write(Stamped(self.count))
        self.count += 1
        if self.count == self.damage_at and self.app is not None:
            self.app.report_damage(f"{self.name}: value {self.count} was damaged")
        if self.fault and self.count == self.fault_after:
            if self.fault == "segfault":
                ctypes.string_at(0)
            elif self.fault == "exit":
                os._exit(3)
            elif self.fault == "kill":
                os.kill(os.getpid(), signal.SIGKILL)

    def on_stop(self) -> None:
        if self.last_after:
            time.sleep(self.last_after)
            self.out.write(Stamped(-1))
        if self.linger:  # not a daemon (as the activity thread is): the interpreter waits for it at the end
            threading.Thread(target=threading.Event().wait, args=(self.linger,), name="lingering", daemon=False).start()

    @operation
    def scale(self, factor: int) -> int:
        """Returns count * factor, in the component's own activity (and process)."""
        if factor < 0:
            raise ValueError(f"factor must not be negative, got {factor}")
        return self.count * factor


class Sink(Component):
    """Appends every value it reads to ``path`` (one line each) and records its pid and on_stop, and
    in ``threads_path`` (when set) the names of the threads that updated it."""

    path = Attribute(str, "sink.txt", "output file")
    threads_path = Attribute(str, "", "where to write the names of the threads that ran on_update")
    value = InputPort(Stamped, event=True)

    def on_config(self) -> None:
        self.file = open(self.path, "w")
        self.file.write(f"pid {os.getpid()}\n")
        self.file.flush()
        self.threads: set[str] = set()

    def on_update(self) -> None:
        self.threads.add(threading.current_thread().name)
        for sample in self.value.read_all():
            self.file.write(f"{sample.value}\n")

    def on_stop(self) -> None:
        for what in self.app.damage if self.app is not None else ():  # what a summary would report
            self.file.write(f"damage {what}\n")
        self.file.write("stopped\n")
        self.file.close()
        if self.threads_path:
            Path(self.threads_path).write_text("\n".join(sorted(self.threads)))


class SlowConfig(Component):
    """Takes ``delay`` seconds to configure (a model to load, a device to open), then writes the
    monotonic time at which it was done to ``path``."""

    delay = Attribute(float, 0.5, "seconds on_config takes")
    path = Attribute(str, "configured.txt", "where the end of on_config is written")

    def on_config(self) -> None:
        time.sleep(self.delay)
        Path(self.path).write_text(repr(time.monotonic()))


class Flusher(Component):
    """Counts the values it reads; its on_stop works ``flush_cpu`` CPU seconds (a video encoder's
    last frames) and then writes the count to ``path``: on a loaded machine that takes longer than a
    second of wall time."""

    flush_cpu = Attribute(float, 1.0, "CPU seconds of work in on_stop")
    path = Attribute(str, "flushed.txt", "where the count is written at the stop")
    value = InputPort(Stamped, event=True)

    def init(self) -> None:
        self.values: list[int] = []

    def on_update(self) -> None:
        self.values += [sample.value for sample in self.value.read_all()]

    def on_stop(self) -> None:
        self.values += [sample.value for sample in self.value.read_all()]
        end = time.thread_time() + self.flush_cpu
        while time.thread_time() < end:
            pass
        Path(self.path).write_text(" ".join(map(str, self.values)))


class Busy(Component):
    """Burns the CPU in pure Python for ``work`` seconds per update (holds the GIL)."""

    work = Attribute(float, 0.05, "seconds of pure-Python work per update")

    def on_update(self) -> None:
        end = time.perf_counter() + self.work
        while time.perf_counter() < end:
            pass


class Caller(Component):
    """Calls ``target``'s ``scale`` operation by name with ``factor`` once per update (and once with
    -1, which raises there), and writes each outcome to ``path``: ``ok <value>`` or
    ``error <type> <remote type>``."""

    target = Attribute(str, "ticker", "component whose operation is called")
    factor = Attribute(int, 2, "argument")
    path = Attribute(str, "calls.txt", "output file")

    def on_config(self) -> None:
        self.operation = self.find_operation(self.target, "scale")
        self.file = open(self.path, "w")

    def on_update(self) -> None:
        for factor in (self.factor, -1):
            self.operation.send(factor, callback=self._record)

    def _record(self, future) -> None:
        error = future.exception()
        if error is None:
            self.file.write(f"ok {future.result()}\n")
        else:
            self.file.write(f"error {type(error).__name__} {getattr(error, 'type_name', '')}\n")
        self.file.flush()

    def on_stop(self) -> None:
        self.file.close()


class CycleGarbage(Component):
    """Makes ``cycles`` reference cycles an update (garbage only the cyclic collector frees), and
    writes what its process did to the collector and its memory to ``path`` (JSON) at its first
    update and at the stop: whether automatic collection is on, the objects frozen, the memory
    locked (VmLck, kB), and the collector's young-generation count."""

    path = Attribute(str, "garbage.json", "output file")
    cycles = Attribute(int, 50, "reference cycles made per update")
    stop_after = Attribute(int, 0, "updates after which the application stops itself (0: never)")

    def on_config(self) -> None:
        self.count = 0
        self.states: list[dict[str, object]] = []

    def state(self) -> dict[str, object]:
        import gc

        locked = next((int(line.split()[1]) for line in Path("/proc/self/status").read_text().splitlines()
                       if line.startswith("VmLck:")), 0)
        return {"enabled": gc.isenabled(), "frozen": gc.get_freeze_count(), "locked_kb": locked,
                "young": gc.get_count()[0], "pid": os.getpid()}

    def on_update(self) -> None:
        if self.count == 0:
            self.states.append(self.state())
        for _ in range(self.cycles):
            loop: list[object] = []
            loop.append(loop)
        self.count += 1
        if self.stop_after and self.count == self.stop_after and self.app is not None:
            self.app.request_stop(f"{self.name}: {self.count} updates")

    def on_stop(self) -> None:
        import json

        self.states.append(self.state())
        Path(self.path).write_text(json.dumps(self.states))


class SchedulingProbe(Component):
    """Writes to ``path`` (JSON), at its first update, how the OS schedules the thread that runs it
    (class and real-time priority) and its process's interpreter switch interval; then stops the
    application when ``stop_after_probe`` is set."""

    path = Attribute(str, "scheduling.json", "output file")
    stop_after_probe = Attribute(bool, False, "stop the application after the first update")

    def on_config(self) -> None:
        self.done = False

    def on_update(self) -> None:
        import json
        import sys

        if self.done:
            return
        self.done = True
        policy = os.sched_getscheduler(0)  # 0: the calling thread on Linux
        Path(self.path).write_text(json.dumps({
            "fifo": policy == os.SCHED_FIFO, "priority": os.sched_getparam(0).sched_priority,
            "switch_interval": sys.getswitchinterval()}))
        if self.stop_after_probe and self.app is not None:
            self.app.request_stop(f"{self.name}: probed")
