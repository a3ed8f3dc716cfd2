"""The one deployment plan: for every process and activity of an application, what drives it and why.

Where an activity runs used to be decided in several modules, one after the other (the activity's
default thread, the process level's eventfd threads, the ROS host's executor or thread), and
``--check`` re-derived it its own way: it once printed a wait set where the run used an eventfd
thread. Now one pure function, :func:`plan_deployment`, computes it from the parsed application
(:class:`~coco_core.model.AppSpec`) and the launch options (:class:`LaunchOptions`); ``--check``
prints it, and every launcher and child process executes it (:func:`drive`, and the ROS host for
what it drives) and then checks the drivers it gave against it (:func:`verify`). Nothing else
decides or re-decides.

The rules (``docs/processes.md`` and ``docs/ros.md`` have the measurements behind them):

- an activity of another process is that process's: the launcher holds a stand-in of it;
- an activity that a write in another process wakes is woken through an eventfd (a kernel counter
  the writer's process increments), so it needs a thread of its own that waits on it;
- the main activity runs in the launcher's main thread (some GUI toolkits need it);
- with the plain host (``coco-launch``) every other activity has a thread of its own;
- with the ROS host, an activity keeps a thread of its own when it asks the OS for anything about
  its thread (affinity, real-time class, priority, nice), is periodic faster than
  :data:`THREAD_PERIOD`, runs a thread-bound component (an OpenGL context), or the command line
  names it (``--threads``, ``--all-threads``); the others are hosted by rclpy: each in a wait set on a
  thread of its own by default, or in the node's executor with ``--executor-threads N``.
"""

from __future__ import annotations

import enum
import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, Iterable, Mapping

from . import registry
from .drivers import Driving, MainThreadDriver, ThreadDriver
from .errors import CocoError, CommandLineError, DeploymentError, did_you_mean
from .model import ActivitySpec, AppSpec, ComponentSpec, ProcessSpec
from .processes.channels import woken_by_other_processes
from .processes.placement import LAUNCHER, Placement
from .schedule import DEFAULT_SPIN, Schedule
from .scheduling import SchedulingRequest

if TYPE_CHECKING:
    from .activity import Activity
    from .application import Application

log = logging.getLogger("coco")

THREAD_PERIOD = 5e-3
"""With the ROS host, periodic activities faster than this (seconds) keep a thread of their own: an
rclpy timer's p99 period error (233 us SingleThreaded, 500 us MultiThreaded at 1 kHz, idle) is a
tenth of such a period."""


class Host(str, enum.Enum):
    """What runs the processes of an application: plain threads, or an rclpy node per process."""

    PLAIN = "plain"
    ROS = "ros"


@dataclass(frozen=True)
class LaunchOptions:
    """The parts of a launcher's command line that decide where activities run."""

    host: Host = Host.PLAIN
    threads: tuple[str, ...] = ()
    """Activities the command line puts on threads of their own (``--threads``; the ROS host)."""
    all_threads: bool = False
    """Every activity on a thread of its own (``--all-threads``; the ROS host)."""
    wait_sets: bool = True
    """The ROS host: each activity it hosts in a wait set of its own (the default), or all of them in
    the node's executor (``--executor-threads``)."""
    executor_threads: int | None = None
    """The ROS host: the executor's threads (``--executor-threads N``); None: as many as the host
    needs (``ExecutorHost.executor_threads``)."""

    def describe(self) -> str:
        if self.host is Host.PLAIN:
            return "plain (coco-launch: a thread per activity)"
        if self.wait_sets:
            return "ROS (an rclpy node per process, a wait set per hosted activity)"
        threads = "as many threads as needed" if self.executor_threads is None else f"{self.executor_threads} thread(s)"
        return f"ROS (an rclpy node per process, hosted activities in one executor with {threads})"


@dataclass(frozen=True)
class ActivityFacts:
    """What the plan needs to know of one activity. Read from the file when planning
    (:meth:`of_spec`) and from the built activity when executing (:meth:`of_activity`): the two must
    be equal, or the run would not be what ``--check`` printed (:func:`verify`)."""

    name: str
    process: str
    period: float | None
    """Seconds; None: triggered."""
    main: bool
    scheduling: SchedulingRequest
    thread_bound: tuple[str, ...]
    """Its components (peers included) that must run in the thread that configured them."""
    spin: float = DEFAULT_SPIN
    """Seconds before each periodic deadline at which its thread stops sleeping and spins."""

    def describe(self) -> str:
        """The schedule, then what the file asks beyond it (a spin, the thread's real-time class,
        priority, nice value and cores): ``periodic 1 ms, spin 0.6 ms, SCHED_FIFO priority 80``."""
        words = [Schedule(self.period).describe()]
        if self.period is not None and self.spin != DEFAULT_SPIN:
            words.append(f"spin {self.spin * 1e3:g} ms")
        return ", ".join([*words, *self.scheduling.describe()])

    @classmethod
    def of_spec(cls, spec: ActivitySpec, components: Mapping[str, ComponentSpec]) -> ActivityFacts:
        schedule = spec.schedule
        period = None
        if schedule.type == "periodic":
            assert schedule.period_ms is not None  # the loader guarantees it
            period = schedule.period_ms / 1e3
        bound: list[str] = []
        stack = [components[name] for name in reversed(spec.components) if name in components]
        while stack:
            component = stack.pop()
            if _thread_bound(component):
                bound.append(component.name)
            stack.extend(reversed(component.peers))
        return cls(spec.name, spec.process, period, schedule.main, SchedulingRequest.of(schedule), tuple(bound),
                   schedule.spin)

    @classmethod
    def of_activity(cls, activity: Activity) -> ActivityFacts:
        bound = tuple(c.name for top in activity.components for c in top.walk() if c.thread_bound)
        return cls(activity.name, activity.process, activity.period, activity.main, activity.scheduling,
                   bound, activity.schedule.spin)


def _thread_bound(component: ComponentSpec) -> bool:
    """Whether the class of ``component`` is thread-bound; False for a class that cannot be found
    (``--check --allow-unknown`` leaves such a component out, and the build reports it otherwise)."""
    try:
        return registry.load(component.task, component.library).thread_bound
    except CocoError:
        return False


@dataclass(frozen=True)
class ActivityDeployment:
    """Where one activity runs, and why."""

    facts: ActivityFacts
    driving: Driving
    reason: str
    """Why this driver (empty when it is the host's default)."""
    eventfd: bool
    """Woken through an eventfd by writes in another process."""

    @property
    def name(self) -> str:
        return self.facts.name

    @property
    def process(self) -> str:
        return self.facts.process

    def line(self) -> str:
        """``activity NAME: SCHEDULE -> DRIVER (WHY)``: what ``--check`` prints and each process logs."""
        if self.driving in (Driving.WAIT_SET, Driving.EXECUTOR):
            entity = "guard condition" if self.facts.period is None else "rclpy timer"
            where = "wait set on its own thread" if self.driving is Driving.WAIT_SET else "executor"
            return f"activity {self.name}: {self.facts.describe()} -> {where} ({entity} in its callback group)"
        driver = self.driving.value + (", woken by an eventfd" if self.eventfd else "")
        return f"activity {self.name}: {self.facts.describe()} -> {driver}" + (f" ({self.reason})" if self.reason else "")


@dataclass(frozen=True)
class Deployment:
    """The plan of one launch: every process (the launcher's is ``""``) and activity, in file order."""

    application: str
    options: LaunchOptions
    processes: Mapping[str, ProcessSpec | None]
    """Every process; the launcher's own has no ``<process>`` (None)."""
    activities: Mapping[str, ActivityDeployment]

    def of_process(self, process: str) -> list[ActivityDeployment]:
        return [activity for activity in self.activities.values() if activity.process == process]

    def threads(self, process: str) -> int:
        """How many of ``process``'s activities have a thread of their own (not hosted by rclpy)."""
        return sum(1 for a in self.of_process(process) if a.driving in (Driving.THREAD, Driving.MAIN))



def plan_deployment(spec: AppSpec, options: LaunchOptions = LaunchOptions()) -> Deployment:
    """The deployment of ``spec`` under ``options``: pure (the file and the options only), so that
    ``--check`` and every process of the run compute or receive the same."""
    components = {component.name: component for component in spec.all_components()}
    facts = [ActivityFacts.of_spec(activity, components) for activity in spec.activities]
    woken = woken_by_other_processes(spec, Placement.of(spec))
    processes: dict[str, ProcessSpec | None] = {LAUNCHER: None}
    processes.update((process.name, process) for process in spec.processes)
    return plan(spec.name, facts, woken, options, processes)


def plan(application: str, facts: Iterable[ActivityFacts], woken: Iterable[str], options: LaunchOptions,
         processes: Mapping[str, ProcessSpec | None] | None = None) -> Deployment:
    """The deployment of activities described by ``facts`` (``woken``: those a write in another
    process wakes); :func:`plan_deployment` for an application file, and for an application built in
    code (which has one process and no file) its activities' own facts."""
    facts = list(facts)
    woken = frozenset(woken)
    names = [f.name for f in facts]
    unknown = sorted(set(options.threads) - set(names))
    if unknown:
        raise CommandLineError(f"--threads: no activity {', '.join(map(repr, unknown))} in application {application}; "
                        f"{did_you_mean(unknown[0], names)}")
    planned = {f.name: _place(f, f.name in woken, options) for f in facts}
    return Deployment(application, options, dict(processes or {LAUNCHER: None}), planned)


def _place(facts: ActivityFacts, woken: bool, options: LaunchOptions) -> ActivityDeployment:
    """The rules of the module's docstring, for one activity."""
    driving = Driving.MAIN if facts.main else Driving.THREAD
    if options.host is Host.PLAIN:
        return ActivityDeployment(facts, driving, "main activity" if facts.main else "", woken)
    reason = _own_thread_reason(facts, woken, options)
    if reason is None:
        return ActivityDeployment(facts, Driving.WAIT_SET if options.wait_sets else Driving.EXECUTOR, "", False)
    return ActivityDeployment(facts, driving, reason, woken)


def _own_thread_reason(facts: ActivityFacts, woken: bool, options: LaunchOptions) -> str | None:
    """Why the ROS host leaves ``facts``'s activity a thread of its own; None: rclpy hosts it."""
    if facts.main:
        return "main activity"
    if woken:
        return "woken by another process"
    if options.all_threads or facts.name in options.threads:
        return "asked on the command line"
    request = facts.scheduling
    if request != SchedulingRequest():
        asked = [name for name, value in (("affinity", request.affinity), ("realtime", request.realtime != "none"),
                                          ("priority", request.priority is not None),
                                          ("nice", request.nice is not None)) if value]
        return f"thread placement: {', '.join(asked) or 'scheduling request'}"
    if facts.period is not None and facts.period < THREAD_PERIOD:
        return f"period {facts.period * 1e3:g} ms < {THREAD_PERIOD * 1e3:g} ms"
    if facts.thread_bound:
        plural = "s" if len(facts.thread_bound) > 1 else ""
        return f"thread-bound component{plural} {', '.join(facts.thread_bound)}"
    return None


def of_application(app: Application, options: LaunchOptions = LaunchOptions()) -> Deployment:
    """The deployment of an application built in code (no file: one process, nothing woken from
    another), from its activities' own facts: for a program that hosts an application it built
    itself (``coco_ros.hosting.ExecutorHost`` in a script, a benchmark)."""
    return plan(app.name, (ActivityFacts.of_activity(a) for a in app.activities.values()), (), options)


def verify(app: Application, deployment: Deployment) -> None:
    """Check that this process's activities are those the plan was made for and are driven as
    planned; a :class:`~coco_core.errors.DeploymentError` says what differs. It guards against the
    plan and the run drifting apart again: a difference is a bug of CoCo, not of the file."""
    problems = []
    for name, activity in app.activities.items():
        planned = deployment.activities.get(name)
        if planned is None:
            problems.append(f"activity {name} is not in the deployment plan")
            continue
        if activity.process != app.process:
            continue  # another process's: it verifies its own
        built = ActivityFacts.of_activity(activity)
        if built != planned.facts:
            problems.append(f"activity {name}: planned from {planned.facts}, built as {built}")
        driver = activity.driver
        if (driver.driving, driver.eventfd is not None) != (planned.driving, planned.eventfd):
            problems.append(f"activity {name}: planned {planned.line()!r}, driven by {type(driver).__name__} "
                            f"({driver.driving.value}{', eventfd' if driver.eventfd is not None else ''})")
    if problems:
        raise DeploymentError("the run differs from the deployment plan (a bug of CoCo): " + "; ".join(problems))


def drive(app: Application, deployment: Deployment, eventfds: Mapping[str, int]) -> None:
    """Give this process's activities of ``app`` the thread drivers the plan names (own thread, main
    thread; woken by the eventfd of ``eventfds`` when the plan says another process wakes it), before
    the application starts. The ROS host drives the activities it hosts (wait set, executor) itself.
    A wake-up eventfd the process level made for an activity that the plan does not wake so, or the
    reverse, is a :class:`~coco_core.errors.DeploymentError`."""
    mine = {name for name, activity in app.activities.items() if activity.process == app.process}
    made = set(eventfds) & mine
    planned = {name for name in mine if name in deployment.activities and deployment.activities[name].eventfd}
    if made != planned:
        raise DeploymentError(f"process {app.process or 'launcher'}: the channels between processes wake "
                              f"{sorted(made)}, the deployment plan {sorted(planned)} (a bug of CoCo)")
    for name in sorted(mine):
        placed = deployment.activities.get(name)
        if placed is None or placed.driving not in (Driving.THREAD, Driving.MAIN):
            continue  # not planned (verify says so), or the ROS host's
        driver = MainThreadDriver if placed.driving is Driving.MAIN else ThreadDriver
        app.activities[name].drive_with(driver(eventfds.get(name)))


def deployed(app: Application, deployment: Deployment) -> None:
    """Check this process's drivers against the plan (:func:`verify`), then log where each of its
    activities runs, in the words ``--check`` printed: ``process P: activity A: ... -> ...``."""
    verify(app, deployment)
    for placed in deployment.of_process(app.process):
        log.info("process %s: %s", app.process or "launcher", placed.line())
