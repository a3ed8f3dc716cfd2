"""The profiler's report: what ``coco-launch --profile`` prints.

Per activity: cycles, overruns and period error percentiles. Per component: executions, total time,
mean and standard deviation of compute time and of service time (time between activations), errors,
and stamp-to-output latency when the component records it. Per connection: flow counters.
"""

from __future__ import annotations

import time

from .activity import PeriodicActivity
from .application import Application


def _table(header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(str(cell)) for cell in column) for column in zip(header, *rows)]
    lines = ["  ".join(cell.ljust(width) for cell, width in zip(header, widths)).rstrip()]
    lines.append("  ".join("-" * width for width in widths))
    lines += ["  ".join(str(cell).ljust(width) for cell, width in zip(row, widths)).rstrip() for row in rows]
    return "\n".join(lines)


def _us(seconds: float) -> str:
    return f"{seconds * 1e6:.1f}"


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.3f}"


def profile_report(app: Application) -> str:
    """The whole profile of ``app`` as text tables."""
    elapsed = time.perf_counter() - app.started_at if app.started_at else 0.0
    parts = [f"Profile of application {app.name!r} after {elapsed:.1f} s"]

    rows = []
    for activity in app.activities.values():
        summary = activity.stats.error_summary() if isinstance(activity, PeriodicActivity) else None
        error = (f"{_us(summary.p50)} / {_us(summary.p99)} / {_us(summary.max)}" if summary else "-")
        rows.append([activity.name + (" (main)" if activity.main else ""), activity.describe(),
                     str(activity.stats.cycles), str(activity.stats.overruns), error])
    parts.append(_table(["activity", "schedule", "cycles", "overruns", "period error p50/p99/max us"], rows))

    rows = []
    for activity, components in app.schedule_tree():
        for top in components:
            for component in top.walk():
                stats = component.stats
                latency = stats.latency
                rows.append([
                    component.name if component.owner is None else f"  {component.name} (peer)",
                    activity.name if activity else "-",
                    str(stats.executions),
                    _ms(stats.compute.total),
                    _us(stats.compute.mean), _us(stats.compute.std),
                    _ms(stats.service.mean), _ms(stats.service.std),
                    str(stats.errors), str(stats.refused),
                    f"{_ms(latency.mean)} / {_ms(latency.max)}" if latency.count else "-",
                ])
    parts.append(_table(["component", "activity", "execs", "total ms", "compute mean us", "compute std us",
                         "service mean ms", "service std ms", "errors", "refused", "latency mean/max ms"], rows))

    rows = []
    for connection in app.connections:
        counters = connection.counters()
        rows.append([f"{connection.source.qualified_name if connection.source else '?'} -> "
                     f"{connection.sink.qualified_name if connection.sink else '?'}",
                     str(connection.policy), str(counters["written"]), str(counters["read"]),
                     str(counters["dropped"]), str(counters["pending"])])
    if rows:
        parts.append(_table(["connection", "policy", "written", "read", "dropped", "pending"], rows))
    return "\n\n".join(parts)
