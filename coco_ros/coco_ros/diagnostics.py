"""The profile on ``/diagnostics``: what ``--profile`` prints, for rqt_robot_monitor and bags.

Every ``diagnostics.period`` seconds (a parameter of the launcher's node; 0: off) the launcher
publishes one ``diagnostic_msgs/DiagnosticArray`` with a status per process, activity, component,
connection and pooled output of every process of the application (children included: the rows come
from the same :class:`~coco_core.report.ProfileSnapshot` objects as the printed profile). A status's
``values`` are the profile's columns; its level comes from what happened since the last array, so a
run that had one burst of overruns goes back to OK once it has passed:

- activity: WARN when it overran ``diagnostics.overruns_warn`` times or more since the last array,
  or its period error p99 is ``diagnostics.period_error_warn_us`` or more;
- component: ERROR when it raised since the last array; WARN when it refused input;
- connection: WARN when it dropped ``diagnostics.drops_warn`` samples or more since the last array;
- pooled output: WARN when its writer stalled (no free slot).

The thresholds are read at every array, so ``ros2 param set`` changes them while the application
runs; ``diagnostics.period`` is read once, at the start, and is read-only. The arrays are made on a
thread of their own, not by a timer of the node: gathering the children's profiles waits for their
answers, which must not hold up the executor that serves the application's ROS entities.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from typing import Any

from coco_core.errors import CocoError
from coco_core.report import ProfileSnapshot

ACTIVITY_COLUMNS = ("schedule", "cycles", "overruns", "period error p50/p99/max us")
COMPONENT_COLUMNS = ("activity", "execs", "total ms", "compute mean us", "compute std us", "service mean ms",
                     "service std ms", "errors", "refused", "merged", "latency mean/max ms")
CONNECTION_COLUMNS = ("policy", "written", "read", "dropped", "pending", "age mean/max ms")
POOL_COLUMNS = ("slots", "published", "stalls")
PERIOD = "diagnostics.period"
THRESHOLDS: dict[str, tuple[float, str]] = {
    "diagnostics.overruns_warn": (1, "overruns of an activity between two arrays that make it WARN"),
    "diagnostics.period_error_warn_us": (1000.0, "an activity's period error p99 (us) that makes it WARN"),
    "diagnostics.drops_warn": (1, "samples a connection drops between two arrays that make it WARN"),
}
OK, WARN, ERROR = b"\x00", b"\x01", b"\x02"


def is_threshold(value: Any) -> bool:
    """Whether ``value`` may be a threshold: a finite number >= 0. NaN passes ``< 0`` and would
    make every comparison false, so an activity could never WARN."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value >= 0


class ProfileDiagnostics:
    """Publishes ``snapshots()`` (the profile of every process) on ``/diagnostics`` through ``node``."""

    def __init__(self, node: Any, app_name: str, snapshots: Callable[[], list[ProfileSnapshot]]) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from rcl_interfaces.msg import ParameterDescriptor

        self.node = node
        self.app_name = app_name
        self.snapshots = snapshots
        self._array_type = DiagnosticArray
        self._previous: dict[str, dict[str, float]] = {}
        """Per status name, the counters of the last array (levels come from what changed since)."""
        declared = {PERIOD: (1.0, "seconds between two /diagnostics arrays of the profile (0: none); read at the "
                                  "start"), **THRESHOLDS}
        for name, (default, doc) in declared.items():
            if not node.has_parameter(name):  # -p diagnostics...:= declared it already, with its value
                node.declare_parameter(name, default, ParameterDescriptor(description=doc))
            given = node.get_parameter(name).value
            if not is_threshold(given):  # the callback below checks later changes only
                raise CocoError(f"-p {name}:={given!r}: expected a finite number >= 0")
        period = node.get_parameter(PERIOD).value
        node.add_on_set_parameters_callback(self._check_change)
        self._publisher = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._period = float(period)
        self._done = threading.Event()
        self._thread: threading.Thread | None = None

    def _check_change(self, parameters: list[Any]) -> Any:
        """The period is read at the start (refused later, with the reason); a threshold must be a
        number >= 0."""
        from rcl_interfaces.msg import SetParametersResult

        for parameter in parameters:
            if parameter.name == PERIOD:
                return SetParametersResult(successful=False, reason=(
                    f"{PERIOD} is read when the launcher starts: restart it with -p {PERIOD}:=SECONDS"))
            if parameter.name in THRESHOLDS and not is_threshold(parameter.value):
                return SetParametersResult(successful=False, reason=(
                    f"{parameter.name} must be a finite number >= 0, got {parameter.value!r}"))
        return SetParametersResult(successful=True)

    def __enter__(self) -> ProfileDiagnostics:
        if self._period > 0:
            self._thread = threading.Thread(target=self._loop, name="coco:diagnostics", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        """Stop publishing (the application stopped), after one last array: its final figures."""
        self._done.set()
        if self._thread is not None:
            self._thread.join()
            self.publish()

    def _loop(self) -> None:
        while not self._done.wait(self._period):
            self.publish()

    def publish(self) -> None:
        array = self._array_type()
        array.header.stamp = self.node.get_clock().now().to_msg()
        array.status = self.statuses(self.snapshots())
        self._publisher.publish(array)

    def statuses(self, snapshots: list[ProfileSnapshot]) -> list[Any]:
        """One DiagnosticStatus per row of the profile, with its level."""
        threshold = {name: self.node.get_parameter(name).value for name in THRESHOLDS}
        statuses = []
        for shot in snapshots:
            process = shot.process or "launcher"
            statuses.append(self._status(f"process {process}", process, OK, "running", {
                "pid": shot.pid, "cpu s": f"{shot.cpu:.2f}", "rss MB": f"{shot.rss / 2**20:.1f}"}))
            for row in shot.activities:
                values = dict(zip(ACTIVITY_COLUMNS, row[1:]))
                overruns = self._since(f"activity {row[0]}", "overruns", values["overruns"])
                p99 = _p99(values["period error p50/p99/max us"])
                level, message = OK, "on time"
                if overruns >= threshold["diagnostics.overruns_warn"]:
                    level, message = WARN, f"{overruns:.0f} overruns since the last report"
                elif p99 is not None and p99 >= threshold["diagnostics.period_error_warn_us"]:
                    level, message = WARN, f"period error p99 {p99:.0f} us"
                statuses.append(self._status(f"activity {row[0]}", process, level, message, values))
            for row in shot.components:
                name = row[0].strip()
                values = dict(zip(COMPONENT_COLUMNS, row[1:]))
                errors = self._since(f"component {name}", "errors", values["errors"])
                refused = self._since(f"component {name}", "refused", values["refused"])
                level, message = OK, "ok"
                if errors > 0:
                    level, message = ERROR, f"{errors:.0f} errors since the last report"
                elif refused > 0:
                    level, message = WARN, f"{refused:.0f} inputs refused since the last report"
                statuses.append(self._status(f"component {name}", process, level, message, values))
            for row in shot.connections:
                values = dict(zip(CONNECTION_COLUMNS, row[1:]))
                dropped = self._since(f"connection {row[0]}", "dropped", values["dropped"])
                level, message = OK, "no sample dropped"
                if dropped and dropped >= threshold["diagnostics.drops_warn"]:
                    level, message = WARN, f"{dropped:.0f} samples dropped since the last report"
                statuses.append(self._status(f"connection {row[0]}", process, level, message, values))
            for row in shot.pools:
                values = dict(zip(POOL_COLUMNS, row[1:]))
                stalls = self._since(f"pool {row[0]}", "stalls", values["stalls"])
                level, message = (WARN, f"{stalls:.0f} frames found no free slot") if stalls else (OK, "ok")
                statuses.append(self._status(f"pooled output {row[0]}", process, level, message, values))
        return statuses

    def _since(self, key: str, counter: str, text: str) -> float:
        """How much ``counter`` of the row ``key`` grew since the last array."""
        try:
            value = float(text)
        except ValueError:
            return 0.0
        previous = self._previous.setdefault(key, {})
        grown = value - previous.get(counter, 0.0)
        previous[counter] = value
        return max(grown, 0.0)

    def _status(self, what: str, process: str, level: bytes, message: str, values: dict[str, Any]) -> Any:
        from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

        return DiagnosticStatus(level=level, name=f"coco/{self.app_name}: {what}", message=message,
                                hardware_id=process,
                                values=[KeyValue(key=key, value=str(value)) for key, value in values.items()])


def _p99(text: str) -> float | None:
    """The p99 of a ``p50 / p99 / max`` cell (None for ``-``)."""
    parts = text.split("/")
    try:
        return float(parts[1]) if len(parts) == 3 else None
    except ValueError:
        return None
