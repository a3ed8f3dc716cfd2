"""The profiler's report: what ``coco-launch --profile`` prints.

Per process: pid, CPU time, CPU share (CPU time over the time the process has lived, in cores:
the machine's budget, :mod:`coco_core.cpu`) and resident memory; per thread of each process, its CPU
time and share, the busiest first (a thread near one core busy-waits, or cannot keep up). Per activity:
cycles, overruns, period error percentiles, and its thread's CPU share (a thread's, as recorded by its
driver when it ended: the profile at exit comes after the threads ended; ``-`` for an activity whose
thread this process does not name, such as a ROS wait set's). Per component: executions, total time, mean and
standard deviation of compute time and of service time (time between activations), errors, and
stamp-to-output latency when the component records it (from its inputs' origins: a ``Stamped``
value's acquisition, a plain value's message stamp, its write in this process or another). Per connection: flow counters. Per pooled
output (a frame pool): frames published, and the writer's stalls, frames it could not publish
because readers held every slot (they never reach a connection, so no connection counts them).
Messages from other hosts refused (not authenticated, replayed, from an unknown host), by topic,
claimed sender and reason.
Per connection, in a profiled run, the age of what its reader took (the read time - the message's
stamp time), so that the latency of every link shows without a component recording it.

A report is rendered from :class:`ProfileSnapshot` objects, one per process: plain data that a child
process sends to the launcher, so that one report shows every process of the application.
"""

from __future__ import annotations

import os
import resource
import time
from collections.abc import Iterable
from dataclasses import dataclass, field

from .application import Application
from .connections import Connection
from .cpu import process_cpu, thread_cpu
from .ports import PooledOutputPort


@dataclass
class ProfileSnapshot:
    """The profile of the part of an application that one process runs, as plain rows."""

    process: str
    """The ``<process>`` name; empty: the launcher's own."""
    pid: int
    elapsed: float
    cpu: float
    """User + system CPU seconds of the whole process so far."""
    rss: int
    """Resident memory in bytes."""
    cores: float | None = None
    """CPU time over the time the process has lived, start-up included (cores); None: unknown (a
    child that sent no profile)."""
    threads: list[list[str]] = field(default_factory=list)
    """Each thread that used CPU time: name, CPU seconds, cores (over the thread's life)."""
    activities: list[list[str]] = field(default_factory=list)
    components: list[list[str]] = field(default_factory=list)
    connections: list[list[str]] = field(default_factory=list)
    pools: list[list[str]] = field(default_factory=list)
    refused: list[list[str]] = field(default_factory=list)
    """Messages from other hosts refused: topic, claimed sender, why, count
    (:class:`~coco_core.hosts.auth.Refusals`)."""


def _us(seconds: float) -> str:
    return f"{seconds * 1e6:.1f}"


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.3f}"


def _rss() -> int:
    """Resident memory of this process, from /proc (Linux), else the peak from getrusage."""
    try:
        with open("/proc/self/statm") as statm:
            return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def snapshot(app: Application, process: str = "") -> ProfileSnapshot:
    """The profile of what this process runs of ``app``: its own activities (not the stand-ins of
    activities that other processes run) and the connections it reads."""
    times = os.times()
    use = process_cpu(since=app.started_at or None)
    shot = ProfileSnapshot(process, os.getpid(), time.perf_counter() - app.started_at if app.started_at else 0.0,
                           times.user + times.system, _rss(), None if use is None or not use.wall else use.cores)
    local = [activity for activity in app.activities.values() if activity.process == app.process]
    ended = {f"coco:{a.name}": a.stats.thread_cpu for a in local if a.stats.thread_cpu is not None and not a.main}
    live = {name: use for name, use in thread_cpu() if name not in ended}
    threads = [*live.items(), *((f"{name} (ended)", use) for name, use in ended.items()),
               *((f"MainThread: activity {a.name} (ended)", a.stats.thread_cpu)  # a part of MainThread's row
                 for a in local if a.stats.thread_cpu is not None and a.main)]
    shot.threads = [[name, f"{use.seconds:.2f}", f"{use.cores:.2f}"]
                    for name, use in sorted(threads, key=lambda row: -row[1].seconds) if use.seconds > 0]
    for activity in local:
        summary = activity.stats.error_summary() if activity.period is not None else None
        error = f"{_us(summary.p50)} / {_us(summary.p99)} / {_us(summary.max)}" if summary else "-"
        use = activity.stats.thread_cpu or live.get(f"coco:{activity.name}")
        shot.activities.append([activity.name + (" (main)" if activity.main else ""), activity.describe(),
                                str(activity.stats.cycles), str(activity.stats.overruns), error,
                                "-" if use is None else f"{use.cores:.2f}"])
    for owner, components in app.schedule_tree():
        if owner is not None and owner.process != app.process:
            continue
        for top in components:
            for component in top.walk():
                stats = component.stats
                latency = stats.latency
                shot.components.append([
                    component.name if component.owner is None else f"  {component.name} (peer)",
                    owner.name if owner else "-",
                    str(stats.executions), _ms(stats.compute.total),
                    _us(stats.compute.mean), _us(stats.compute.std),
                    _ms(stats.service.mean), _ms(stats.service.std),
                    str(stats.errors), str(stats.refused), str(stats.merged),
                    f"{_ms(latency.mean)} / {_ms(latency.max)}" if latency.count else "-",
                ])
                for port in component.outputs.values():
                    if isinstance(port, PooledOutputPort):
                        pool = port.pool
                        shot.pools.append([port.qualified_name, str(pool.count), str(pool.published),
                                           str(pool.stalls)])
    shot.connections = connection_rows(app.connections)
    shot.refused = app.network_refusals.rows()
    return shot


def connection_rows(connections: Iterable[Connection]) -> list[list[str]]:
    """The profile's rows of ``connections``: label, policy, flow counters, and the age of the
    messages the reader took (mean/max, in a profiled run; ``-`` when not measured or none had a
    stamp)."""
    rows = []
    for connection in connections:
        counters = connection.counters()
        age = connection.age
        rows.append([connection.label, connection.describe(), str(counters["written"]), str(counters["read"]),
                     str(counters["dropped"]), str(counters["pending"]),
                     f"{_ms(age.mean)} / {_ms(age.max)}" if age is not None and age.count else "-"])
    return rows


def _table(header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(str(cell)) for cell in column) for column in zip(header, *rows)]
    lines = ["  ".join(cell.ljust(width) for cell, width in zip(header, widths)).rstrip()]
    lines.append("  ".join("-" * width for width in widths))
    lines += ["  ".join(str(cell).ljust(width) for cell, width in zip(row, widths)).rstrip() for row in rows]
    return "\n".join(lines)


def render(name: str, snapshots: list[ProfileSnapshot]) -> str:
    """One report of the snapshots of every process of application ``name``; a column names the
    process of each row when there is more than one."""
    elapsed = max((shot.elapsed for shot in snapshots), default=0.0)
    parts = [f"Profile of application {name!r} after {elapsed:.1f} s"]
    several = len(snapshots) > 1

    def rows(attribute: str) -> list[list[str]]:
        return [([shot.process or "launcher"] if several else []) + row
                for shot in snapshots for row in getattr(shot, attribute)]

    where = ["process"] if several else []
    known = [shot.cores for shot in snapshots if shot.cores is not None]
    parts.append(_table(["process", "pid", "cpu s", "rss MB", "cpu cores"],
                        [[shot.process or "launcher", str(shot.pid), f"{shot.cpu:.2f}", f"{shot.rss / 2**20:.1f}",
                          "-" if shot.cores is None else f"{shot.cores:.2f}"] for shot in snapshots])
                 + f"\nall processes: {sum(known):.2f} cores of {os.cpu_count() or 1} (CPU time / time lived, "
                 "start-up included)")
    threads = rows("threads")
    if threads:
        parts.append(_table([*where, "thread", "cpu s", "cpu cores"], threads))
    parts.append(_table([*where, "activity", "schedule", "cycles", "overruns", "period error p50/p99/max us",
                         "cpu cores"], rows("activities")))
    parts.append(_table([*where, "component", "activity", "execs", "total ms", "compute mean us", "compute std us",
                         "service mean ms", "service std ms", "errors", "refused", "merged", "latency mean/max ms"],
                        rows("components")))
    connections = rows("connections")
    if connections:
        parts.append(_table([*where, "connection", "policy", "written", "read", "dropped", "pending",
                             "age mean/max ms"], connections))
    pools = rows("pools")
    if pools:
        parts.append(_table([*where, "pooled output", "slots", "published", "stalls (no free slot)"], pools))
    refused = rows("refused")
    if refused:
        parts.append("Refused from the network (never read, never a stop):\n"
                     + _table([*where, "topic", "claimed sender", "why", "count"], refused))
    return "\n\n".join(parts)


def profile_report(app: Application) -> str:
    """The whole profile of ``app`` run in this one process, as text tables."""
    return render(app.name, [snapshot(app)])
