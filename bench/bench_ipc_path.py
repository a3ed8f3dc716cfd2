"""Where the time goes between a write in one process and the reader's ``on_update`` in another.

One small sample (the 19-joint sample of ``bench_ipc.py``), 1,000 a second, from an output port in this
process to an event input port of a triggered activity in a child process, over the process level's
shared-memory channel (a BUFFER ring; the writer wakes the reader's activity through its eventfd, as
:func:`coco_core.processes.channels.attach` wires it). Each step of each sample's trip is stamped with
``time.perf_counter_ns`` (CLOCK_MONOTONIC, which both processes share):

writer (this process)                         reader (the child)
  1. ``port.write`` entered                     4. ``eventfd_read`` returned (blocking reader only)
  2. ring push done (the value and its stamp    5. the activity's cycle entered
     in the ring: encode + store)               6. ``on_update`` entered
  3. eventfd write done (``port.write``         7. ring pop done (``port.read`` returned the value:
     returned)                                     load + decode)

The stamps come from the production path itself, not from a copy of it: 1 and 3 around the real
``OutputPort.write``, 2 in the channel's ``trigger`` (the real waker, called through a function that
stamps first), 4 to 7 from bench subclasses (a driver, an activity, a reader) that stamp and then
call the production method; ``on_update`` is the bench component's own. The *polling* reader is an
activity that cycles without sleeping (its thread spins through ``cycle``; the writer wakes nobody):
the channel's own cost without the kernel's wake-up of a sleeping reader.

Anchors in the same run (``bench_ipc.py``'s): Eclipse iceoryx2's ``Listener.blocking_wait`` and polling
receivers, and the bare CoCo ring (``ShmWriter.push`` -> ``ShmReader.pop``, no port, no activity).

    .venv/bin/python bench/bench_ipc_path.py [--messages 2000] [--json PATH]
"""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
import threading
import time
from typing import Any

import _report
import numpy as np
from _table import Table, fmt_ratio, fmt_time_ns

import bench_ipc
from coco_core import NEW_DATA, Component, InputPort, OutputPort
from coco_core.activity import Activity
from coco_core.connections import EMPTY
from coco_core.drivers import ThreadDriver
from coco_core.shm import ShmReader

WARMUP = 100
WRITER_STEPS = ("write entered", "ring push done", "eventfd write done")
READER_STEPS = ("eventfd_read returned", "cycle entered", "on_update entered", "ring pop done")
ns = time.perf_counter_ns


class Source(Component):
    """The writing component: ``out`` carries (sample number, names, positions)."""

    out = OutputPort()


class Sink(Component):
    """The reading component: on each update, stamps its entry and the value's arrival by number."""

    sample = InputPort(event=True)

    def __init__(self, count: int) -> None:
        super().__init__("sink")
        self.stamps = np.zeros((count + 1, len(READER_STEPS)), np.int64)
        self.count = count
        self.done = threading.Event()

    def on_update(self) -> None:
        entered = ns()
        activity = self.activity
        reader = self.sample.connections[0]
        assert isinstance(activity, StampedActivity) and isinstance(reader, StampedReader)
        while True:  # one wake-up may stand for several writes (the eventfd counts them as one)
            status, value = self.sample.read()
            if status is not NEW_DATA:
                return
            number = value[0]
            self.stamps[number] = (activity.driver_woke, activity.entered, entered, reader.popped)
            if number >= self.count:
                self.done.set()


class StampedReader(ShmReader):
    """The production reader; stamps when a pop returned a value."""

    popped = 0

    def pop(self) -> Any:
        item = super().pop()
        if item is not EMPTY:
            self.popped = ns()
        return item


class StampedActivity(Activity):
    """The production activity; stamps the entry of each cycle."""

    entered = 0
    driver_woke = 0

    def cycle(self) -> None:
        self.entered = ns()
        super().cycle()


class StampedEventfdDriver(ThreadDriver):
    """A thread driver blocked in ``eventfd_read`` (the production loop), stamping its return."""

    def _triggered(self, activity: Activity) -> None:
        assert self.eventfd is not None and isinstance(activity, StampedActivity)
        read, fd = os.eventfd_read, self.eventfd
        while not activity.stopping:
            read(fd)
            activity.driver_woke = ns()
            if activity.stopping:
                break
            activity.cycle()


class PollingDriver(ThreadDriver):
    """Cycles the activity without sleeping: a reader that polls its port."""

    def _triggered(self, activity: Activity) -> None:
        while not activity.stopping:
            activity.cycle()


def receive(spec_hex: str, fd: int, count: int, blocking: bool) -> dict[str, Any]:
    """The reader's process: a triggered activity with one component on an event input port."""
    sink = Sink(count)
    reader = StampedReader(pickle.loads(bytes.fromhex(spec_hex)))
    sink.sample.add_connection(reader, True)
    activity = StampedActivity("reader", [sink])
    activity.drive_with(StampedEventfdDriver(fd) if blocking else PollingDriver())
    activity.start()
    print("ready", flush=True)
    deadline = time.monotonic() + 60 + count / 1000
    while not sink.done.wait(0.1):  # the last sample, or a finished writer with nothing left (drops)
        if (reader.writer_finished and not reader.pending) or time.monotonic() > deadline:
            break
    activity.stop()
    activity.driver.join(10)
    reader.close()
    return {"stamps": sink.stamps[1:].tolist()}


def run(count: int, blocking: bool) -> np.ndarray:
    """Stamps of every sample, one row each, columns WRITER_STEPS + READER_STEPS (0: not taken)."""
    from coco_core.policy import BufferPolicy, ConnectionPolicy
    from coco_core.processes.channels import _waker
    from coco_core.shm import Arena, ShmWriter

    arena = Arena(f"benchpath{os.getpid()}")
    fd = os.eventfd(0)
    try:
        spec = arena.channel(ConnectionPolicy(BufferPolicy.BUFFER, size=1024), "source.out->sink.sample")
        source = Source("source")
        writer = ShmWriter(spec)
        source.out.add_connection(writer)
        stamps = np.zeros((count + 1, len(WRITER_STEPS)), np.int64)
        number = 0
        if blocking:
            wake = _waker(fd, None, -1)

            def trigger() -> None:
                stamps[number, 1] = ns()
                wake()

            writer.trigger = trigger
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
        child = subprocess.Popen([sys.executable, __file__, "--receive", pickle.dumps(spec).hex(), str(fd), str(count),
                                  "blocking" if blocking else "polling"], stdout=subprocess.PIPE, text=True,
                                 env=env, pass_fds=(fd,))
        assert child.stdout is not None
        child.stdout.readline()  # "ready"
        positions = np.arange(19, dtype=np.float64)

        def send(now: float) -> None:
            nonlocal number
            number += 1
            stamps[number, 0] = ns()
            source.out.write((number, bench_ipc.NAMES, positions))
            stamps[number, 2] = ns()

        bench_ipc.paced(count, 1000.0, send)
        writer.writer_done()
        out, _ = child.communicate(timeout=120 + count / 1000)
        if not blocking:
            stamps[:, 1] = stamps[:, 2]  # no wake-up: the push is done when write returns
        reader = np.asarray(json.loads(out.strip().splitlines()[-1])["stamps"], np.int64)
        writer.close()
        return np.hstack([stamps[1:], reader])
    finally:
        arena.close()
        os.close(fd)


def steps(stamps: np.ndarray, blocking: bool) -> dict[str, dict[str, float]]:
    """p50/p99 of each step (the time from the stamp before) and of the whole trip, after WARMUP."""
    kept = stamps[WARMUP:]
    kept = kept[kept[:, 6] != 0]  # a sample the ring refused (full) never arrived: no reader stamps
    names = [*WRITER_STEPS, *READER_STEPS]
    order = list(range(len(names)))
    if not blocking:  # no eventfd: steps 2 and 3 coincide, nothing is read from the eventfd
        order = [0, 1, 4, 5, 6]
    result: dict[str, dict[str, float]] = {}
    for before, after in zip(order, order[1:]):
        delta = kept[:, after] - kept[:, before]
        result[f"{names[before]} -> {names[after]}"] = {"p50_ns": float(np.percentile(delta, 50)),
                                                          "p99_ns": float(np.percentile(delta, 99))}
    total = kept[:, 6] - kept[:, 0]
    result["one way: write entered -> value in on_update"] = {"p50_ns": float(np.percentile(total, 50)),
                                                                "p99_ns": float(np.percentile(total, 99))}
    return result


def main() -> None:
    parser = _report.parser("bench_ipc_path", __doc__.splitlines()[0])
    parser.add_argument("--messages", type=int, default=2000, help="samples per reader kind (1,000 a second)")
    args = parser.parse_args()
    count = args.messages
    results: dict[str, Any] = {}
    with _report.LoadMeter() as load:
        for kind, blocking in (("blocking", True), ("polling", False)):
            results[kind] = steps(run(count, blocking), blocking)
            print(kind, results[kind], flush=True)
        anchors = {"iceoryx2 blocking_wait": bench_ipc.run_iceoryx2(count, 1000.0, True),
                   "iceoryx2 polling": bench_ipc.run_iceoryx2(count, 1000.0, False),
                   "bare CoCo ring, eventfd (push -> pop)": bench_ipc.run_shm(count, 1000.0),
                   "bare CoCo ring, polling (push -> pop)": bench_ipc.run_shm_polling(count, 1000.0)}
    results["anchors"] = anchors
    results["others"] = load.others
    table = Table("A small sample's trip, write in one process -> on_update in another, per step (1,000/s)",
                  ["step", "blocking p50", "p99", "polling p50", "p99"])
    for name in results["blocking"]:
        poll = results["polling"].get(name)
        table.add(name, fmt_time_ns(results["blocking"][name]["p50_ns"]), fmt_time_ns(results["blocking"][name]["p99_ns"]),
                  fmt_time_ns(poll["p50_ns"]) if poll else "-", fmt_time_ns(poll["p99_ns"]) if poll else "-")
    for name in results["polling"]:
        if name not in results["blocking"]:
            table.add(name, "-", "-", fmt_time_ns(results["polling"][name]["p50_ns"]),
                      fmt_time_ns(results["polling"][name]["p99_ns"]))
    total = "one way: write entered -> value in on_update"
    for name, anchor in anchors.items():
        kind = "blocking" if ("blocking" in name or "eventfd" in name) else "polling"
        ours = results[kind][total]
        table.notes.append(f"{name}, same run: p50 {fmt_time_ns(anchor['p50_ns'])}, p99 {fmt_time_ns(anchor['p99_ns'])}; "
                           f"the {kind} CoCo path's one way is {fmt_ratio(ours['p50_ns'] / anchor['p50_ns'])} at p50, "
                           f"{fmt_ratio(ours['p99_ns'] / anchor['p99_ns'])} at p99")
    table.notes.append("polling: the cycle that finds a value mostly began before its push ended (a negative "
                       "'ring push done -> cycle entered'), so its 'on_update entered -> ring pop done' holds the "
                       "rest of the push as well as the pop, and any time the spinning thread lost its core")
    if load.others is not None:
        table.notes.append(f"other processes used {load.others:.0%} of the cores meanwhile (this bench's receivers, "
                           f"one of which spins, included)")
    _report.emit("bench_ipc_path", args, [table], results)


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--receive":
        print(json.dumps(receive(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5] == "blocking")),
              flush=True)
    else:
        main()
