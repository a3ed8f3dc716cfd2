"""The ROS launcher's rules for the deployment plan (:class:`coco_core.deployment.LaunchRules`).

The core plans hosts, processes, the main thread and the activities an eventfd wakes; the ROS host
decides the rest of each activity here, and what each process's node runs beside its activities
(its executor's threads), so that ``--check`` prints exactly what every process does and the ROS
words stay in this package. An activity keeps a thread of its own when it asks the OS for anything
about its thread (affinity, real-time class, priority, nice), is periodic faster than
:data:`THREAD_PERIOD`, runs a thread-bound component (an OpenGL context), or the command line names
it (``--threads``, ``--all-threads``); the others are hosted by rclpy (:mod:`.hosting`): each in a
wait set on a thread of its own by default, or in the node's executor with ``--executor-threads N``.
``docs/ros.md`` has the measurements behind the rule.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from coco_core.deployment import ActivityDeployment, ActivityFacts, Decision, Driving
from coco_core.errors import CommandLineError, did_you_mean
from coco_core.processes.messages import HostConfig
from coco_core.thread_placement import SchedulingRequest

THREAD_PERIOD = 5e-3
"""Periodic activities faster than this (seconds) keep a thread of their own: an rclpy timer's p99
period error (233 us SingleThreaded, 500 us MultiThreaded at 1 kHz, idle) is a tenth of such a period."""


@dataclass(frozen=True)
class ExecutorPlan:
    """What one process's node runs its hosted activities with (:attr:`ProcessPlan.host
    <coco_core.deployment.ProcessPlan.host>`): a wait set per activity, or the node's executor;
    and the executor's threads (a ``SingleThreadedExecutor`` for one)."""

    wait_sets: bool
    threads: int

    def describe(self) -> str:
        hosting = "a wait set per hosted activity" if self.wait_sets else "hosted activities in the executor"
        return f"rclpy node: {hosting}, executor with {self.threads} thread{'s' if self.threads > 1 else ''}"


@dataclass(frozen=True)
class RosChildConfig(HostConfig):
    """What every child of the ROS launcher needs beyond the plan (:mod:`.child`)."""

    node: str
    """The launcher's node's name: a child's node is ``<node>_<process>``."""
    ros_args: tuple[str, ...] = ()
    """The launcher's ROS arguments (the child drops its node renames)."""
    expose: tuple[str, ...] = ()
    """``--expose`` patterns: the ports every process mirrors on topics."""


@dataclass(frozen=True)
class RosRules:
    """The ROS launcher's :class:`~coco_core.deployment.LaunchRules`, from its command line."""

    threads: tuple[str, ...] = ()
    """Activities the command line puts on threads of their own (``--threads``)."""
    all_threads: bool = False
    """Every activity on a thread of its own (``--all-threads``)."""
    wait_sets: bool = True
    """Each hosted activity in a wait set of its own (the default), or all of them in the node's
    executor (``--executor-threads``)."""
    executor_threads: int | None = None
    """``--executor-threads N``: the executor's threads; None: as :meth:`settings` counts them."""
    thread_period: float = THREAD_PERIOD
    """Periodic activities faster than this keep a thread of their own (0: rclpy hosts them all, as
    ``bench/bench_hosting.py`` measures it)."""

    def describe(self) -> str:
        if self.wait_sets:
            return "ROS (an rclpy node per process, a wait set per hosted activity)"
        return "ROS (an rclpy node per process, hosted activities in one executor)"

    def check(self, activities: Sequence[str]) -> None:
        unknown = sorted(set(self.threads) - set(activities))
        if unknown:
            raise CommandLineError(f"--threads: no activity {', '.join(map(repr, unknown))} in the application; "
                                   f"{did_you_mean(unknown[0], activities)}")

    def decide(self, facts: ActivityFacts) -> Decision:
        reason = self._own_thread_reason(facts)
        if reason is not None:
            return Decision(False, reason)
        entity = "rclpy timer" if facts.period is not None else (
            "guard condition, a one-shot timer for its min_period" if facts.min_period else "guard condition")
        where = "wait set on its own thread" if self.wait_sets else "executor"
        return Decision(True, f"{where} ({entity} in its callback group)")

    def _own_thread_reason(self, facts: ActivityFacts) -> str | None:
        """Why ``facts``'s activity keeps a thread of its own; None: rclpy hosts it."""
        if self.all_threads or facts.name in self.threads:
            return "asked on the command line"
        request = facts.scheduling
        if request != SchedulingRequest():
            asked = [name for name, value in (("affinity", request.affinity), ("realtime", request.realtime != "none"),
                                              ("priority", request.priority is not None),
                                              ("nice", request.nice is not None)) if value]
            return f"thread placement: {', '.join(asked) or 'scheduling request'}"
        if facts.period is not None and facts.period < self.thread_period:
            return f"period {facts.period * 1e3:g} ms < {self.thread_period * 1e3:g} ms"
        if facts.thread_bound:
            plural = "s" if len(facts.thread_bound) > 1 else ""
            return f"thread-bound component{plural} {', '.join(facts.thread_bound)}"
        return None

    def settings(self, activities: Sequence[ActivityDeployment], stand_ins: int) -> ExecutorPlan:
        """The executor's threads of one process (``activities``: its own). With wait sets (the
        default) the executor runs no hosted activity, only the ROS entities of the activities on
        threads of their own (one executor thread each, so they run in parallel) and of the node's
        default group (one more): 1 when there are none of the former. In the executor: N threads
        (``--executor-threads N``), or without N (a program that hosts an application it built
        itself) one per hosted activity and one more for the ROS entities in other groups, at least
        two; but 1 when the executor hosts every activity of the application (no stand-in of another
        process's either) and there is at most one: every callback is then in that activity's group,
        except those of components in no activity, so there is next to nothing to run in parallel
        (:meth:`coco_ros.hosting.ExecutorHost.create_executor` makes it a ``SingleThreadedExecutor``)."""
        hosted = sum(1 for a in activities if a.driving is Driving.HOSTED)
        if self.wait_sets:
            threaded = len(activities) - hosted
            return ExecutorPlan(True, threaded + 1 if threaded else 1)
        if self.executor_threads is not None:
            return ExecutorPlan(False, self.executor_threads)
        if hosted <= 1 and hosted == len(activities) and not stand_ins:
            return ExecutorPlan(False, 1)
        return ExecutorPlan(False, max(2, hosted + 1))
