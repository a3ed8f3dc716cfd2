"""Where the ROS launcher runs an activity, in numbers: a wait set of its own, the executor, or a thread.

For each host and period (1 ms and 10 ms), one application runs for ``--seconds``: a periodic activity
(its period error, as the activity measures it: callback or spin exit minus deadline, and its
overruns) and a triggered activity woken 100 times per second by a thread outside the application
writing to its event port (the *wake latency*: that write to the cycle that reads it). Hosts:

- *wait set*: the launcher's default (``ExecutorHost``, ``wait_sets=True``): each activity's timer or
  guard condition waited on in an ``ActivityWaitSet`` of its own;
- *executor*: callback groups of the node's executor (``--executor-threads N``: here the
  MultiThreadedExecutor with one thread per activity and one more, as ``executor_threads`` says);
- *thread*: CoCo's own activity loop (``--threads``), what an activity below 5 ms gets.

To host a 1 ms activity by rclpy at all, the 5 ms rule (``coco_ros.deployment.THREAD_PERIOD``) is
switched off in the deployment plans made here: measuring why it exists is the point. Goal: none; this backs the
hosting rule in docs/ros.md.

    .venv/bin/python bench/bench_hosting.py [--seconds 10] [--json PATH] [--no-plot]
"""

from __future__ import annotations

import threading
import time
from typing import Any, Callable

import _report
from _ros import RosContext  # sets ROS_DOMAIN_ID before rclpy is imported
from _table import Table, fmt_ratio, fmt_time_ns

import numpy as np
from coco_core import Application, Component, InputPort, OutputPort, PeriodicActivity, TriggeredActivity
from coco_core.deployment import of_application
from coco_core.policy import BufferPolicy, ConnectionPolicy
from coco_ros.deployment import RosRules
from coco_ros.hosting import ExecutorHost, ExecutorThread
from rclpy.node import Node

HOSTS = ("wait set", "executor", "thread")
PERIODS_MS = (1, 10)
WRITES_HZ = 100.0


class Idle(Component):
    """A periodic component with nothing to do: the activity's period error is the host's."""


class Source(Component):
    """Written from a thread outside the application: each value is the write's perf_counter_ns."""

    out = OutputPort(int)


class Waker(Component):
    """Reads its event port when woken: the wake latency of every value."""

    stamps = InputPort(int, event=True)

    def init(self) -> None:
        self.latencies: list[int] = []

    def on_update(self) -> None:
        now = time.perf_counter_ns()
        self.latencies.extend(now - stamp for stamp in self.stamps.read_all())


def run(context: Any, host: str, period_ms: int, seconds: float) -> dict[str, Any]:
    """One application hosted by ``host`` for ``seconds``: the figures of the table's row."""
    app = Application(f"hosting_{host.replace(' ', '_')}_{period_ms}")
    periodic = PeriodicActivity("periodic", period_ms / 1e3)
    app.add(Idle("idle"), periodic)
    source = app.add(Source("source"))
    waker = app.add(Waker("waker"), TriggeredActivity("triggered"))
    app.connect("source.out", "waker.stamps", ConnectionPolicy(data=BufferPolicy.BUFFER, size=64))
    node = Node(app.name, context=context)
    # The 5 ms rule switched off (thread_period 0): rclpy hosts the 1 ms activity too.
    plan = of_application(app, RosRules(tuple(app.activities) if host == "thread" else (), wait_sets=host == "wait set",
                                         thread_period=0.0))
    rclpy_host = ExecutorHost(node, app, plan)
    executor = rclpy_host.create_executor(context=context)
    executor.add_node(node)
    spinner = ExecutorThread(executor)
    stop = threading.Event()

    def write() -> None:
        deadline = time.perf_counter()
        while not stop.is_set():
            deadline += 1.0 / WRITES_HZ
            time.sleep(max(0.0, deadline - time.perf_counter()))
            source.out.write(time.perf_counter_ns())

    writer = threading.Thread(target=write, name="writer")
    try:
        app.start()
        rclpy_host.start()
        spinner.start()
        writer.start()
        time.sleep(seconds)
    finally:
        stop.set()
        writer.join()
        clean = app.stop()
        spinner.stop()
        if clean:
            rclpy_host.close()
        node.destroy_node()
    error = periodic.stats.error_summary()
    wake = np.array(waker.latencies or [0])
    return {"cycles": periodic.stats.cycles, "overruns": periodic.stats.overruns,
            "error_p50_ns": error.p50 * 1e9 if error else float("nan"),
            "error_p99_ns": error.p99 * 1e9 if error else float("nan"),
            "wake_p50_ns": float(np.percentile(wake, 50)), "wake_p99_ns": float(np.percentile(wake, 99)),
            "wakes": len(waker.latencies), "clean": clean}


def table(results: dict[str, dict[str, Any]], seconds: float) -> Table:
    t = Table("Hosting an activity in the ROS launcher: period error and wake latency",
              ["host", "period", "cycles", "overruns", "period error p50", "p99", "wake latency p50", "p99",
               "wake p50 vs thread"])
    for period_ms in PERIODS_MS:
        thread = results[f"thread {period_ms} ms"]
        for host in HOSTS:
            row = results[f"{host} {period_ms} ms"]
            t.add(host, f"{period_ms} ms", row["cycles"], row["overruns"], fmt_time_ns(row["error_p50_ns"]),
                  fmt_time_ns(row["error_p99_ns"]), fmt_time_ns(row["wake_p50_ns"]), fmt_time_ns(row["wake_p99_ns"]),
                  fmt_ratio(row["wake_p50_ns"] / thread["wake_p50_ns"]))
    t.notes += [f"{seconds:g} s per row, one row after the other in this process; the periodic activity's error is "
                "its own measure (a timer callback's start, a thread's spin exit, minus the deadline); wake "
                f"latency: {WRITES_HZ:g} writes per second from a thread outside the application to the "
                "triggered activity's event port, to the cycle that reads each. The 5 ms rule was switched off "
                "so that rclpy hosts the 1 ms activity."]
    return t


def draw(results: dict[str, dict[str, Any]]) -> Callable[[Any], Any]:
    def figure(plt: Any) -> Any:
        fig, axes = plt.subplots(1, 2, figsize=(9, 3.4))
        for ax, key, title in ((axes[0], "error", "period error"), (axes[1], "wake", "wake latency")):
            labels = [f"{host}, {period} ms" for period in PERIODS_MS for host in HOSTS]
            rows = [results[f"{host} {period} ms"] for period in PERIODS_MS for host in HOSTS]
            y = np.arange(len(rows))
            ax.barh(y - 0.2, [r[f"{key}_p50_ns"] / 1e3 for r in rows], height=0.4, label="p50")
            ax.barh(y + 0.2, [r[f"{key}_p99_ns"] / 1e3 for r in rows], height=0.4, label="p99")
            ax.set_yticks(y, labels if ax is axes[0] else [""] * len(labels), fontsize=8)
            ax.invert_yaxis()
            ax.set_xlabel(f"{title} (us)")
            ax.set_title(title)
        axes[1].legend()
        fig.tight_layout()
        return fig

    return figure


def main() -> None:
    p = _report.parser("bench_hosting", __doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=10.0, help="seconds per row (default 10)")
    args = p.parse_args()
    results: dict[str, dict[str, Any]] = {}
    with RosContext() as context:
        for period_ms in PERIODS_MS:
            for host in HOSTS:
                print(f"  {host}, {period_ms} ms ...", flush=True)
                results[f"{host} {period_ms} ms"] = run(context, host, period_ms, args.seconds)
    _report.emit("bench_hosting", args, [table(results, args.seconds)], results)
    _report.save_plot(args, draw(results))


if __name__ == "__main__":
    main()
