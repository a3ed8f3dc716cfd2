"""The one deployment plan: hosts > processes > activities > drivers, planned once, executed everywhere.

Where and how everything of an application runs is settled here, once per launch, by one pure
function, :func:`plan_deployment`, from the parsed file (:class:`~coco_core.model.AppSpec`) and the
rules of the launch host (:class:`LaunchRules`). The result is one tree, :class:`Deployment`, as
OROCOS's DeploymentComponent holds one: its :meth:`Deployment.render` is what ``--check`` prints,
for every host, and each part of the run takes its branch of it instead of working anything out
again (so there is nothing left to disagree, and no cross-check at run time)::

    Deployment                    the file, the launch host's rules, the hosts' Where
    └── HostDeployment            one host's part (the file's whole when it declares no host)
        ├── placement             every activity's and component's process (Placement)
        ├── crossings             the connections between processes, with the activity each wakes
        └── ProcessPlan           one process: its activities' real-time class (RealtimeClass),
            │                     affinity, nice, memory lock, GC, its wake set, what its
            │                     launch host runs beside it (its own threads)
            └── ActivityDeployment  one activity: its schedule (ActivityFacts) and its driver, and why

Who consumes which part:

- the launchers (:mod:`coco_core.launcher` and every launch host's): the whole tree; ``--check``
  prints :meth:`Deployment.render`, a run executes :meth:`Deployment.host` of ``--host``;
- the builder (:func:`coco_core.builder.build_application`): a host's ``placement`` (which
  components and activities a process builds, which connections cross);
- the data-flow graph (:mod:`coco_core.dataflow_graph`): the whole tree (placement, hosts' Where);
- the process level (:mod:`coco_core.processes`): the supervisor makes one eventfd for each activity
  of a ``woken`` set and plans the shared-memory channels of the ``crossings``; each child applies
  its :class:`ProcessPlan`'s settings and drives its activities with :func:`drive`;
- a launch host's own driver: the activities planned ``HOSTED`` and its process's
  :attr:`ProcessPlan.host` settings (whatever the host runs beside the activities);
- :meth:`Application.start <coco_core.application.Application.start>`, for an application built in
  code that no launch planned: the plan of its own activities (:func:`drive_unplanned`). An activity
  has no driver of its own choosing, so these rules live here only.

The host level and the process level take their branches without knowing each other
(:mod:`coco_core.levels` has the protocols through which the launch joins them): the planner, above
both, cuts the hosts' parts and gives the host level every component's host and process
(:class:`~coco_core.hosts.part.Where`).

The rules, in order (``docs/processes.md`` has the measurements behind them):

- an activity of another process is that process's: the launcher holds a stand-in of it;
- the main activity runs in the launcher's main thread (some GUI toolkits need it);
- an activity that a write in another process wakes is woken through an eventfd (a kernel counter
  the writer's process increments), so it needs a thread of its own that waits on it;
- every other activity: the launch host's rules (:meth:`LaunchRules.decide`) say whether the host
  runs it with a driver of its own (``HOSTED``) or it has a thread of its own. The plain host
  (``coco-launch``, :class:`PlainRules`) gives every activity a thread; another launch host plugs
  its own rules in, from its own package, with its own words for what it hosts;
- a process's real-time class is its activities' summed up (:class:`RealtimeClass`, which says why
  it is no setting of the process's own).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, Iterable, Mapping, Protocol, Sequence

from . import registry
from .drivers import Driving, MainThreadDriver, ThreadDriver
from .errors import CocoError
from .lock_ceiling import CEILING_PRIORITY, applies as ceiling_applies
from .model import ActivitySpec, AppSpec, ComponentSpec, ProcessSpec
from .processes.channels import Crossing, crossings
from .processes.placement import LAUNCHER, Placement
from .schedule import DEFAULT_SPIN, Schedule
from .thread_placement import SchedulingRequest
from .wakeup import Wakeup

if TYPE_CHECKING:
    from .activity import Activity
    from .application import Application
    from .hosts.part import Where

log = logging.getLogger("coco")


@dataclass(frozen=True)
class ActivityFacts:
    """What the plan needs to know of one activity: read from the file when planning
    (:meth:`of_spec`), or from an activity built in code that has no file (:meth:`of_activity`)."""

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
    min_period: float = 0.0
    """Triggered: seconds from the start of one cycle to the start of the next, at least (0: none)."""

    def describe(self) -> str:
        """The schedule, then what the file asks beyond it (a spin, the thread's real-time class,
        priority, nice value and cores): ``periodic 1 ms, spin 0.6 ms, SCHED_FIFO priority 80``,
        ``triggered, at most every 16 ms, nice 10``."""
        words = [Schedule(self.period, min_period=self.min_period).describe()]
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
                   schedule.spin, schedule.min_period_ms / 1e3)

    @classmethod
    def of_activity(cls, activity: Activity) -> ActivityFacts:
        bound = tuple(c.name for top in activity.components for c in top.walk() if c.thread_bound)
        return cls(activity.name, activity.process, activity.period, activity.main, activity.scheduling,
                   bound, activity.schedule.spin, activity.schedule.min_period)


def _thread_bound(component: ComponentSpec) -> bool:
    """Whether the class of ``component`` is thread-bound; False for a class that cannot be found
    (``--check --allow-unknown`` leaves such a component out, and the build reports it otherwise)."""
    try:
        return registry.load(component.task, component.library).thread_bound
    except CocoError:
        return False


@dataclass(frozen=True)
class Decision:
    """A launch host's word on one activity that neither the main thread nor an eventfd claims."""

    hosted: bool
    """The host runs it with a driver of its own; else CoCo's thread driver, a thread of its own."""
    words: str = ""
    """Hosted: how the host runs it (``--check``'s words after the arrow); else why a thread of its
    own when that is not the host's default (empty when it is)."""


class HostSettings(Protocol):
    """What a launch host plans for one process beyond its activities (say, the threads that run
    what it hosts).
    Travels to the process with the plan: a frozen dataclass of the host's own package."""

    def describe(self) -> str:
        """``--check``'s words for it, after the process's own settings."""


class LaunchRules(Protocol):
    """What a launch host supplies to the planner, one extension point:
    the core plans processes, the main thread and eventfds; the host decides the rest of each
    activity and what runs beside a process's activities. Pure, like the planner."""

    def describe(self) -> str:
        """The ``deployment:`` line of ``--check``: which host, and how it runs what it hosts."""

    def check(self, activities: Sequence[str]) -> None:
        """Refuse options that name no activity of ``activities`` (a :class:`CommandLineError`)."""

    def decide(self, facts: ActivityFacts) -> Decision:
        """Host the activity of ``facts``, or give it a thread of its own (and why)."""

    def settings(self, activities: Sequence[ActivityDeployment], stand_ins: int) -> HostSettings | None:
        """What the host runs beside one process's ``activities`` (its own, planned), where the
        application also holds ``stand_ins`` activities of other processes; None: nothing."""


class PlainRules:
    """``coco-launch``: every activity on a thread of its own (:class:`LaunchRules`)."""

    def describe(self) -> str:
        return "plain (coco-launch: a thread per activity)"

    def check(self, activities: Sequence[str]) -> None:
        """The plain host takes no option that names activities."""

    def decide(self, facts: ActivityFacts) -> Decision:
        return Decision(False)

    def settings(self, activities: Sequence[ActivityDeployment], stand_ins: int) -> HostSettings | None:
        return None


PLAIN = PlainRules()


@dataclass(frozen=True)
class ActivityDeployment:
    """Where one activity runs, and why."""

    facts: ActivityFacts
    driving: Driving
    reason: str = ""
    """Why this driver (empty when it is the host's default)."""
    eventfd: bool = False
    """Woken through an eventfd by writes in another process."""
    words: str = ""
    """A hosted activity: how the launch host runs it, in the host's own words."""

    @property
    def name(self) -> str:
        return self.facts.name

    @property
    def process(self) -> str:
        return self.facts.process

    def line(self) -> str:
        """``activity NAME: SCHEDULE -> DRIVER (WHY)``: what ``--check`` prints and each process logs."""
        if self.driving is Driving.HOSTED:
            return f"activity {self.name}: {self.facts.describe()} -> {self.words}"
        driver = self.driving.value + (", woken by an eventfd" if self.eventfd else "")
        return f"activity {self.name}: {self.facts.describe()} -> {driver}" + (f" ({self.reason})" if self.reason else "")


@dataclass(frozen=True)
class RealtimeClass:
    """A process's real-time class: the plan's summary of the classes its activities' threads ask
    for (``<schedule realtime=... priority=...>``), and what follows from them for its other threads.

    Linux schedules threads, not processes, and CoCo asks for a real-time class where the deadline
    is, per activity; the rest of a real-time process follows from that: its other threads take the
    interpreter lock's ceiling (:mod:`coco_core.lock_ceiling`: the lowest real-time priority, below
    its loops, so a loop never waits for the lock behind the machine's normal work). A ``<process
    realtime=...>`` would be a second place to say it, with a rule for which wins, and could
    contradict the ceiling (other threads at the loop's priority or above: the loop then waits for
    them). So the plan derives the process's class once, from its activities: ``--check`` prints it
    on the process's line (which process holds real-time threads, at what priority, so which needs
    root, ``CAP_SYS_NICE`` or a real-time budget, and usually its memory locked beside it), and the
    child applies the ceiling from it (:mod:`coco_core.processes.child`), not from the file."""

    policy: str
    """``FIFO`` or ``RR``: the highest class's."""
    priority: int | None
    """The highest priority asked (None: none named, the OS's lowest)."""
    activities: tuple[str, ...]
    """Every activity of the process that asks for a real-time class, in file order."""
    priorities: tuple[int, ...]
    """Each one's priority (the lowest, :data:`~coco_core.lock_ceiling.CEILING_PRIORITY`, where it
    names none, as the OS applies it)."""
    ceiling: bool
    """Whether the process's other threads take the interpreter lock's ceiling
    (:mod:`coco_core.lock_ceiling`): a ``<process>``'s (the launcher's own runs everything else of
    the application) whose real-time activities leave room below them. Its child applies it."""

    @classmethod
    def of(cls, activities: Iterable[ActivityDeployment], child: bool) -> RealtimeClass | None:
        """The class of a process that runs ``activities`` (``child``: a ``<process>``, not the
        launcher's own); None when none asks for one."""
        asking = [placed.facts for placed in activities if placed.facts.scheduling.realtime != "none"]
        if not asking:
            return None
        highest = max(asking, key=lambda facts: (facts.scheduling.priority or 0, facts.scheduling.realtime == "FIFO"))
        priorities = tuple(facts.scheduling.priority or CEILING_PRIORITY for facts in asking)
        return cls(highest.scheduling.realtime, highest.scheduling.priority, tuple(facts.name for facts in asking),
                   priorities, child and ceiling_applies(priorities))

    def describe(self) -> str:
        """``real-time SCHED_FIFO priority 80 (haptics), other threads SCHED_FIFO 1 (the lock's
        ceiling)``: the highest class, who asks, and the ceiling when the process takes it."""
        priority = f" priority {self.priority}" if self.priority is not None else ""
        ceiling = f", other threads SCHED_FIFO {CEILING_PRIORITY} (the lock's ceiling)" if self.ceiling else ""
        return f"real-time SCHED_{self.policy}{priority} ({', '.join(self.activities)}){ceiling}"


@dataclass(frozen=True)
class ProcessPlan:
    """One process of a host: the launcher's (``""``, no ``<process>``) or a child. Its settings are
    applied by the child itself (:mod:`coco_core.processes.child`), from here, not from the file."""

    name: str
    activities: tuple[str, ...] = ()
    """Its activities, in file order."""
    affinity: tuple[int, ...] = ()
    """Cores the whole process may run on; empty: any."""
    nice: int | None = None
    lock_memory: bool = False
    gc: str = "auto"
    """``auto`` or ``between_cycles`` (:mod:`coco_core.garbage`)."""
    woken: frozenset[str] = frozenset()
    """Its activities that a write in another process wakes: each gets an eventfd and a thread."""
    host: HostSettings | None = None
    """What the launch host runs beside the activities (:meth:`LaunchRules.settings`)."""
    realtime: RealtimeClass | None = None
    """The real-time class of its activities' threads, summed up (see :class:`RealtimeClass` for why
    a summary and not a setting of its own); None: every thread in the normal class."""

    @classmethod
    def of(cls, spec: ProcessSpec | None, name: str, activities: Sequence[ActivityDeployment],
           host: HostSettings | None) -> ProcessPlan:
        """The plan of process ``name`` (``spec``: its ``<process>``; None: the launcher's) that runs
        ``activities``, planned."""
        names = tuple(placed.name for placed in activities)
        woken = frozenset(placed.name for placed in activities if placed.eventfd)
        realtime = RealtimeClass.of(activities, spec is not None)
        if spec is None:
            return cls(name, names, woken=woken, host=host, realtime=realtime)
        return cls(name, names, tuple(spec.affinity), spec.nice, spec.lock_memory, spec.gc, woken, host, realtime)

    @property
    def asks_nothing(self) -> bool:
        """Whether the process asks nothing of the OS or the launch host beyond what its activities
        ask each (a one-process application's tree then lists its activities alone)."""
        return not self._settings()

    def describe(self) -> str:
        """``real-time SCHED_FIFO priority 80 (haptics), affinity 2,3, nice -5, memory locked, gc
        between cycles, ...``: its activities' real-time class, then what it asks beyond the
        defaults, the launch host's settings last."""
        return ", ".join([self.realtime.describe()] + self._settings() if self.realtime is not None
                         else self._settings())

    def _settings(self) -> list[str]:
        words = [f"affinity {','.join(map(str, self.affinity))}" if self.affinity else "",
                 f"nice {self.nice}" if self.nice is not None else "",
                 "memory locked" if self.lock_memory else "",
                 "gc between cycles" if self.gc == "between_cycles" else "",
                 self.host.describe() if self.host is not None else ""]
        return [word for word in words if word]


@dataclass(frozen=True)
class HostDeployment:
    """One host's part of the plan: what one launch (and each of its child processes) executes."""

    spec: AppSpec
    """The host's part of the file (:func:`coco_core.hosts.part.host_part`), or the whole file."""
    rules: str
    """The launch host's :meth:`LaunchRules.describe`."""
    placement: Placement
    crossings: tuple[Crossing, ...]
    """The connections between two of its processes, in file order, each with the activity it wakes."""
    processes: Mapping[str, ProcessPlan]
    """The launcher's (``""``) first, then the children in file order."""
    activities: Mapping[str, ActivityDeployment]

    @property
    def name(self) -> str:
        """The host's name; empty when the file declares no host."""
        return self.spec.part_of

    @property
    def woken(self) -> frozenset[str]:
        """Every activity of the host that a write in another process wakes (one eventfd each)."""
        return frozenset(name for process in self.processes.values() for name in process.woken)

    def process(self, name: str) -> ProcessPlan:
        return self.processes[name]

    def of_process(self, process: str) -> list[ActivityDeployment]:
        return [self.activities[name] for name in self.processes[process].activities]


@dataclass(frozen=True)
class Deployment:
    """The plan of one launch: every host (one, named ``""``, when the file declares none), its
    processes and activities. What ``--check`` prints (:meth:`render`) and what every process runs."""

    spec: AppSpec
    """The whole file."""
    hosts: Mapping[str, HostDeployment]
    placement: Placement
    """The process of every activity and component of the whole file."""
    where: Where | None = None
    """The host and process of everything, when the file declares hosts."""

    @property
    def application(self) -> str:
        return self.spec.name

    def host(self, name: str | None = None) -> HostDeployment:
        """The part that host ``name`` runs (``--host``); None: the file's, which declares no host."""
        return self.hosts[name or ""]

    def render(self, parts: Mapping[str, Mapping[str, Application]] | None = None,
               notes: Mapping[str, Sequence[str]] | None = None) -> str:
        """What ``--check`` prints, every host in turn: processes with their settings, activities
        with their drivers and why, and with ``parts`` (every host's built processes: host ->
        process -> part) the components and connections; ``notes``: lines the launch host adds
        under a host (:mod:`coco_core.scheduling_tree`)."""
        from .scheduling_tree import render

        return render(self, parts or {}, notes or {})


def plan_deployment(spec: AppSpec, rules: LaunchRules = PLAIN, host: str | None = None) -> Deployment:
    """The deployment of ``spec`` under the launch host's ``rules``: every host's part, or only
    ``host``'s (a run with ``--host``; ``--check`` plans all). Pure (the file and the rules only)."""
    from .hosts.part import host_part

    placement = Placement.of(spec)
    if not spec.hosts:
        return Deployment(spec, {"": plan_host(spec, rules, placement)}, placement)
    where = _where(spec, placement)
    names = [host] if host is not None else [machine.name for machine in spec.hosts]
    parts = [host_part(spec, name, where) for name in names]
    return Deployment(spec, {part.part_of: plan_host(part, rules, Placement.of(part)) for part in parts}, placement,
                      where)


def _where(spec: AppSpec, placement: Placement) -> Where:
    """The host and process of everything in ``spec``: the process level's ``placement`` (every
    component's process, through the activity that runs its top-level owner) with each one's host,
    the host of that activity, or the first host for what no activity runs. Here, above both levels,
    since each level knows only its own."""
    from .hosts.part import Where

    hosts = tuple(host.name for host in spec.hosts)
    host_of = {activity.name: activity.host for activity in spec.activities}
    runs = {name: activity.host for activity in spec.activities for name in activity.components}
    return Where(hosts, {name: (host_of[name], process) for name, process in placement.of_activity.items()},
                 {name: (runs.get(placement.top_of[name], hosts[0]), process)
                  for name, process in placement.of_component.items()})


def plan_host(spec: AppSpec, rules: LaunchRules, placement: Placement) -> HostDeployment:
    """One host's part of the plan (``spec``: the host's part, or a file without hosts, whose
    ``placement`` the caller has)."""
    components = {component.name: component for component in spec.all_components()}
    crossed = tuple(crossings(spec, placement))
    woken = {crossing.wakes for crossing in crossed if crossing.wakes}
    facts = [ActivityFacts.of_spec(activity, components) for activity in spec.activities]
    rules.check([f.name for f in facts])
    planned = {f.name: _place(f, f.name in woken, rules) for f in facts}
    children = {process.name: process for process in spec.processes}
    processes = {}
    for name in [LAUNCHER, *children]:
        own = [a for a in planned.values() if a.process == name]
        stand_ins = len(planned) - len(own) if name == LAUNCHER else 0
        processes[name] = ProcessPlan.of(children.get(name), name, own, rules.settings(own, stand_ins))
    return HostDeployment(spec, rules.describe(), placement, crossed, processes, planned)


def _place(facts: ActivityFacts, woken: bool, rules: LaunchRules) -> ActivityDeployment:
    """The rules of the module's docstring, for one activity."""
    if facts.main:
        return ActivityDeployment(facts, Driving.MAIN, "main activity", woken)
    if woken:
        return ActivityDeployment(facts, Driving.THREAD, "", True)
    decision = rules.decide(facts)
    if decision.hosted:
        return ActivityDeployment(facts, Driving.HOSTED, words=decision.words)
    return ActivityDeployment(facts, Driving.THREAD, decision.words)


def of_application(app: Application, rules: LaunchRules = PLAIN) -> HostDeployment:
    """The deployment of an application built in code (no file: one process, nothing woken from
    another), from its activities' own facts: for a program that hosts an application it built
    itself (a launch host's driver in a script, a benchmark)."""
    facts = [ActivityFacts.of_activity(a) for a in app.activities.values()]
    rules.check([f.name for f in facts])
    planned = {f.name: _place(f, False, rules) for f in facts}
    own = [a for a in planned.values() if a.process == app.process]
    process = ProcessPlan.of(None, app.process, own, rules.settings(own, len(planned) - len(own)))
    return HostDeployment(AppSpec(name=app.name), rules.describe(), Placement(), (), {app.process: process}, planned)


def drive(app: Application, deployment: HostDeployment, eventfds: Mapping[str, Wakeup]) -> None:
    """Give this process's activities of ``app`` the thread drivers the plan names (own thread, main
    thread; woken by their eventfd of ``eventfds``, made for the plan's ``woken`` set), before the
    application starts. The launch host drives the activities the plan hosts itself."""
    for name in deployment.processes[app.process].activities:
        _give(app.activities[name], deployment.activities[name], eventfds)


def drive_unplanned(app: Application) -> None:
    """Give every activity of ``app`` that has no driver yet the one the plan of the application's
    own activities names (:func:`of_application`, the plain host's rules): what an application built
    in code, which no launch planned, gets from :meth:`Application.start
    <coco_core.application.Application.start>`. So the rules (a main activity in the calling
    thread, every other on a thread of its own) live here only, not restated by the activity; a
    driver given before (a launch's, a launch host's own, a program's) stays."""
    unplanned = [activity for activity in app.activities.values() if not activity.driven]
    if unplanned:
        plan = of_application(app)
        for activity in unplanned:
            _give(activity, plan.activities[activity.name], {})


def _give(activity: Activity, placed: ActivityDeployment, eventfds: Mapping[str, Wakeup]) -> None:
    """``activity``'s thread driver as ``placed`` says; nothing for one the launch host drives."""
    if placed.driving is Driving.HOSTED:
        return
    driver = MainThreadDriver if placed.driving is Driving.MAIN else ThreadDriver
    activity.drive_with(driver(eventfds[placed.name] if placed.eventfd else None))


def deployed(app: Application, deployment: HostDeployment) -> None:
    """Log where each of this process's activities runs, in the words ``--check`` printed:
    ``process P: activity A: ... -> ...``."""
    for placed in deployment.of_process(app.process):
        log.info("process %s: %s", app.process or "launcher", placed.line())
