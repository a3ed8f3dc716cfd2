"""Figure 3: period error of a 1 kHz CoCo PeriodicActivity against a 1 kHz rclpy timer.

The *error* of one cycle is the time its callback starts minus the deadline the scheduler set for
it, both on CLOCK_MONOTONIC (``time.perf_counter_ns``), so a late cycle counts as late instead of
being matched to a later grid point:
- CoCo (``PeriodicActivity``): the grid starts when the loop starts (taken at the end of
  ``on_config``, just before); the deadlines are replayed with the activity's rule (after a cycle
  that ends past the next deadline, the deadlines it missed are skipped).
- rclpy (timer on the steady clock): each callback reads the deadline rcl has just set for the next
  call (``time_until_next_call``), the first one is read right after the timer is created.
The runtime's own figure (``ActivityStats.error_summary()``: spin exit minus deadline) is shown too.
Conditions: *idle*; *busy*, with a pure-Python busy loop in a second activity (CoCo) or thread
(rclpy), CoCo also with ``sys.setswitchinterval(1e-4)`` (the usual GIL mitigation); *loaded*, with two
CPU-bound processes beside this one (what a shared machine does, made reproducible), CoCo also with a
SCHED_FIFO scheduling request. Goal: p99 < 50 us idle.

    PYTHONPATH=coco_core .venv/bin/python bench/bench_period.py [--seconds 10] [--json PATH] [--no-plot]
"""

from __future__ import annotations

import os
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import _report
from _ros import RosContext  # sets ROS_DOMAIN_ID before rclpy is imported
from _table import Table, fmt_ratio, fmt_time_ns, verdict

import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.task import Future

from coco_core.activity import PeriodicActivity, TriggeredActivity
from coco_core.application import Application
from coco_core.component import Component
from coco_core.thread_placement import SchedulingRequest

PERIOD_NS = 1_000_000
WARMUP_S = 0.5
GOAL_P99_NS = 50_000
BUSY_CHUNK_S = 0.01
SWITCH_FAST = 1e-4
FIFO_PRIORITY = 50
LOADERS = 2
"""Spinning processes of the ``loaded`` condition: one per core of the 2-core machines."""
IDLE, BUSY, LOADED = "idle", "busy", "loaded"
DISPATCH_MAX_NS = 20_000
PERCENTILES = (50, 90, 99, 99.9)


def burn(seconds: float) -> int:
    """A pure-Python busy loop: holds the GIL but for the interpreter's forced switches."""
    end = time.perf_counter() + seconds
    count = 0
    while time.perf_counter() < end:
        count += 1
    return count


def burn_until(stop: threading.Event) -> None:
    """The busy thread of the rclpy runs: the same loop as the CoCo busy activity, until ``stop``."""
    while not stop.is_set():
        burn(BUSY_CHUNK_S)


class Recorder:
    """Start and end times of callbacks in preallocated lists (no allocation in the timed path)."""

    def __init__(self, capacity: int) -> None:
        self.starts = [0] * capacity
        self.ends = [0] * capacity
        self.count = 0
        self.capacity = capacity

    def start(self) -> int:
        return time.perf_counter_ns()

    def done(self, start: int) -> None:
        i = self.count
        if i < self.capacity:
            self.starts[i] = start
            self.ends[i] = time.perf_counter_ns()
            self.count = i + 1


class Probe(Component):
    """The 1 kHz component: records when each ``on_update`` starts and ends."""

    def __init__(self, name: str, recorder: Recorder) -> None:
        super().__init__(name)
        self.recorder = recorder
        self.origin = 0
        self.realtime = False
        """Whether the OS granted the activity's thread SCHED_FIFO."""

    def on_config(self) -> None:
        self.realtime = hasattr(os, "sched_getscheduler") and os.sched_getscheduler(0) == os.SCHED_FIFO
        self.origin = time.perf_counter_ns()  # the loop takes its first deadline right after this

    def on_update(self) -> None:
        recorder = self.recorder
        recorder.done(recorder.start())


class Busy(Component):
    """Burns the CPU in pure Python and asks its triggered activity for the next cycle at once."""

    def on_config(self) -> None:
        # Let the 1 kHz activity enter its loop first: a GIL switch between the probe's on_config and
        # the loop's first deadline would shift the grid that the errors are measured against.
        time.sleep(0.2)
        self.activity.wake()

    def on_update(self) -> None:
        burn(BUSY_CHUNK_S)
        self.activity.wake()


def coco_deadlines(starts: list[int], ends: list[int], first: int, period: int) -> np.ndarray:
    """The deadline each cycle of a PeriodicActivity ran for, by the activity's own rule.

    After a cycle that ended (``ends[i]``) past the next deadline, the deadlines it missed are skipped.
    The activity reads its clock a little after ``on_update`` returns, so where a thread switch falls in
    between, this puts a deadline earlier than the activity did: errors can only come out larger. The
    grid origin is known to a few us only (see :func:`grid_origin`): a cycle that ended within those few
    us of a grid point may be replayed as skipping one deadline too many, which the next start shows
    (the activity never starts a cycle before its deadline) and which is then undone.
    """
    out = np.empty(len(ends), dtype=np.int64)
    deadline, previous = first, first - period
    for i, (start, end) in enumerate(zip(starts, ends)):
        if deadline > start:
            deadline = max(deadline - -(-(deadline - start) // period) * period, previous + period)
        out[i] = previous = deadline
        deadline += period
        if end > deadline:
            deadline += ((end - deadline) // period + 1) * period
    return out


@dataclass
class Run:
    """One condition: errors (ns) of the cycles after warm-up, and what went missing."""

    name: str
    scheduler: str
    load: str
    """IDLE, BUSY (a busy thread in this process) or LOADED (busy processes beside it)."""
    errors_ns: np.ndarray
    missed: int
    overruns: int | None = None
    own: dict[str, float] | None = None
    others_cpu: float | None = None
    """Share of the machine's cores used by other processes during the run."""
    variant: str = ""
    """What differs from the plain run under the same load (a GIL switch interval, a real-time class)."""
    grid_fitted: bool = False
    """True when the grid origin had to be taken from the first cycle (see :func:`grid_origin`)."""
    extra: dict[str, Any] = field(default_factory=dict)

    def percentiles(self) -> dict[str, float]:
        e = self.errors_ns
        stats = {f"p{p:g}": float(np.percentile(e, p)) for p in PERCENTILES}
        return {**stats, "min": float(e.min()), "max": float(e.max()), "mean": float(e.mean()), "cycles": int(len(e))}


def window(starts: np.ndarray, t0: int, seconds: float) -> np.ndarray:
    """Indices of the callbacks inside the measured window (after the warm-up)."""
    begin = t0 + int(WARMUP_S * 1e9)
    return (starts >= begin) & (starts < begin + int(seconds * 1e9))


def missed_in(all_deadlines: np.ndarray, keep: np.ndarray) -> int:
    """Grid points inside the window that no callback ran for."""
    kept = all_deadlines[keep]
    if len(kept) < 2:
        return 0
    return int(round((kept[-1] - kept[0]) / PERIOD_NS)) + 1 - len(kept)  # rclpy's are read, +-1 us


def grid_origin(first_start: int, guess: int) -> tuple[int, bool]:
    """The origin of the activity's deadline grid, and whether the guess had to be replaced.

    The loop takes its first deadline between the end of on_config (``guess``) and the start of the
    first on_update (``first_start``, which follows it without a sleep), normally a few us apart. When
    they are further apart (the thread was preempted or waited for the GIL in between), the first
    start is taken instead: that leaves the dispatch to the component out of the errors.
    """
    if first_start - guess <= DISPATCH_MAX_NS:
        return guess, False
    return first_start, True


def run_coco(seconds: float, load: str, switchinterval: float | None = None, fifo: int | None = None) -> Run:
    recorder = Recorder(int((seconds + WARMUP_S + 1) * 1e9 / PERIOD_NS * 1.2))
    app = Application("bench_period")
    probe = Probe("probe", recorder)
    scheduling = SchedulingRequest(realtime="FIFO", priority=fifo) if fifo is not None else None
    activity = PeriodicActivity("rt", PERIOD_NS / 1e9, scheduling=scheduling)
    app.add(probe, activity)
    if load == BUSY:
        app.add(Busy("busy"), TriggeredActivity("busy"))
    previous = sys.getswitchinterval()
    if switchinterval is not None:
        sys.setswitchinterval(switchinterval)
    try:
        with _report.other_processes(LOADERS if load == LOADED else 0):
            app.start()
            t0 = time.perf_counter_ns()
            time.sleep(WARMUP_S)
            activity.stats.reset()
            overruns_before = activity.stats.overruns
            with _report.LoadMeter() as load_meter:
                time.sleep(seconds)
            overruns = activity.stats.overruns - overruns_before
            own = activity.stats.error_summary()
            app.stop()
    finally:
        sys.setswitchinterval(previous)
    n = recorder.count
    starts = np.array(recorder.starts[:n], dtype=np.int64)
    origin, fitted = grid_origin(recorder.starts[0], probe.origin)
    dl = coco_deadlines(recorder.starts[:n], recorder.ends[:n], origin, PERIOD_NS)
    keep = window(starts, t0, seconds)
    refused = "" if probe.realtime else " REFUSED by the OS"
    variant = ", ".join(([f"SCHED_FIFO {fifo}{refused}"] if fifo is not None else [])
                        + ([f"setswitchinterval({switchinterval:g})"] if switchinterval is not None else []))
    own_ns = None if own is None else {"p50": own.p50 * 1e9, "p99": own.p99 * 1e9, "max": own.max * 1e9,
                                       "cycles": own.samples}
    return Run(f"CoCo PeriodicActivity{', ' + variant if variant else ''}, {load}", "coco", load,
               starts[keep] - dl[keep], missed_in(dl, keep), overruns, own_ns, load_meter.others, variant, fitted)


def run_rclpy(seconds: float, load: str, multi: bool) -> Run:
    recorder = Recorder(int((seconds + WARMUP_S + 1) * 1e9 / PERIOD_NS * 1.2))
    stop = threading.Event()
    burner = threading.Thread(target=burn_until, args=(stop,), daemon=True)
    with _report.other_processes(LOADERS if load == LOADED else 0), RosContext() as context:
        node = Node("bench_timer", context=context)
        executor = (MultiThreadedExecutor if multi else SingleThreadedExecutor)(context=context)
        executor.add_node(node)

        def tick() -> None:
            start = recorder.start()
            # The deadline rcl has just set for the next call, on the same clock: exact, whatever
            # happened between rcl's call of the timer and this callback.
            next_deadlines.append(time.perf_counter_ns() + timer.time_until_next_call())
            recorder.done(start)

        timer = node.create_timer(PERIOD_NS / 1e9, tick, clock=Clock(clock_type=ClockType.STEADY_TIME))
        next_deadlines = [time.perf_counter_ns() + timer.time_until_next_call()]
        t0 = time.perf_counter_ns()
        if load == BUSY:
            burner.start()
        try:
            # A future nobody completes: spin until the timeout, in this thread, as a node's main does.
            with _report.LoadMeter() as load_meter:
                executor.spin_until_future_complete(Future(), timeout_sec=WARMUP_S + seconds)
        finally:
            stop.set()
            if burner.is_alive():
                burner.join()
            node.destroy_timer(timer)
            for _ in range(3):  # handlers already taken from the wait set now see an invalid handle
                executor.spin_once(timeout_sec=0.01)
            executor.shutdown()
            node.destroy_node()
    n = recorder.count
    starts = np.array(recorder.starts[:n], dtype=np.int64)
    dl = np.array(next_deadlines[:n], dtype=np.int64)
    keep = window(starts, t0, seconds)
    kind = "MultiThreadedExecutor" if multi else "SingleThreadedExecutor"
    return Run(f"rclpy timer, {kind}, {load}", "rclpy-mt" if multi else "rclpy-st", load,
               starts[keep] - dl[keep], missed_in(dl, keep), others_cpu=load_meter.others)


def conditions(seconds: float) -> list[Callable[[], Run]]:
    """Every run, in the order they are made: each load measured for both schedulers back to back."""
    return [
        lambda: run_coco(seconds, IDLE),
        lambda: run_rclpy(seconds, IDLE, multi=False),
        lambda: run_rclpy(seconds, IDLE, multi=True),
        lambda: run_coco(seconds, BUSY),
        lambda: run_coco(seconds, BUSY, switchinterval=SWITCH_FAST),
        lambda: run_rclpy(seconds, BUSY, multi=False),
        lambda: run_rclpy(seconds, BUSY, multi=True),
        lambda: run_coco(seconds, LOADED),
        lambda: run_coco(seconds, LOADED, fifo=FIFO_PRIORITY),
        lambda: run_rclpy(seconds, LOADED, multi=False),
    ]


def percent(share: float | None) -> str:
    return "n/a" if share is None else f"{share * 100:.0f}%"


def anchor_of(run: Run, runs: list[Run]) -> Run:
    """The rclpy SingleThreadedExecutor run under the same load."""
    return next(r for r in runs if r.scheduler == "rclpy-st" and r.load == run.load)


def table(runs: list[Run], seconds: float) -> tuple[Table, dict[str, Any]]:
    t = Table(f"Figure 3 - period error at 1 kHz over {seconds:g} s (callback start - its deadline)",
              ["variant", "cycles", "missed deadlines", "overruns", "min", "p50", "p99", "p99.9", "max",
               "p99: rclpy ST / this", f"goal p99 < {GOAL_P99_NS / 1e3:g} us idle", "others' CPU"])
    results: dict[str, Any] = {}
    for run in runs:
        stats = run.percentiles()
        anchor = anchor_of(run, runs).percentiles()["p99"]
        ok = stats["p99"] < GOAL_P99_NS if run.scheduler == "coco" and run.load == IDLE else None
        label = run.name + (" (grid from 1st cycle)" if run.grid_fitted else "")
        t.add(label, stats["cycles"], run.missed, "-" if run.overruns is None else run.overruns,
              *(fmt_time_ns(stats[key]) for key in ("min", "p50", "p99", "p99.9", "max")),
              fmt_ratio(anchor / stats["p99"]), verdict(ok), percent(run.others_cpu))
        if run.own is not None:
            own_ok = run.own["p99"] < GOAL_P99_NS if run.load == IDLE else None
            t.add("  ActivityStats of the run above", run.own["cycles"], "-", "-", "-",
                  fmt_time_ns(run.own["p50"]), fmt_time_ns(run.own["p99"]), "-", fmt_time_ns(run.own["max"]),
                  fmt_ratio(anchor / run.own["p99"]), verdict(own_ok), "")
        quantiles = np.percentile(run.errors_ns, np.linspace(0, 100, 101)).tolist()
        results[run.name] = {**stats, "missed": run.missed, "overruns": run.overruns, "others_cpu": run.others_cpu,
                             "grid_from_first_cycle": run.grid_fitted, "activity_stats": run.own,
                             "quantiles_ns_0_to_100": quantiles}
    t.notes += [
        "missed deadlines: grid points in the window that no callback ran for (the scheduler skipped them); "
        "overruns: the activity's own counter (cycles that ended past the next deadline).",
        "ActivityStats measures spin exit - deadline inside the loop. The measured CoCo rows take on_update "
        "start against a grid whose origin is the end of on_config, a little before the loop takes its first "
        "deadline: they include the dispatch to the component and overstate the error by a constant of a "
        "few us (see min). '(grid from 1st cycle)': the thread was held up between the two, so the "
        "grid starts at the first on_update instead, and the dispatch is left out.",
        "others' CPU: share of the machine's cores that other processes used during the run (/proc/stat).",
        f"busy: a pure-Python loop in a second CoCo TriggeredActivity (rclpy: a plain thread); "
        f"setswitchinterval({SWITCH_FAST:g}) during that run only (default {sys.getswitchinterval():g} s); "
        f"loaded: {LOADERS} other processes spin on the CPU during the run (a shared machine, made "
        f"reproducible); SCHED_FIFO {FIFO_PRIORITY}: the activity's scheduling request realtime=FIFO, "
        f"priority={FIFO_PRIORITY}.",
    ]
    return t, results


def draw(runs: list[Run]):
    def figure(plt: Any) -> Any:
        fig, axes = plt.subplots(1, 3, figsize=(15, 4.5), sharey=True)
        styles = {"coco": ("tab:blue", "-"), "rclpy-st": ("tab:red", "--"), "rclpy-mt": ("tab:orange", ":")}
        panels = ((IDLE, "idle process"), (BUSY, "a busy pure-Python thread in the process"),
                  (LOADED, f"{LOADERS} CPU-bound processes beside it"))
        for ax, (load, title) in zip(axes, panels):
            for run in (r for r in runs if r.load == load):
                errors = np.sort(np.maximum(run.errors_ns, 100)) / 1e3
                exceed = 1.0 - np.arange(len(errors)) / len(errors)
                color, style = styles[run.scheduler]
                if run.variant:
                    color = "tab:green"
                ax.step(errors, exceed, where="post", color=color, linestyle=style,
                        label=run.name.removesuffix(f", {run.load}"))
            ax.axvline(GOAL_P99_NS / 1e3, color="gray", linewidth=0.8)
            ax.axhline(0.01, color="gray", linewidth=0.8, linestyle="-.")
            ax.text(GOAL_P99_NS / 1e3 * 1.1, 0.5, "50 us", color="gray", fontsize=8)
            ax.text(0.15, 0.012, "p99", color="gray", fontsize=8)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlim(0.1, 1e5)
            ax.set_ylim(1e-4, 1.05)
            ax.set_xlabel("period error: callback start - deadline (us, log)")
            ax.set_title(title)
            ax.legend(fontsize=8, loc="lower left")
            ax.grid(True, which="major", alpha=0.3)
        axes[0].set_ylabel("fraction of cycles later than x")
        fig.suptitle("1 kHz loop: CoCo PeriodicActivity vs rclpy timer")
        return fig

    return figure


def main() -> None:
    p = _report.parser("bench_period", __doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=10.0, help="measured seconds per condition (default 10)")
    args = p.parse_args()
    runs = []
    for make in conditions(args.seconds):
        run = make()
        print(f"  {run.name}: {len(run.errors_ns)} cycles, p99 {fmt_time_ns(run.percentiles()['p99'])}",
              flush=True)
        runs.append(run)
    t, results = table(runs, args.seconds)
    _report.emit("bench_period", args, [t], results)
    _report.save_plot(args, draw(runs))


if __name__ == "__main__":
    main()
