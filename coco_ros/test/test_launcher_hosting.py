"""Activities hosted by an rclpy executor (coco_ros.hosting), in-process.

Each test builds a small application from test-local components, hosts it on a node of its own rclpy
context (domain 94, localhost only, set before rclpy.init; 201 for the ``min_period`` tests) and
stops it at teardown, even when the test fails half-way.
"""

from __future__ import annotations

import threading
import time
from typing import Callable, Iterator

import pytest
import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.context import Context
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node

from coco_core import (
    Application,
    BufferPolicy,
    CocoError,
    Component,
    ConnectionPolicy,
    InputPort,
    OutputPort,
    PeriodicActivity,
    SyncPolicy,
    TriggeredActivity,
    current_activity,
    operation,
)
from coco_core.deployment import HostDeployment, of_application
from coco_ros.deployment import RosRules
from coco_ros.hosting import (
    ExecutorHost,
    ExecutorThread,
    activity_callback,
    callback_group,
    ros_node,
)

BUFFERED = ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 1000)


def wait_until(predicate: Callable[[], object], timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.002)
    return True


class Counter(Component):
    """Writes 0, 1, 2, ... one value per update."""

    out = OutputPort(int)

    def init(self) -> None:
        self.count = 0

    def on_update(self) -> None:
        self.out.write(self.count)
        self.count += 1


class Recorder(Component):
    """Records its life cycle: phase, thread name and current activity of every call, and when each
    update began."""

    ev = InputPort(int, event=True)

    def init(self) -> None:
        self.events: list[tuple[str, str, object]] = []
        self.values: list[int] = []
        self.updates = 0
        self.starts: list[float] = []
        self.in_update = 0
        self.max_in_update = 0
        self.work = 0.0
        self.lock = threading.Lock()

    def _note(self, phase: str) -> None:
        activity = current_activity()
        self.events.append((phase, threading.current_thread().name, activity.name if activity else None))

    def on_config(self) -> None:
        self._note("on_config")

    def on_update(self) -> None:
        self.starts.append(time.perf_counter())
        with self.lock:
            self.in_update += 1
            self.max_in_update = max(self.max_in_update, self.in_update)
        self._note("on_update")
        self.values += self.ev.read_all()
        if self.work:
            time.sleep(self.work)
        self.updates += 1
        with self.lock:
            self.in_update -= 1

    def on_stop(self) -> None:
        self._note("on_stop")

    @operation
    def mark(self, label: str) -> str | None:
        """Runs in the component's activity: returns that activity's name."""
        self._note(f"op:{label}")
        activity = current_activity()
        return activity.name if activity else None

    def phases(self) -> list[str]:
        return [phase for phase, _, _ in self.events]


class Hosting:
    """One rclpy context, node and executor hosting one application, each hosted activity in a wait
    set of its own (``wait_sets``, the launcher's default) or as a callback group of the executor."""

    def __init__(self, wait_sets: bool = True) -> None:
        self.wait_sets = wait_sets
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = Node("coco_test_hosting", context=self.context)
        self.app: Application | None = None
        self.host: ExecutorHost | None = None
        self.spinner: ExecutorThread | None = None
        self.errors: list[str] = []

    def host_app(self, app: Application, threads: tuple[str, ...] = ()) -> ExecutorHost:
        self.app = app
        self.host = ExecutorHost(self.node, app, self.plan(app, threads))
        return self.host

    def plan(self, app: Application, threads: tuple[str, ...] = ()) -> HostDeployment:
        """The ROS host's deployment of ``app`` (``threads``: as ``--threads`` names them)."""
        return of_application(app, RosRules(threads, wait_sets=self.wait_sets))

    def spin(self) -> None:
        assert self.host is not None
        executor = self.host.create_executor(context=self.context)
        executor.add_node(self.node)
        self.host.start()
        self.spinner = ExecutorThread(executor, on_error=self.errors.append).start()

    def start(self, app: Application, threads: tuple[str, ...] = ()) -> ExecutorHost:
        host = self.host_app(app, threads)
        app.start()
        self.spin()
        return host

    def stop(self) -> bool:
        clean = self.app.stop() if self.app is not None else True
        if self.spinner is not None:
            assert self.spinner.stop(), "the spin loop did not end"
            self.spinner = None
        if self.host is not None and clean:
            self.host.close()  # ends the wait sets' threads
            self.host = None
        assert self.errors == [], self.errors
        return clean

    def close(self) -> None:
        try:
            self.stop()
        finally:
            self.node.destroy_node()
            self.context.try_shutdown()
            self.context.destroy()


def hosting_on(monkeypatch: pytest.MonkeyPatch, domain: str, wait_sets: bool) -> Iterator[Hosting]:
    """For a fixture: a :class:`Hosting` on DDS ``domain``, this host only, closed at teardown."""
    monkeypatch.setenv("ROS_DOMAIN_ID", domain)  # read by rclpy.init
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    rig = Hosting(wait_sets=wait_sets)
    yield rig
    rig.close()


@pytest.fixture(params=[True, False], ids=["wait sets", "executor"])
def hosting(monkeypatch: pytest.MonkeyPatch, request: pytest.FixtureRequest) -> Iterator[Hosting]:
    yield from hosting_on(monkeypatch, "94", request.param)


@pytest.fixture(params=[True, False], ids=["wait sets", "executor"])
def bounded_hosting(monkeypatch: pytest.MonkeyPatch, request: pytest.FixtureRequest) -> Iterator[Hosting]:
    """The ``min_period`` tests' own domain."""
    yield from hosting_on(monkeypatch, "201", request.param)


def pipeline(period: float = 0.01) -> tuple[Application, Counter, Recorder]:
    """counter (periodic) -> recorder (triggered, event port)."""
    app = Application("hosted")
    counter = app.add(Counter("counter"), PeriodicActivity("ticks", period))
    recorder = app.add(Recorder("recorder"), TriggeredActivity("events"))
    app.connect("counter.out", "recorder.ev", BUFFERED)
    return app, counter, recorder


# --- running on the executor ----------------------------------------------------------------------


def test_periodic_timer_and_triggered_guard_condition_run_every_sample(hosting: Hosting) -> None:
    app, counter, recorder = pipeline()
    host = hosting.start(app)
    assert set(host.hosted) == {"ticks", "events"}
    assert wait_until(lambda: len(recorder.values) >= 30)
    # No activity loop was started: the wait sets' threads (or the executor's workers) ran everything.
    names = {t.name for t in threading.enumerate()}
    assert not {"coco:ticks", "coco:events"} & names
    wait_sets = {"coco:ticks (wait set)", "coco:events (wait set)"}
    assert wait_sets <= names if hosting.wait_sets else not wait_sets & names
    assert hosting.stop()
    assert not wait_sets & {t.name for t in threading.enumerate()}, "a wait set's thread outlived the host"
    # Every sample in order, none lost or repeated (a sample written during the stop may stay unread).
    assert recorder.values == list(range(len(recorder.values)))
    ticks, events = app.activity("ticks"), app.activity("events")
    assert ticks.stats.cycles == counter.count
    assert events.stats.cycles >= 1
    # The timer's period error went into the activity's profile.
    summary = ticks.stats.error_summary()
    assert summary is not None and summary.samples == ticks.stats.cycles - 1
    update_threads = {thread for phase, thread, _ in recorder.events if phase == "on_update"}
    assert update_threads and not update_threads & {"coco:ticks", "coco:events", "coco:executor"}


def test_each_callback_runs_as_its_activity(hosting: Hosting) -> None:
    app, _, recorder = pipeline()
    hosting.start(app)
    assert wait_until(lambda: recorder.updates >= 5)
    assert hosting.stop()
    phases = recorder.phases()
    assert phases[0] == "on_config" and phases[-1] == "on_stop"
    assert phases.count("on_config") == 1 and phases.count("on_stop") == 1
    assert {activity for _, _, activity in recorder.events} == {"events"}, \
        "the current activity must be set in every executor callback, configure and stop included"


def test_triggered_activity_is_configured_at_start_and_runs_only_when_woken(hosting: Hosting) -> None:
    app = Application("quiet")
    source = app.add(Counter("source"))  # in no activity: the test writes for it
    recorder = app.add(Recorder("recorder"), TriggeredActivity("events"))
    app.connect("source.out", "recorder.ev", BUFFERED)
    hosting.start(app)
    assert wait_until(lambda: "on_config" in recorder.phases()), "on_config must not wait for data"
    time.sleep(0.2)
    assert recorder.updates == 0, "a triggered activity must not run without a trigger"
    source.out.write(7)  # from this thread: the event port triggers the guard condition
    assert wait_until(lambda: recorder.values == [7])
    app.activity("events").wake()
    assert wait_until(lambda: recorder.updates == 2)
    time.sleep(0.1)
    assert recorder.updates == 2, "one wake, one cycle"


def test_data_written_before_start_triggers_the_first_cycle(hosting: Hosting) -> None:
    app = Application("early")
    source = app.add(Counter("source"))
    recorder = app.add(Recorder("recorder"), TriggeredActivity("events"))
    app.connect("source.out", "recorder.ev", BUFFERED)
    source.out.write(42)
    hosting.start(app)
    assert wait_until(lambda: recorder.values == [42])


def test_a_pending_wake_of_a_hosted_activity_keeps_the_application_in_flight(hosting: Hosting) -> None:
    """A wake-up the executor has not served yet is data in flight: a producer that asks
    ``in_flight()`` before stopping (BagReplay's stop_at_end) must wait for it. The latest-value
    connection holds no queue, so only the hosted activity's pending wake-up says so."""
    app = Application("pending")
    source = app.add(Counter("source"))
    recorder = app.add(Recorder("recorder"), TriggeredActivity("events"))
    app.connect("source.out", "recorder.ev", ConnectionPolicy(BufferPolicy.DATA, SyncPolicy.LOCKED))
    hosting.host_app(app)
    app.start()  # the executor does not spin yet: nothing serves the wake-up
    assert not app.in_flight()
    source.out.write(7)
    assert app.activity("events").wake_pending
    assert app.in_flight(), "a pending wake-up of a hosted activity is data in flight"
    hosting.spin()
    assert wait_until(lambda: recorder.values == [7])
    assert wait_until(lambda: not app.in_flight())


def test_wakes_during_a_cycle_cause_one_more_cycle(hosting: Hosting) -> None:
    app = Application("busy")
    source = app.add(Counter("source"))
    recorder = app.add(Recorder("recorder"), TriggeredActivity("events"))
    app.connect("source.out", "recorder.ev", BUFFERED)
    recorder.work = 0.05
    hosting.start(app)
    assert wait_until(lambda: "on_config" in recorder.phases())
    writers = [threading.Thread(target=lambda: [source.out.write(i) for i in range(100)]) for _ in range(3)]
    for writer in writers:
        writer.start()
    for writer in writers:
        writer.join()
    assert wait_until(lambda: len(recorder.values) == 300), f"{len(recorder.values)} of 300 values read"
    assert recorder.max_in_update == 1, "the activity's cycles overlapped"


LATE_START = 0.005
"""Seconds from the driver's start of a cycle to its first component's update, at most (more than
microseconds only when the thread is preempted in between): the gaps between updates may be that
much shorter than the ``min_period`` between the cycles' starts."""


def test_a_min_period_holds_the_wake_ups_for_a_one_shot_timer_and_a_stop_does_not_wait(
        bounded_hosting: Hosting) -> None:
    """``view`` is woken every 10 ms by ``ticks``' cycles (the chain: in ticks' callback), ``slow``
    by this thread (its guard condition): each cycles no sooner than its min_period after its last
    cycle began, the last wake-up is served, and a stop ends a minute's wait at once."""
    min_period = 0.1
    app = Application("bounded")
    counter = app.add(Counter("counter"), PeriodicActivity("ticks", 0.01))
    view = app.add(Recorder("view"), TriggeredActivity("view", min_period=min_period))
    source = app.add(Counter("source"))  # in no activity: the test writes for it
    slow = app.add(Recorder("slow"), TriggeredActivity("slow", min_period=60.0))
    app.connect("counter.out", "view.ev", BUFFERED)
    app.connect("source.out", "slow.ev", BUFFERED)
    bounded_hosting.start(app)
    assert wait_until(lambda: len(view.starts) >= 4, timeout=20)
    ticks = app.activity("ticks")
    ticks.stop()
    assert wait_until(lambda: ticks.finished, timeout=20)
    assert wait_until(lambda: view.values[-1:] == [counter.count - 1] and not app.activity("view").wake_pending,
                      timeout=20), "the last value written is read"
    starts = list(view.starts)
    gaps = [later - earlier for earlier, later in zip(starts, starts[1:])]
    assert min(gaps) >= min_period - LATE_START, f"cycles {gaps} s apart, bound {min_period} s"
    assert view.values == list(range(counter.count)), "every value, none lost"
    assert len(starts) < counter.count, "the wake-ups within the bound got one cycle, not one each"

    source.out.write(0)
    assert wait_until(lambda: slow.values == [0], timeout=20), "the first wake-up waits for nothing"
    source.out.write(1)  # held: the next cycle may start a minute after the first
    asked = time.monotonic()
    assert bounded_hosting.stop()
    assert time.monotonic() - asked < 15, "the stop waited for the min_period"
    assert slow.values == [0, 1], "a natural stop drains what the held wake-up brought"


def test_operation_queued_to_a_triggered_activity_runs_in_it_before_its_cycle(hosting: Hosting) -> None:
    app = Application("ops")
    recorder = app.add(Recorder("recorder"), TriggeredActivity("events"))
    hosting.start(app)
    assert wait_until(lambda: "on_config" in recorder.phases())
    future = recorder.operation("mark")("from-test")
    assert future.result(timeout=5) == "events", "the call must run in the callee's activity"
    assert wait_until(lambda: recorder.updates == 1), "a queued call wakes a triggered activity"
    phases = recorder.phases()
    assert phases.index("op:from-test") < phases.index("on_update")
    op_thread = next(thread for phase, thread, _ in recorder.events if phase == "op:from-test")
    assert op_thread != threading.current_thread().name


def test_operation_queued_to_a_periodic_activity_runs_before_its_next_update(hosting: Hosting) -> None:
    app = Application("ops")
    recorder = app.add(Recorder("recorder"), PeriodicActivity("slow", 0.05))
    hosting.start(app)
    assert wait_until(lambda: recorder.updates >= 1)
    future = recorder.operation("mark")("queued")
    assert future.result(timeout=5) == "slow"
    assert wait_until(lambda: recorder.updates >= 3)
    phases = recorder.phases()
    position = phases.index("op:queued")
    assert phases[position + 1] == "on_update", phases


def test_callback_group_is_exclusive_within_an_activity_and_parallel_across(hosting: Hosting) -> None:
    app = Application("groups")
    one = app.add(Recorder("one"), TriggeredActivity("first"))
    two = app.add(Recorder("two"), TriggeredActivity("second"))
    one.work = two.work = 0.2
    host = hosting.start(app)
    group = host.callback_group("first")
    assert isinstance(group, MutuallyExclusiveCallbackGroup)
    assert group is not host.callback_group("second")
    assert callback_group(one) is group and ros_node(one) is hosting.node
    # A ROS timer of component "one", in its activity's group, never runs during one's update.
    overlaps: list[int] = []
    ticks: list[int] = []

    def tick() -> None:
        overlaps.append(one.in_update)
        ticks.append(1)

    timer = hosting.node.create_timer(0.005, tick, callback_group=group)
    assert wait_until(lambda: "on_config" in one.phases() and "on_config" in two.phases())
    together = threading.Barrier(2)
    both: list[int] = []

    def watch() -> None:
        together.wait()
        deadline = time.monotonic() + 3
        while time.monotonic() < deadline and not (one.in_update and two.in_update):
            time.sleep(0.001)
        both.append(one.in_update and two.in_update)

    watcher = threading.Thread(target=watch)
    watcher.start()
    together.wait()
    for _ in range(3):
        app.activity("first").wake()
        app.activity("second").wake()
        time.sleep(0.05)
    watcher.join()
    assert wait_until(lambda: one.updates >= 2 and two.updates >= 2)
    assert both == [1], "two activities must run in parallel on the executor's threads"
    assert ticks, "the component's timer never ran"
    assert not any(overlaps), "a callback of the activity's group ran during its update"
    assert one.max_in_update == 1 and two.max_in_update == 1
    timer.timer_period_ns = 10**15  # parked, so that no tick is in flight when the executor shuts down
    timer.reset()


def test_overrun_is_counted_when_a_cycle_outlasts_its_period(hosting: Hosting) -> None:
    app = Application("late")
    recorder = app.add(Recorder("recorder"), PeriodicActivity("tight", 0.02))
    recorder.work = 0.07  # every update misses at least two deadlines
    hosting.start(app)
    assert wait_until(lambda: recorder.updates >= 4)
    assert hosting.stop()
    stats = app.activity("tight").stats
    assert stats.overruns >= 2
    summary = stats.error_summary()
    assert summary is not None and summary.max < 0.02, "missed deadlines are skipped, not recorded as error"


def test_set_period_reaches_the_timer(hosting: Hosting) -> None:
    app = Application("period")
    recorder = app.add(Recorder("recorder"), PeriodicActivity("rate", 1.0))
    host = hosting.start(app)
    assert wait_until(lambda: recorder.updates == 1)  # the first cycle runs at once
    app.set_period("rate", 0.01)
    assert host.hosted["rate"].timer.timer_period_ns == 10_000_000
    assert app.activity("rate").period == 0.01
    assert wait_until(lambda: recorder.updates >= 10), "the new period was not taken"
    with pytest.raises(ValueError):
        app.set_period("rate", 0.0)


def test_dedicated_threads_run_beside_the_executor(hosting: Hosting) -> None:
    app, counter, recorder = pipeline(period=0.002)  # faster than THREAD_PERIOD: its own thread
    host = hosting.start(app, threads=("events",))
    assert host.hosted == {}
    assert wait_until(lambda: len(recorder.values) >= 50)
    names = {t.name for t in threading.enumerate()}
    assert {"coco:ticks", "coco:events"} <= names
    assert hosting.stop()
    assert recorder.values == list(range(len(recorder.values)))
    assert {thread for phase, thread, _ in recorder.events if phase == "on_update"} == {"coco:events"}


def test_stop_is_clean_and_runs_on_stop_once_in_the_activity(hosting: Hosting) -> None:
    app, _, recorder = pipeline()
    hosting.start(app)
    assert wait_until(lambda: recorder.updates >= 3)
    app.request_stop("test")
    assert hosting.stop(), "Application.stop must see every hosted activity finish within a second"
    assert all(activity.finished for activity in app.activities.values())
    stops = [event for event in recorder.events if event[0] == "on_stop"]
    assert len(stops) == 1 and stops[0][2] == "events"
    assert recorder.phases()[-1] == "on_stop"
    updates = recorder.updates
    time.sleep(0.1)
    assert recorder.updates == updates, "no cycle after the stop"


def test_stop_requested_before_the_first_callback_configures_nothing(hosting: Hosting) -> None:
    app, _, recorder = pipeline()
    hosting.host_app(app)
    app.start()  # hands the activities to the executor, which does not spin yet
    app.request_stop("test")
    hosting.spin()
    assert app.stop(), "the first callbacks must finish the activities"
    assert recorder.phases() == [], "neither on_config nor on_stop may run after an early stop"


def test_a_component_outside_the_ros_launcher_has_no_node() -> None:
    app, _, recorder = pipeline()
    with pytest.raises(CocoError, match="ROS launcher"):
        ros_node(recorder)


def test_an_entity_callback_runs_the_cycle_it_woke_before_returning(hosting: Hosting) -> None:
    app = Application("direct")
    source = app.add(Counter("source"))  # in no activity: the timer callback writes for it
    recorder = app.add(Recorder("recorder"), TriggeredActivity("events"))
    app.connect("source.out", "recorder.ev", BUFFERED)
    host = hosting.start(app)
    assert wait_until(lambda: "on_config" in recorder.phases())
    seen: list[tuple[object, int]] = []

    def write() -> None:  # what a ROSInterface subscription does: write a port in the activity's group
        seen.append((current_activity(), recorder.updates))
        source.on_update()

    wrapped = activity_callback(recorder, write)
    after: list[tuple[int, list[int]]] = []

    def tick() -> None:
        wrapped()
        after.append((recorder.updates, list(recorder.values)))

    timer = hosting.node.create_timer(0.01, tick, callback_group=callback_group(recorder))
    assert wait_until(lambda: len(after) >= 5)
    timer.timer_period_ns = 10**15  # parked, so that no tick is in flight when the executor shuts down
    timer.reset()
    assert hosting.stop()
    # Each tick's value was read by the cycle that ran inside the tick, as the activity.
    for k, (updates, values) in enumerate(after[:5]):
        assert updates == k + 1 and values == list(range(k + 1)), after
    assert all(activity is app.activity("events") for activity, _ in seen)
    assert app.activity("events").stats.cycles == recorder.updates
    assert "events" in host.hosted


def test_an_entity_callback_of_a_threaded_activity_is_left_as_it_is(hosting: Hosting) -> None:
    app, _, recorder = pipeline()
    hosting.host_app(app, threads=("events",))
    callback = lambda: None  # noqa: E731
    assert activity_callback(recorder, callback) is callback


def test_one_hosted_activity_gets_a_single_threaded_executor_and_more_get_worker_threads(hosting: Hosting) -> None:
    app = Application("alone")
    recorder = app.add(Recorder("recorder"), TriggeredActivity("events"))
    app.add(Counter("source"))  # in no activity: its entities would be in the node's default group
    host = hosting.host_app(app)
    assert host.plan.threads == 1
    executor = host.create_executor(context=hosting.context)
    assert isinstance(executor, SingleThreadedExecutor)
    assert isinstance(host.create_executor(3, context=hosting.context), MultiThreadedExecutor)
    app.start()
    hosting.spin()
    recorder.operation("mark")("single")
    assert wait_until(lambda: recorder.updates == 1), "the activity never ran"
    two, _, _ = pipeline()
    # With wait sets the executor runs no hosted activity: one thread is enough for the rest.
    assert ExecutorHost(hosting.node, two, hosting.plan(two)).plan.threads == (1 if hosting.wait_sets else 3)
    threaded, _, _ = pipeline()
    assert ExecutorHost(hosting.node, threaded, hosting.plan(threaded, ("ticks",))).plan.threads == 2, \
        "an activity on its own thread may have entities in its group: they get a worker of their own"


class Relay(Recorder):
    """Records like Recorder and hands every value on (a stage of a pipeline)."""

    out = OutputPort(int)

    def on_update(self) -> None:
        before = len(self.values)
        super().on_update()
        for value in self.values[before:]:
            self.out.write(value)


def chain_app() -> tuple[Application, Counter, Relay, Relay, Recorder]:
    """source (in no activity, written by an entity callback of "first") -> first -> second -> third,
    each stage a triggered activity of its own: the default layout of a ROS pipeline."""
    app = Application("chain")
    source = app.add(Counter("source"))
    first = app.add(Relay("a"), TriggeredActivity("first"))
    second = app.add(Relay("b"), TriggeredActivity("second"))
    third = app.add(Recorder("c"), TriggeredActivity("third"))
    app.connect("source.out", "a.ev", BUFFERED)
    app.connect("a.out", "b.ev", BUFFERED)
    app.connect("b.out", "c.ev", BUFFERED)
    return app, source, first, second, third


def test_a_chain_of_triggered_activities_runs_in_the_callback_its_data_came_in(hosting: Hosting) -> None:
    """A message through three hosted triggered activities: each stage's cycle runs, as its own
    activity, in the executor callback that brought the data, before it returns (no guard
    condition round trip per hop)."""
    app, source, first, second, third = chain_app()
    hosting.start(app)
    assert wait_until(lambda: all("on_config" in r.phases() for r in (first, second, third)))
    wrapped = activity_callback(first, source.on_update)
    after: list[tuple[str, list[int]]] = []

    def tick() -> None:
        wrapped()
        after.append((threading.current_thread().name, list(third.values)))

    timer = hosting.node.create_timer(0.01, tick, callback_group=callback_group(first))
    assert wait_until(lambda: len(after) >= 5)
    timer.timer_period_ns = 10**15
    timer.reset()
    assert hosting.stop()
    for k, (_, values) in enumerate(after[:5]):
        assert values == list(range(k + 1)), "the last stage had the value before the callback returned"
    updates = {r.name: [(thread, activity) for phase, thread, activity in r.events if phase == "on_update"]
               for r in (first, second, third)}
    for name, activity in (("a", "first"), ("b", "second"), ("c", "third")):
        assert all(a == activity for _, a in updates[name]), "each cycle runs as its own activity"
    ticks = [thread for thread, _ in after[:5]]
    assert [thread for thread, _ in updates["c"][:5]] == ticks, "in the thread of the callback"


def test_a_chained_activity_busy_elsewhere_is_served_by_its_guard_and_never_runs_twice_at_once(
        hosting: Hosting) -> None:
    """While a stage is running (its own callback, slow, woken from elsewhere too), the stage before
    it cannot run its cycle in its callback: the wake-up goes to its guard condition, nothing is
    lost, the callback is not kept, and no component ever runs twice at once."""
    app, source, first, second, third = chain_app()
    second.work = 0.02
    hosting.start(app)
    assert wait_until(lambda: all("on_config" in r.phases() for r in (first, second, third)))
    wrapped = activity_callback(first, source.on_update)
    feeding = threading.Lock()
    fed = [True]

    def feed() -> None:  # a tick the executor took before the timers were slowed still feeds whole
        with feeding:
            if fed[0]:
                wrapped()

    direct = [hosting.node.create_timer(0.003, feed, callback_group=callback_group(first)),
              hosting.node.create_timer(0.007, lambda: app.activity("second").wake(),
                                        callback_group=MutuallyExclusiveCallbackGroup())]
    assert wait_until(lambda: source.count >= 60, timeout=10)
    for timer in direct:
        timer.timer_period_ns = 10**15
        timer.reset()
    with feeding:  # after any tick in flight: no more values
        fed[0] = False
        sent = source.count
    assert wait_until(lambda: len(third.values) == sent, timeout=10), (len(third.values), sent)
    assert hosting.stop()
    assert third.values == list(range(sent)), "every value, in order"
    assert first.max_in_update == second.max_in_update == third.max_in_update == 1
