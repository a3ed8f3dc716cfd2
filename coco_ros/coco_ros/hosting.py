"""Hosting CoCo activities in an rclpy node: a wait set per activity, callback groups of an executor, or threads.

Each activity hosted by rclpy is one callback group of the launcher's node, so its components never
run concurrently with each other while different activities run in parallel. Who runs the group's
callbacks:

- by default an :class:`~coco_ros.wait_set.ActivityWaitSet`: a thread of the activity's own that waits
  on the group's entities only and runs their callbacks itself (a :class:`~coco_ros.wait_set.WaitSetGroup`,
  which the node's executor leaves alone). No wait set of the whole node rebuilt after every
  callback, no hand-off from the executor's thread to a worker: the default layout answers as fast
  as a plain rclpy node on a ``SingleThreadedExecutor`` (``docs/benchmarks.md``, Figure 6);
- with ``wait_sets=False`` (the launcher's ``--executor-threads N``) the node's executor: the group is
  a ``MutuallyExclusiveCallbackGroup`` and the executor's threads (N of them) run all groups.

Either way:

- a *periodic* activity is a timer (steady clock) in its group. Its callbacks are measured against
  the ideal time grid: the lateness goes into ``activity.stats`` (``--profile`` shows it as the
  period error) and a callback that starts more than one period after its deadline counts as an
  overrun, the deadlines it missed being skipped, as the activity's own thread does;
- a *triggered* activity is a guard condition in its group, triggered by the activity's ``wake``:
  data on an event port, an operation queued to it, or an explicit ``wake()``. Wake-ups that arrive
  during a cycle cause one more cycle; none is lost. Wake-ups are coalesced: while one is pending,
  the next trigger nothing; one from inside the group's own callbacks is served at the end of that
  callback (one guard condition trigger at most); and a ROS entity callback wrapped by
  :func:`activity_callback` (a ROSInterface subscription) runs the cycle its data asked for right
  after it, in the same callback: the guard condition round trip (trigger, wake-up, wait-set
  rebuild, and on the executor a dispatch to a worker) is the costliest hop of a pipeline, measured
  in ``docs/benchmarks.md`` (Figure 6). The same holds between activities (the *chain*): a triggered
  activity woken by a hosted activity's callback runs its cycle in that callback, right after, as
  itself and under its own lock (``ExecutorDriver.busy``: its own callbacks wait for it, and a
  wake-up while one of them runs goes to its guard condition), so a pipeline of triggered
  activities crosses all its stages in the callback that brought the message. A triggered activity
  whose schedule has a ``min_period`` also has a one-shot timer in its group: a cycle due sooner than
  ``min_period`` after its last cycle began does not run; its wake-up stays pending (the later ones
  coalesce into it) and the timer, set to the time left, runs the one cycle at the bound. No
  callback ever sleeps for the bound: a sleep would hold the executor thread or the wait set that
  runs other activities' chained cycles and this group's other entities, and a stop, which the
  group's next callback serves, would wait for it.

Every callback makes the activity the thread's *current activity* while it runs (executor threads
are shared, and a chained cycle runs in another activity's thread, so operations called from a
component must know whose thread they are in). The first callback of an activity configures its
components; its cycles begin with the first callback after the application's start gate opened
(:mod:`coco_core.lifecycle`: every activity of every process configured), which the gate's opening
triggers, so no callback ever waits for the others; the activity's last callback runs ``finish``
(``on_stop``), inside its group, after the application asked for a stop. ``on_config``,
``on_update`` and ``on_stop`` of a hosted activity may therefore run on *different* threads (never
at the same time): a component that holds a thread-bound resource (an OpenGL context, a
thread-affine device SDK) needs a dedicated thread.

Which activities keep a thread of their own (coco_core's thread drivers) instead is decided by the
deployment plan (:mod:`coco_core.deployment`), which ``--check`` prints and every process executes;
see ``docs/ros.md`` for the rule and the measured numbers behind it.

How rclpy attaches to an activity: an :class:`ExecutorDriver` is the activity's driver
(``Activity.drive_with``, the protocol of :mod:`coco_core.drivers`), whether a wait set or the
executor runs its group, so event ports, queued operations, ``Application.stop``,
``Application.set_period`` and ``Application.in_flight`` reach it through the activity's own
methods; nothing is replaced on the activity.
"""

from __future__ import annotations

import functools
import logging
import math
import threading
import time
from typing import TYPE_CHECKING, Callable

from coco_core import Activity, Application, CocoError, Component
from coco_core.deployment import Driving, HostDeployment
from coco_core.errors import did_you_mean
from coco_core.period import PeriodGrid
from coco_core.operations import set_current_activity
from .deployment import ExecutorPlan
from .wait_set import ActivityWaitSet, WaitSetGroup
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.clock import Clock, ClockType

if TYPE_CHECKING:
    from rclpy.callback_groups import CallbackGroup
    from rclpy.context import Context
    from rclpy.executors import Executor
    from rclpy.guard_condition import GuardCondition
    from rclpy.node import Node
    from rclpy.timer import Timer

log = logging.getLogger("coco")

MULTI_POLL = 0.1
"""Seconds a multi-threaded executor's spin waits at most (see :class:`ExecutorThread`)."""

PARKED_NS = 86_400 * 10**9
"""The period (a day) a stopped activity's timer, and an idle ``min_period`` timer, are parked at."""
CHAIN_LIMIT = 64
"""Cycles one executor callback runs at most for the activities its data woke (the rest get their
guard conditions): a chain that keeps waking itself cannot hold an executor thread for ever."""

_CHAIN = threading.local()
"""``queue``: the hosted triggered activities woken by the executor callback this thread runs, whose
cycles it runs before it returns (None outside such a callback)."""


class ExecutorDriver:
    """The driver (:class:`coco_core.drivers.Driver`) of one activity hosted by rclpy: its callback
    group, guard condition and (periodic) timer, run by its wait set or by the node's executor. The
    activity keeps its own class and methods: its ``wake``, ``stop``, ``set_period`` and ``join``
    come here because this is its driver."""

    eventfd = None
    """Other processes never wake a hosted activity: the plan gives such an activity a thread."""

    def __init__(self, host: ExecutorHost, activity: Activity, group: MutuallyExclusiveCallbackGroup,
                 server: ActivityWaitSet | None = None) -> None:
        self.host = host
        self.activity = activity
        self.group = group
        self.server = server
        """The thread that waits on this activity's entities (a :class:`WaitSetGroup`), or None when
        the node's executor runs the group's callbacks."""
        self.driving = Driving.HOSTED
        self.started = False
        self.configured = False
        self.running = False
        """Configured, and the application's start gate open: cycles run."""
        self.pending = False
        """A wake-up (data, a queued operation) not yet served by a cycle."""
        self.closed = False
        self.inside = False
        """A callback of this activity's group runs now (the group lets one run at a time): a wake-up
        then only marks ``pending``, and that callback serves it when it ends."""
        self.busy = threading.Lock()
        """Held while this activity's components run, by its own callbacks and by a cycle another
        activity's callback runs for it (the chain): the callback group alone cannot keep those two
        apart, since a chained cycle runs in another group's callback."""
        self.chained = activity.schedule.period is None
        """Whether a wake-up from another hosted activity's callback runs this one's cycle in that
        callback (triggered activities) rather than through the guard condition."""
        node = host.node
        self.guard: GuardCondition = node.create_guard_condition(self._on_guard, callback_group=group)
        self.timer: Timer | None = None
        self.grid: PeriodGrid | None = None
        """A periodic activity's time grid, against which the timer's callbacks are measured."""
        self._lock = threading.Lock()
        self.min_period = activity.schedule.min_period
        """Triggered: seconds from the start of one cycle to the start of the next, at least (0: none)."""
        self.began = float("-inf")
        """When the last cycle began (``time.perf_counter``), kept when there is a ``min_period``."""
        self.held = False
        """A pending wake-up waits for ``min_period``: the ``bound`` timer serves it (changed under ``busy``)."""
        self.bound: Timer | None = None
        """The one-shot timer that runs the cycle held for ``min_period``; parked while none is."""
        if self.min_period:
            self.bound = node.create_timer(self.min_period, self._on_bound, callback_group=group,
                                           clock=host.clock, autostart=False)
        period = activity.schedule.period
        if period is not None:
            self.grid = PeriodGrid(period, activity.stats)
            self.timer = node.create_timer(period, self._on_timer, callback_group=group, clock=host.clock,
                                           autostart=False)
        activity.drive_with(self)  # a wake-up pending from before (data written early) comes along

    # --- the driver protocol (called through the activity) ---------------------------------------
    def start(self, activity: Activity) -> None:
        """The executor's first callback of this group configures the activity."""
        self.started = True
        self._trigger()

    def wake(self) -> None:
        """Trigger the guard condition only when no wake-up is pending: a pending one already has a
        trigger (or the running callback, ``inside``) that will serve it, and the cycle it leads to
        clears ``pending`` before reading the ports, so it sees this wake-up's data too. Every
        trigger saved is an executor wake-up, wait-set rebuild and dispatch of an empty callback."""
        if self.pending:
            return
        self.pending = True
        if self.inside or not self.started:
            return
        queue = getattr(_CHAIN, "queue", None)
        if queue is not None and self.chained and self.running:
            queue.append(self)  # the callback running in this thread runs the cycle before it returns
        else:
            self._trigger()

    @property
    def wake_pending(self) -> bool:
        return self.pending

    def stop(self) -> None:
        """The activity is marked stopping: a timer callback now returns at once, and the group's
        next callback runs ``finish`` (``on_stop``)."""
        if self.timer is not None and not self.closed:
            # Park the timer rather than cancel it: cancelling races with an executor that already
            # took it as ready (rclpy then fails in call_timer). close() destroys it after the spin.
            with self._lock:
                self.timer.timer_period_ns = PARKED_NS
                self.timer.reset()
        self._trigger()

    def set_period(self, period: float) -> None:
        """A new period (checked and stored by the activity): the next cycle comes one new period
        from now (an rclpy timer restarts from its reset), and the grid continues from it."""
        assert self.grid is not None and self.timer is not None  # only a periodic activity has a period
        with self._lock:
            now = time.perf_counter()
            self.grid.change_period(period, now)
            if self.activity.stopping:  # the timer stays parked
                return
            self.timer.timer_period_ns = int(round(period * 1e9))
            if self.running:
                self.timer.reset()  # the timer's next call is one new period from now: so is the grid's
                self.grid.begin(now + period)
        self._rewait()  # the current wait was computed with the old period

    def _rewait(self) -> None:
        """Have the wait set (or the executor) that waits on this group's entities wait again: it
        computes its timeout from the group's timers anew, after one of them changed."""
        if self.server is not None:
            self.server.wake()
        elif self.host.node.executor is not None:
            self.host.node.executor.wake()

    def join(self, timeout: float | None = None) -> bool:
        return self.activity.wait_finished(timeout) if self.started else True

    # --- callbacks, each inside the activity's mutually exclusive group ------------------------
    def _leave(self) -> None:
        """End of a callback of the group: a wake-up that came meanwhile gets its cycle. ``inside`` is
        cleared before ``pending`` is read, so a wake-up from another thread is never lost: either it
        sees ``inside`` False and triggers, or this sees its ``pending``."""
        queue, _CHAIN.queue = _CHAIN.queue, None
        for driver in queue or ():  # woken after the last cycle (a bug guard's exit): their guards
            driver._trigger()
        set_current_activity(None)
        self.inside = False
        self.busy.release()
        if self.pending and self.running and not self.held:  # before the start gate opens, its opening
            self._trigger()  # triggers; a held wake-up is the bound timer's

    def _trigger(self) -> None:
        if self.closed:
            return
        try:
            self.guard.trigger()
        except Exception:  # destroyed at shutdown: a late writer has nothing left to wake
            pass

    def _on_guard(self) -> None:
        activity = self.activity
        if not self.started or activity.finished:
            return
        self._enter()
        try:
            if activity.stopping:
                activity.finish()
                return
            if not self.configured:
                self.configured = True
                activity.configure()
                activity.when_may_run(self._trigger)  # the callback that runs the first cycle
            if activity.stopping:
                activity.finish()
                return
            if not self.running:
                if not activity.may_run:
                    return  # data written meanwhile stays pending for the first cycle
                self.running = True
                if self.grid is not None:
                    self._begin_grid(self.grid)  # and run the first cycle now, as a thread driver does
                    activity.cycle()
                    return
            self._serve()
        except Exception:  # components isolate their own errors; this is a bug guard
            self._crashed()
        finally:
            self._leave()

    # --- the chain: a pipeline of hosted activities in the callback its data came in -------------
    def _enter(self) -> None:
        """Start of a callback of the group: this activity's components are this thread's, and the
        activities it wakes are run by this callback (``_CHAIN.queue``) instead of being triggered."""
        self.busy.acquire()  # only a chained cycle on another thread can hold it: a cycle's length
        self.inside = True
        set_current_activity(self.activity)
        _CHAIN.queue = []

    def _serve(self) -> None:
        """The cycles the callback's data asked for, in this callback: this activity's, then one of
        each activity it woke, in the order woken (their own wake-ups join the chain), with one more
        of this activity's after each if they woke it (a reply), up to :data:`CHAIN_LIMIT` cycles.
        Saved per hop: the guard condition round trip (trigger, executor wake-up, wait-set rebuild,
        dispatch to a worker thread), the costliest part of a pipeline's latency on the executor.
        A wake-up that comes from elsewhere during the last cycle goes to the guard condition, so a
        busy activity does not keep this executor thread."""
        queue = _CHAIN.queue
        budget, own = CHAIN_LIMIT, True
        while budget:
            if own and self._cycle_pending():
                own = False
                budget -= 1
            elif queue:
                queue.pop(0)._run_chained()
                budget -= 1
                own = True
            else:
                break
        for driver in queue:  # beyond the budget: served by their guard conditions
            driver._trigger()
        queue.clear()

    def _cycle_pending(self) -> bool:
        """The activity's cycle, when a wake-up is pending, the activity still runs and its
        ``min_period`` has passed since the last cycle began (else the wake-up is held for the bound
        timer); whether it ran (the caller holds ``busy``)."""
        activity = self.activity
        if not self.pending or self.held or activity.stopping or activity.finished:
            return False
        if self.bound is not None:
            now = time.perf_counter()
            remaining = self.began + self.min_period - now
            if remaining > 0:
                self._hold(self.bound, remaining)
                return False
            self.began = now
        self.pending = False
        set_current_activity(activity)
        activity.cycle()
        return True

    def _run_chained(self) -> None:
        """Run this activity's pending cycle in the calling callback (another activity's). When its
        own callback or another chain runs it now, or it is woken again meanwhile, its guard
        condition serves the wake-up."""
        if not self.busy.acquire(blocking=False):
            self._trigger()
            return
        self.inside = True
        try:
            self._cycle_pending()
        except Exception:  # components isolate their own errors; this is a bug guard
            self._crashed()
        finally:
            self.inside = False
            self.busy.release()
        if self.pending and not self.held:
            self._trigger()

    # --- min_period: a one-shot timer instead of a sleep ----------------------------------------
    def _hold(self, bound: Timer, remaining: float) -> None:
        """Keep the pending wake-up for ``bound`` to serve in ``remaining`` seconds (the caller
        holds ``busy``): the timer restarts with that period, and the wait that waits on it again."""
        self.held = True
        with self._lock:
            bound.timer_period_ns = max(1, math.ceil(remaining * 1e9))
            bound.reset()
        self._rewait()

    def _on_bound(self) -> None:
        """The ``min_period`` since the last cycle began has passed: the held wake-up gets its cycle
        (and the chain its data woke). The timer is parked, not cancelled: a cancel races with an
        executor that already took it as ready (see :meth:`stop`)."""
        bound = self.bound
        assert bound is not None  # the timer of an activity with a min_period
        with self._lock:
            bound.timer_period_ns = PARKED_NS
            bound.reset()
        if not self.started or self.activity.finished:
            return
        self._enter()
        try:
            self.held = False
            if self.running:
                self._serve()
        except Exception:  # components isolate their own errors; this is a bug guard
            self._crashed()
        finally:
            self._leave()

    def run_entity_callback(self, callback: Callable[..., None], *args: object) -> None:
        """A ROS entity callback of this group (so never during a cycle), as the activity, then at
        once the cycle its writes asked for: the data reaches the components in this executor
        callback instead of one guard condition round trip later."""
        self._enter()
        try:
            callback(*args)
            if self.running:
                try:
                    self._serve()
                except Exception:  # components isolate their own errors; this is a bug guard
                    self._crashed()
        finally:
            self._leave()

    def _begin_grid(self, grid: PeriodGrid) -> None:
        assert self.timer is not None
        with self._lock:
            self.timer.reset()  # starts the timer: its grid begins now
            grid.begin(time.perf_counter() + self.timer.time_until_next_call() / 1e9)

    def _on_timer(self) -> None:
        now = time.perf_counter()
        activity = self.activity
        if not self.running or activity.stopping:
            return
        assert self.grid is not None  # only a periodic activity has a timer
        with self._lock:
            self.grid.fired(now)
        self._enter()
        try:
            activity.cycle()
            self._serve()  # the activities its cycle woke (and one more of its own for a queued operation)
        except Exception:
            self._crashed()
        finally:
            self._leave()

    def _crashed(self) -> None:
        log.exception("activity %s: its executor callback failed; stopping the application", self.activity.name)
        app = self.host.app
        app.request_stop(f"activity {self.activity.name} failed", hard=True)

    def close(self) -> None:
        """End the wait set's thread, then destroy the timer and the guard condition (after the
        executor stopped spinning)."""
        if self.server is not None:
            self.server.stop()
        self.closed = True
        for timer in (self.timer, self.bound):
            if timer is not None:
                self.host.node.destroy_timer(timer)
        self.host.node.destroy_guard_condition(self.guard)


class ExecutorHost:
    """Runs ``app``'s activities in ``node`` as ``deployment`` plans them: each in a wait set of its
    own (the default) or as callback groups of the node's executor; the others have the thread
    drivers :func:`coco_core.deployment.drive` gave them.

    Create it after the application was built and before ``app.start()``; add ``node`` to the
    executor of :meth:`create_executor` and spin it, and :meth:`start` the wait sets, while the
    application runs (the executor runs what no wait
    set does: the node's parameter services, the entities of components in no activity or in an
    activity on its own thread, and without wait sets the hosted activities, which then need as many
    threads to run in parallel: the plan's :class:`~coco_ros.deployment.ExecutorPlan`). After ``app.stop()``, stop spinning and
    call :meth:`close`, which also ends the wait sets' threads.

    Every activity, hosted or not, gets a mutually exclusive callback group (:meth:`callback_group`):
    the ROS entities of its components (subscriptions, timers) belong there, so that they never run
    at the same time as the activity's cycle when it is hosted.
    The host is the application's (``app.host``), and so the node is reachable from any component
    (:func:`ros_node`, :func:`callback_group`).
    """

    def __init__(self, node: Node, app: Application, deployment: HostDeployment) -> None:
        self.node = node
        self.app = app
        self.deployment = deployment
        plan = deployment.process(app.process).host
        if not isinstance(plan, ExecutorPlan):
            raise CocoError(f"process {app.process or 'launcher'} of application {app.name} was not planned for an "
                            "rclpy node (coco_ros.deployment.RosRules)")
        self.plan = plan
        """The process's executor as planned: a wait set per hosted activity (an
        :class:`ActivityWaitSet`) or callback groups in the executor's shared threads, and how many."""
        self.clock = Clock(clock_type=ClockType.STEADY_TIME)
        """Activity timers run on the steady clock, like the activities' own threads (not /clock)."""
        self.groups: dict[str, MutuallyExclusiveCallbackGroup] = {}
        self.hosted: dict[str, ExecutorDriver] = {}
        for name, activity in app.activities.items():
            if activity.process != app.process or deployment.activities[name].driving is not Driving.HOSTED:
                self.groups[name] = MutuallyExclusiveCallbackGroup()  # its components' ROS entities
            elif plan.wait_sets:
                group = self.groups[name] = WaitSetGroup()
                server = ActivityWaitSet(group, node.context, name,
                                         on_error=functools.partial(app.request_stop, hard=True))
                self.hosted[name] = ExecutorDriver(self, activity, group, server)
            else:
                self.groups[name] = MutuallyExclusiveCallbackGroup()
                self.hosted[name] = ExecutorDriver(self, activity, self.groups[name])
        app.hosted_by(self)

    def callback_group(self, activity: Activity | str) -> CallbackGroup:
        """The callback group of ``activity`` (by object or name)."""
        name = activity if isinstance(activity, str) else activity.name
        try:
            return self.groups[name]
        except KeyError:
            raise CocoError(f"no activity {name!r} in application {self.app.name}; "
                            f"{did_you_mean(name, self.groups)}") from None

    def create_executor(self, threads: int | None = None, context: Context | None = None) -> Executor:
        """The executor to add the node to: a ``MultiThreadedExecutor`` with ``threads`` workers
        (default: the plan's, :meth:`coco_ros.deployment.RosRules.settings`), or for one thread a
        ``SingleThreadedExecutor``.

        One thread is not a ``MultiThreadedExecutor(num_threads=1)``: that one still hands every
        callback to its worker while its spinning thread polls the wait set again, which costs (rclpy
        7.1, measured with one hosted activity at 100 messages/s) 1.5-6x the CPU of running the callback
        in the spinning thread and a tail of tens to hundreds of milliseconds (docs/benchmarks.md,
        Figure 6).
        """
        from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor

        threads = threads or self.plan.threads
        if threads == 1:
            return SingleThreadedExecutor(context=context)
        return MultiThreadedExecutor(num_threads=threads, context=context)

    def start(self) -> None:
        """Start the wait sets' threads: call it when the executor starts spinning (after
        ``app.start()``, which has the first callback of every hosted activity configure it)."""
        for hosted in self.hosted.values():
            if hosted.server is not None:
                hosted.server.start()

    def close(self) -> None:
        """Release the timers and guard conditions; call after the executor stopped spinning."""
        for hosted in self.hosted.values():
            hosted.close()


class ExecutorThread:
    """Spins an executor in a thread of its own until :meth:`stop`.

    ``Executor.shutdown()`` destroys the executor's guard condition while handlers it already handed
    to its worker threads may still use it (rclpy then reports an ``InvalidHandle`` that was "never
    retrieved"); stopping the spin loop and leaving the executor alive avoids that race. An exception
    from a handler is given to ``on_error`` and the loop goes on, so that activities can still finish.

    ``poll`` is the longest wait of one spin. By default a ``SingleThreadedExecutor`` waits without
    one: every callback, :meth:`stop` (a future the spin waits for, and ``executor.wake()``) and a ROS
    shutdown (rclpy wakes its executors) end the wait, and rclpy creates a timer for every wait that
    has a timeout (about 20 us per executor callback, measured). Another executor polls every
    :data:`MULTI_POLL` seconds: rclpy 7.1's ``MultiThreadedExecutor`` can miss a wake-up (a guard
    condition ping-pong between two callback groups of a node without parameter services stalled
    about 15 ms per hop without a timeout), which the poll bounds.
    """

    def __init__(self, executor: Executor, on_error: Callable[[str], None] | None = None,
                 poll: float | None = None) -> None:
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.task import Future

        self.executor = executor
        self.on_error = on_error
        if poll is None and not isinstance(executor, SingleThreadedExecutor):
            poll = MULTI_POLL
        self.poll = poll
        self._done = Future()
        """Done when :meth:`stop` was called: the spin's wait condition."""
        self._thread = threading.Thread(target=self._loop, name="coco:executor", daemon=True)

    def start(self) -> ExecutorThread:
        self._thread.start()
        return self

    def _loop(self) -> None:
        from rclpy.executors import ExternalShutdownException

        executor, done = self.executor, self._done
        while not done.done():
            if not executor.context.ok():
                if self.on_error is not None:
                    self.on_error("ROS was shut down")
                return
            try:
                executor.spin_once_until_future_complete(done, timeout_sec=self.poll)
            except ExternalShutdownException:  # the single-threaded executor's way to say it
                continue
            except Exception:
                log.exception("the ROS executor failed")
                if self.on_error is not None:
                    self.on_error("the ROS executor failed")

    def stop(self, timeout: float = 1.0) -> bool:
        """End the spin loop; False when it did not end within ``timeout`` seconds."""
        if not self._done.done():
            self._done.set_result(None)
        try:
            self.executor.wake()
        except Exception:  # the context is already shut down
            pass
        if self._thread.is_alive():
            self._thread.join(timeout)
        return not self._thread.is_alive()


def ros_node(app_or_component: Application | Component) -> Node:
    """The rclpy node hosting the application (what ROS bridges create their entities on).

    Raises :class:`CocoError` when the application is not run by the ROS launcher.
    """
    app = app_or_component.app if isinstance(app_or_component, Component) else app_or_component
    return _host_of(app).node


def _host_of(app: Application | None) -> ExecutorHost:
    """The ROS host of ``app``, or the error that says how to run it with one."""
    host = app.host if app is not None else None
    if not isinstance(host, ExecutorHost):
        raise _not_hosted(app)
    return host


def _not_hosted(app: Application | None) -> CocoError:
    """The explanation for an application that the ROS launcher does not run (it has no node or host)."""
    name = app.name if app is not None else "(none)"
    return CocoError(f"application {name} has no ROS node: run it with the ROS launcher "
                     "(ros2 run coco_ros launcher app.xml), not coco-launch")


def _scheduled(component: Component) -> tuple[ExecutorHost, Activity | None]:
    """The host of ``component``'s application and the activity that runs it (peers: their owner's)."""
    top = component
    while top.owner is not None:
        top = top.owner
    return _host_of(top.app), top.activity


def callback_group(component: Component) -> CallbackGroup:
    """The callback group of the activity that runs ``component`` (peers: their owner's)."""
    host, activity = _scheduled(component)
    if activity is None:
        return host.node.default_callback_group
    return host.callback_group(activity)


def activity_callback(component: Component, callback: Callable[..., None]) -> Callable[..., None]:
    """``callback`` made fit for a ROS entity in ``callback_group(component)`` (a subscription).

    When the executor hosts ``component``'s activity, the returned callback runs ``callback`` as that
    activity (``current_activity()``) and, if its writes woke the (triggered) activity, the activity's
    cycle right after it in the same executor callback: sound because the group never runs that
    callback during a cycle, and it saves the guard condition round trip to the next executor
    callback. On a dedicated thread the activity's own loop runs the cycle: ``callback`` is returned
    as it is.
    """
    host, activity = _scheduled(component)
    hosted = host.hosted.get(activity.name) if activity is not None else None
    if hosted is None:
        return callback
    return functools.partial(hosted.run_entity_callback, callback)
