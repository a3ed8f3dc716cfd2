"""Activities: triggered and periodic scheduling, run-time period changes, main activity, shutdown."""

from __future__ import annotations

import logging
import statistics
import threading
import time

import pytest

from coco_core import (
    BufferPolicy,
    CocoError,
    ErrorPolicy,
    Component,
    ConnectionPolicy,
    InputPort,
    OutputPort,
    PeriodicActivity,
    SyncPolicy,
    TriggeredActivity,
)

BUFFERED = ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 100)


class Source(Component):
    out = OutputPort(int)


class Lifecycle(Component):
    """Records every life-cycle call with the thread it ran in."""

    def init(self):
        self.calls: list[tuple[str, int]] = [("init", threading.get_ident())]
        self.updates = 0
        self.configured = threading.Event()
        self.stopped = threading.Event()

    def on_config(self):
        self.calls.append(("on_config", threading.get_ident()))
        self.configured.set()

    def on_update(self):
        self.updates += 1
        if self.updates <= 3:
            self.calls.append(("on_update", threading.get_ident()))

    def on_stop(self):
        self.calls.append(("on_stop", threading.get_ident()))
        self.stopped.set()

    def phases(self):
        return [phase for phase, _ in self.calls]

    def thread_of(self, phase):
        return {thread for name, thread in self.calls if name == phase}


class EventSink(Lifecycle):
    ev = InputPort(int, event=True)
    plain = InputPort(int)

    def init(self):
        super().init()
        self.values: list[int] = []

    def on_update(self):
        super().on_update()
        self.values += self.ev.read_all()
        self.values += self.plain.read_all()


class Ticker(Lifecycle):
    """Records the start time of every update; optionally works (sleeps) for ``work`` seconds."""

    def init(self):
        super().init()
        self.starts: list[float] = []
        self.work = 0.0

    def on_update(self):
        self.starts.append(time.perf_counter())
        super().on_update()
        if self.work:
            time.sleep(self.work)


def settled(activity) -> bool:
    """Neither in a cycle nor woken for one: a write that wakes it sets its wake-up before it
    returns, so once this holds after a write, every cycle that write caused has run."""
    return activity.current is None and not activity.wake_pending


def rate(starts: list[float]) -> float:
    """Cycles a second over the cycles that started at ``starts``."""
    return (len(starts) - 1) / (starts[-1] - starts[0])


def event_rig(make_app, **connect):
    app = make_app("events")
    source = app.add(Source("source"))
    other = app.add(Source("other"))
    sink = app.add(EventSink("sink"), TriggeredActivity("triggered"))
    app.connect("source.out", "sink.ev", BUFFERED, **connect)
    app.connect("other.out", "sink.plain", BUFFERED)
    return app, source, other, sink


# --- triggered activities -------------------------------------------------------------------------


def test_triggered_activity_runs_once_per_event_and_never_for_plain_ports(make_app, wait_until):
    app, source, other, sink = event_rig(make_app)
    app.start()
    assert sink.configured.wait(1.0)
    triggered = app.activity("triggered")
    assert wait_until(lambda: settled(triggered))
    assert sink.updates == 0, "a triggered activity must not run without a trigger"

    other.out.write(10)  # plain port: stored, but nobody is woken
    assert wait_until(lambda: settled(triggered))
    assert sink.updates == 0
    assert sink.values == []

    source.out.write(1)
    assert wait_until(lambda: sink.updates == 1)
    assert sink.values == [1, 10], "the update sees the event and whatever else is waiting"
    assert wait_until(lambda: settled(triggered))
    assert sink.updates == 1, "one event, one update"

    for expected in (2, 3):
        source.out.write(expected)
        assert wait_until(lambda: sink.updates == expected)
    time.sleep(0.05)
    assert sink.updates == 3
    assert sink.values == [1, 10, 2, 3]
    assert app.activity("triggered").stats.cycles == 3


def test_event_flag_can_be_overridden_per_connection(make_app, wait_until):
    app = make_app("override")
    source = app.add(Source("source"))
    sink = app.add(EventSink("sink"), TriggeredActivity("triggered"))
    app.connect("source.out", "sink.plain", BUFFERED, event=True)
    muted = app.add(Source("muted"))
    app.connect("muted.out", "sink.ev", BUFFERED, event=False)
    app.start()
    assert sink.configured.wait(1.0)
    muted.out.write(5)
    assert wait_until(lambda: settled(app.activity("triggered")))
    assert sink.updates == 0, "event=False on the connection: the event port stays quiet"
    source.out.write(6)
    assert wait_until(lambda: sink.updates == 1)
    assert sorted(sink.values) == [5, 6]


def test_wake_during_a_cycle_is_not_lost(make_app, wait_until):
    class Slow(Component):
        ev = InputPort(int, event=True)

        def init(self):
            self.in_cycle = threading.Event()
            self.proceed = threading.Event()
            self.seen: list[list[int]] = []

        def on_update(self):
            self.seen.append(self.ev.read_all())
            if len(self.seen) == 1:
                self.in_cycle.set()
                self.proceed.wait(2.0)

    app = make_app("wake")
    source = app.add(Source("source"))
    slow = app.add(Slow("slow"), TriggeredActivity("triggered"))
    app.connect("source.out", "slow.ev", BUFFERED)
    app.start()
    source.out.write(1)
    assert slow.in_cycle.wait(2.0)
    source.out.write(2)  # arrives while the first cycle is still running
    slow.proceed.set()
    assert wait_until(lambda: len(slow.seen) >= 2), "the wake-up during the cycle was lost"
    assert slow.seen[:2] == [[1], [2]]


def test_data_written_before_start_triggers_the_first_cycle(make_app, wait_until):
    app, source, other, sink = event_rig(make_app)
    source.out.write(42)
    app.start()
    assert wait_until(lambda: sink.updates == 1)
    assert sink.values == [42]


def test_event_port_declared_in_init_wakes_an_activity_given_at_construction(make_app, wait_until):
    class Dynamic(Component):
        def init(self):
            self.topic = self.add_input("topic", int, event=True)
            self.values: list[int] = []

        def on_update(self):
            self.values += self.topic.read_all()

    app = make_app("dynamic")
    dynamic = Dynamic("dynamic")
    activity = TriggeredActivity("triggered", [dynamic])  # scheduled before app.add runs init()
    app.add(dynamic)
    app.add_activity(activity)
    source = app.add(Source("source"))
    app.connect("source.out", "dynamic.topic", BUFFERED)
    assert dynamic.inputs["topic"].triggers
    app.start()
    source.out.write(7)
    assert wait_until(lambda: dynamic.values == [7], timeout=1.0), \
        "an event port declared in init() never wakes its triggered activity"


# --- periodic activities --------------------------------------------------------------------------


def grid_errors(starts: list[float], period: float) -> list[float]:
    """Distance of each start from the time grid of the first one, in periods."""
    t0 = starts[0]
    return [abs((t - t0) / period - round((t - t0) / period)) for t in starts[1:]]


def test_periodic_activity_cycles_about_period_wise_on_a_fixed_grid(make_app, wait_until):
    period = 0.02
    app = make_app("periodic")
    ticker = app.add(Ticker("ticker"), PeriodicActivity("periodic", period))
    ticker.work = 0.004  # a relative sleep would drift by this much every cycle
    app.start()
    assert wait_until(lambda: len(ticker.starts) >= 20, timeout=10.0)
    app.stop()
    starts = ticker.starts
    elapsed = starts[-1] - starts[0]
    expected = elapsed / period
    assert len(starts) - 1 <= expected + 1, "a periodic activity never runs faster than its period"
    # Drift-free: the starts stay on the grid of absolute deadlines (median within a fifth of a period).
    assert statistics.median(grid_errors(starts, period)) < 0.2
    assert elapsed / (len(starts) - 1) >= period * 0.95
    activity = app.activity("periodic")
    assert activity.stats.cycles == len(starts)
    summary = activity.stats.error_summary()
    assert summary is not None and summary.samples >= len(starts) - 1


def test_overruns_are_counted_and_missed_deadlines_skipped(make_app, wait_until):
    period = 0.01
    app = make_app("overrun")
    ticker = app.add(Ticker("ticker"), PeriodicActivity("periodic", period))
    ticker.work = 0.025
    app.start()
    assert wait_until(lambda: len(ticker.starts) >= 8, timeout=10.0)
    app.stop()
    activity = app.activity("periodic")
    cycles = activity.stats.cycles
    assert cycles >= 3
    assert activity.stats.overruns >= cycles - 1, "every cycle took longer than the period"
    # Missed deadlines are skipped, not caught up with a burst of back-to-back cycles.
    intervals = [b - a for a, b in zip(ticker.starts, ticker.starts[1:])]
    assert min(intervals) >= 0.025
    assert statistics.median(grid_errors(ticker.starts, period)) < 0.25


def test_periodic_activity_without_overrun_counts_none(make_app, wait_until):
    app = make_app("no-overrun")
    ticker = app.add(Ticker("ticker"), PeriodicActivity("periodic", 0.02))
    app.start()
    assert wait_until(lambda: len(ticker.starts) >= 10, timeout=10.0)
    app.stop()
    activity = app.activity("periodic")
    assert activity.stats.cycles >= 3
    # A quiet cycle takes microseconds; even on a noisy machine most cycles cannot overrun 20 ms.
    assert activity.stats.overruns <= activity.stats.cycles // 2


def test_set_period_at_run_time_changes_the_rate(make_app, wait_until):
    app = make_app("set-period")
    ticker = app.add(Ticker("ticker"), PeriodicActivity("periodic", 0.05))
    app.start()
    assert wait_until(lambda: ticker.updates >= 6)
    slow_rate = rate(ticker.starts[-6:])
    app.set_period("periodic", 0.005)
    assert app.activity("periodic").period == 0.005
    changed = len(ticker.starts) + 1  # the cycle that ends the old period's sleep comes first
    assert wait_until(lambda: len(ticker.starts) >= changed + 20)
    fast_rate = rate(ticker.starts[changed:])
    assert slow_rate <= 1 / 0.05 * 1.1, slow_rate
    assert fast_rate >= 3 * slow_rate, (slow_rate, fast_rate)
    app.set_period("periodic", 0.05)
    changed = len(ticker.starts) + 1
    assert wait_until(lambda: len(ticker.starts) >= changed + 5)
    assert rate(ticker.starts[changed:]) <= 1 / 0.05 * 1.1, "the period can be made longer again"


def test_set_period_from_a_long_period_takes_effect_promptly(make_app, wait_until):
    app = make_app("set-period-long")
    ticker = app.add(Ticker("ticker"), PeriodicActivity("periodic", 2.0))
    app.start()
    assert wait_until(lambda: ticker.updates == 1)
    app.set_period("periodic", 0.01)
    # The new 10 ms period must not wait for the rest of the old 2 s one.
    assert wait_until(lambda: ticker.updates >= 5, timeout=1.0), \
        f"{ticker.updates} updates 1 s after shortening the period from 2 s to 10 ms"


def test_set_period_is_refused_for_triggered_and_non_positive(make_app):
    app = make_app("refused")
    app.add(Ticker("t1"), PeriodicActivity("periodic", 0.01))
    app.add(Ticker("t2"), TriggeredActivity("triggered"))
    with pytest.raises(CocoError, match="triggered"):
        app.set_period("triggered", 0.01)
    with pytest.raises(ValueError, match="greater than 0"):
        app.set_period("periodic", 0)
    with pytest.raises(ValueError, match="greater than 0"):
        PeriodicActivity("bad", -1.0)
    for absurd in (1e297, float("nan"), float("inf")):  # 1e297 s ended the activity's thread at its first sleep
        with pytest.raises(ValueError, match=r"at most 86400 s \(a day\)"):
            app.set_period("periodic", absurd)
        with pytest.raises(ValueError, match=r"at most 86400 s \(a day\)"):
            PeriodicActivity("bad", absurd)
    assert app.activity("periodic").period == 0.01


def test_an_activity_whose_driver_fails_stops_the_application_and_is_recorded(make_app):
    # A driver's own failure (not a component's: their policies handle those) ended the activity's
    # thread while the application ran on, and the launcher exited 0.
    from coco_core.drivers import ThreadDriver
    from coco_core.launcher import stopped_by_a_failure

    class FailingDriver(ThreadDriver):
        def _triggered(self, activity):
            raise OverflowError("timeout value is too large")

    app = make_app("failing")
    activity = TriggeredActivity("doomed")
    activity.drive_with(FailingDriver())
    app.add(Ticker("t"), activity)
    app.start()
    assert app.wait(timeout=10), "the application was not stopped"
    assert app.stop()
    assert activity.failure == "OverflowError: timeout value is too large"
    assert app.stop_reason == "activity doomed failed: OverflowError: timeout value is too large"
    assert stopped_by_a_failure(app)


def test_periodic_activity_with_an_event_port_does_not_busy_spin(make_app, wait_until):
    class Polled(Component):
        ev = InputPort(int, event=True)

        def init(self):
            self.samples: list[tuple[float, float]] = []

        def on_update(self):
            self.ev.read()
            self.samples.append((time.thread_time(), time.perf_counter()))

    app = make_app("periodic-event")
    source = app.add(Source("source"))
    # spin=0: the activity sleeps right up to each deadline, so its idle thread should use ~no CPU.
    polled = app.add(Polled("polled"), PeriodicActivity("periodic", 0.02, spin=0.0))
    app.connect("source.out", "polled.ev")
    app.start()
    assert wait_until(lambda: len(polled.samples) >= 2)
    source.out.write(1)  # an event port in a periodic activity: the data is simply polled
    time.sleep(0.05)
    first = len(polled.samples)
    assert wait_until(lambda: len(polled.samples) >= first + 20, timeout=10.0)
    (cpu0, wall0), (cpu1, wall1) = polled.samples[first - 1], polled.samples[-1]
    ratio = (cpu1 - cpu0) / (wall1 - wall0)
    # Sleeping until each 20 ms deadline costs well under 1% of a core; busy waiting costs up to 100%
    # (less on a loaded machine, hence the low bound).
    assert ratio < 0.2, f"the periodic activity's thread used {ratio:.0%} of a core between cycles"


# --- main activity, life cycle, shutdown ----------------------------------------------------------


def test_main_activity_runs_in_the_calling_thread(make_app):
    app = make_app("main")
    main = app.add(Lifecycle("main_comp"), PeriodicActivity("main", 0.01, main=True))
    side = app.add(Lifecycle("side_comp"), PeriodicActivity("side", 0.01))
    caller = threading.get_ident()
    t0 = time.monotonic()
    app.run(duration=0.3)
    elapsed = time.monotonic() - t0
    assert 0.25 <= elapsed < 2.0
    assert main.phases()[0] == "init" and main.phases()[1] == "on_config" and main.phases()[-1] == "on_stop"
    for phase in ("on_config", "on_update", "on_stop"):
        assert main.thread_of(phase) == {caller}, phase
        assert side.thread_of(phase) and caller not in side.thread_of(phase), phase
    assert len(side.thread_of("on_update") | side.thread_of("on_config") | side.thread_of("on_stop")) == 1
    assert main.updates >= 5
    assert app.activity("main").finished and app.activity("side").finished


class SlowToConfigure(Lifecycle):
    """Takes 0.6 s to configure, as an OpenGL context or a URDF can on a loaded machine."""

    def on_config(self):
        time.sleep(0.6)  # the component's own work, not the test waiting
        super().on_config()


def test_a_duration_counts_from_the_start_of_the_run_not_from_the_configuration(make_app):
    # With configure-all-then-start-all, --duration 3 once ended a display app before its first cycle.
    app = make_app("duration")
    slow = app.add(SlowToConfigure("slow"), PeriodicActivity("slow", 0.01))
    ticks = app.add(Ticker("ticks"), PeriodicActivity("ticks", 0.01))
    t0 = time.monotonic()
    app.run(duration=0.3)
    assert time.monotonic() - t0 >= 0.85  # 0.6 s of configuration, then 0.3 s of run
    assert slow.updates >= 5 and ticks.updates >= 5, (slow.updates, ticks.updates)


def test_main_activity_stops_when_stopped_from_another_thread(make_app):
    app = make_app("main-stop")
    main = app.add(Lifecycle("main_comp"), TriggeredActivity("main", main=True))
    # app.run() runs in a helper thread (its "calling thread") so a hang fails the test instead of pytest.
    runner = threading.Thread(target=app.run, daemon=True)
    runner.start()
    assert main.configured.wait(2.0)
    t0 = time.monotonic()
    app.stop()
    runner.join(2.0)
    assert not runner.is_alive(), "Application.run() did not return after stop()"
    assert time.monotonic() - t0 < 1.0
    assert main.phases() == ["init", "on_config", "on_stop"]
    assert main.thread_of("on_config") == main.thread_of("on_stop") == {runner.ident}


def test_lifecycle_order_and_threads(make_app, wait_until):
    app = make_app("lifecycle")
    comp = app.add(Lifecycle("comp"), PeriodicActivity("periodic", 0.01))
    assert comp.phases() == ["init"], "init runs when the component is added"
    app.start()
    assert wait_until(lambda: comp.updates >= 3)
    app.stop()
    phases = comp.phases()
    assert phases[:2] == ["init", "on_config"] and phases[-1] == "on_stop"
    assert set(phases[2:-1]) == {"on_update"}
    assert comp.thread_of("init") == {threading.get_ident()}
    activity_threads = comp.thread_of("on_config") | comp.thread_of("on_update") | comp.thread_of("on_stop")
    assert len(activity_threads) == 1 and threading.get_ident() not in activity_threads


def test_stop_within_one_second_with_idle_triggered_and_long_periodic(make_app, wait_until):
    app = make_app("shutdown")
    idle = app.add(Lifecycle("idle"), TriggeredActivity("triggered"))
    slow = app.add(Lifecycle("slow"), PeriodicActivity("slow", 10.0))
    app.start()
    assert idle.configured.wait(1.0)
    assert wait_until(lambda: slow.updates == 1)  # now sleeping towards a deadline 10 s away
    time.sleep(0.05)
    t0 = time.monotonic()
    clean = app.stop()
    elapsed = time.monotonic() - t0
    assert clean is True
    assert elapsed < 1.0, f"stop took {elapsed:.2f} s"
    assert idle.stopped.is_set() and slow.stopped.is_set()
    assert idle.thread_of("on_stop") == idle.thread_of("on_config"), "on_stop runs in the activity thread"
    assert slow.thread_of("on_stop") == slow.thread_of("on_config")
    assert threading.get_ident() not in idle.thread_of("on_stop") | slow.thread_of("on_stop")
    assert all(activity.finished for activity in app.activities.values())
    assert app.stop() is True, "stopping twice is harmless"


def test_what_on_stop_writes_is_there_after_stop(make_app, wait_until):
    class Producer(Component):
        out = OutputPort(object)

        def init(self):
            self.count = 0

        def on_update(self):
            self.count += 1
            self.out.write(self.count)

        def on_stop(self):
            self.out.write("final")

    class Collector(Component):
        inp = InputPort(object)

    app = make_app("flush")
    producer = app.add(Producer("producer"), PeriodicActivity("periodic", 0.01))
    collector = app.add(Collector("collector"))
    app.connect("producer.out", "collector.inp", ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCK_FREE, 1000))
    app.start()
    assert wait_until(lambda: producer.count >= 3)
    assert app.stop()
    values = collector.inp.read_all()
    assert values[-1] == "final"
    assert values[:-1] == list(range(1, producer.count + 1))


def test_stop_reports_an_activity_that_does_not_finish(make_app, wait_until, caplog):
    class Stuck(Component):
        def init(self):
            self.release = threading.Event()
            self.inside = threading.Event()

        def on_update(self):
            self.inside.set()
            self.release.wait(5.0)

    app = make_app("stuck")
    stuck = app.add(Stuck("stuck"), PeriodicActivity("periodic", 0.01))
    app.start()
    assert stuck.inside.wait(1.0)
    caplog.set_level(logging.ERROR, logger="coco")
    t0 = time.monotonic()
    try:
        clean = app.stop()
        elapsed = time.monotonic() - t0
    finally:
        stuck.release.set()
    assert clean is False
    assert elapsed < 2.0
    messages = [r.getMessage() for r in caplog.records if r.name == "coco"]
    assert any("periodic" in m and "stuck" in m and "did not stop" in m for m in messages), messages
    assert app.activity("periodic").join(2.0)


def test_on_stop_only_runs_for_components_that_were_configured(make_app):
    class Broken(Lifecycle):
        def on_config(self):
            super().on_config()
            raise OSError("device missing")

    app = make_app("early-stop")
    activity = PeriodicActivity("periodic", 0.01)
    broken = app.add(Broken("broken"), activity)
    broken.on_error = ErrorPolicy.STOP_APP  # stops the application before `later` is configured
    later = app.add(Lifecycle("later"), activity)
    app.start()
    assert app.wait(2.0) and app.stop()
    assert later.updates == 0
    # on_stop releases what on_config acquired: calling it on a never-configured component breaks it.
    assert later.phases() == ["init"], f"later: {later.phases()}"


def test_stop_after_start_does_not_wait_for_a_main_activity_that_never_ran(make_app, caplog):
    caplog.set_level(logging.ERROR, logger="coco")
    app = make_app("start-only")
    app.add(Lifecycle("main_comp"), TriggeredActivity("main", main=True))
    side = app.add(Lifecycle("side_comp"), TriggeredActivity("side"))
    app.start()  # starts every activity but the main one, which only Application.run() runs
    assert side.configured.wait(1.0)
    t0 = time.monotonic()
    clean = app.stop()
    elapsed = time.monotonic() - t0
    errors = [r.getMessage() for r in caplog.records if r.name == "coco"]
    assert clean is True and errors == [], errors
    assert elapsed < 0.5, f"stop() waited {elapsed:.2f} s for a main activity that never ran"


class Stage(Component):
    """Reads every value; passes each one below 100 on, plus one."""

    inp = InputPort(int, event=True)
    out = OutputPort(int)

    def init(self) -> None:
        self.seen: list[int] = []

    def on_update(self) -> None:
        for value in self.inp.read_all():
            self.seen.append(value)
            if value < 100:
                self.out.write(value + 1)


def two_stages(make_app, feedback: bool):
    """source -> first -> second, both stages in one triggered activity, optionally second -> first."""
    app = make_app("stages")
    source = app.add(Source("source"))
    activity = TriggeredActivity("pipeline")
    first, second = app.add(Stage("first"), activity), app.add(Stage("second"), activity)
    app.connect("source.out", "first.inp", BUFFERED)
    app.connect("first.out", "second.inp", BUFFERED)
    if feedback:
        app.connect("second.out", "first.inp", BUFFERED)
    app.start()
    return source, first, second, activity


def test_a_pipeline_in_one_triggered_activity_runs_one_cycle_per_input(make_app, wait_until):
    """What a stage writes to a later stage of its activity is read in the same cycle: no other cycle."""
    source, first, second, activity = two_stages(make_app, feedback=False)
    for value in (0, 10, 20):
        source.out.write(value)
        assert wait_until(lambda: second.seen[-1:] == [value + 1])
    assert wait_until(lambda: settled(activity))
    assert activity.stats.cycles == 3, "one cycle per input: the stage-to-stage write is read in it"
    assert first.seen == [0, 10, 20] and second.seen == [1, 11, 21]


def test_data_for_a_stage_the_cycle_already_ran_gets_a_cycle_of_its_own(make_app, wait_until):
    source, first, second, activity = two_stages(make_app, feedback=True)
    source.out.write(95)
    assert wait_until(lambda: second.seen[-1:] == [100])
    assert wait_until(lambda: settled(activity))
    assert first.seen == [95, 97, 99] and second.seen == [96, 98, 100]
    assert activity.stats.cycles == 3


@pytest.mark.parametrize("main", [False, True])
def test_no_activity_cycles_before_every_activity_is_configured(make_app, main):
    """Configure all, then start all (the paper's and RTT's life cycle): a fast periodic activity
    configured first does not cycle while another activity (here the main one, or one on its own
    thread) is still configuring, e.g. loading a model or opening a device."""

    class SlowConfig(Lifecycle):
        def init(self):
            super().init()
            self.peer: Lifecycle | None = None
            self.updates_seen = -1

        def on_config(self):
            super().on_config()
            assert self.peer is not None and self.peer.configured.wait(5.0)
            # Give the other activity the chance to cycle (it would at once, every millisecond).
            deadline = time.monotonic() + 0.3
            while self.peer.updates == 0 and time.monotonic() < deadline:
                time.sleep(0.005)
            self.updates_seen = self.peer.updates

    app = make_app("configure-all")
    fast = app.add(Lifecycle("fast"), PeriodicActivity("fast", 0.001))
    slow = app.add(SlowConfig("slow"), TriggeredActivity("slow", main=main))
    slow.peer = fast
    if main:
        runner = threading.Thread(target=app.run)
        runner.start()
    else:
        app.start()
    try:
        assert slow.configured.wait(5.0) and fast.configured.wait(5.0)
        deadline = time.monotonic() + 5.0
        while fast.updates == 0 and time.monotonic() < deadline:  # then it starts
            time.sleep(0.005)
        assert slow.updates_seen == 0, "an activity cycled before the others were configured"
        assert fast.updates > 0
    finally:
        app.request_stop("test over")
        if main:
            runner.join(5.0)
        app.stop()


def test_a_paused_application_holds_every_cycle_and_runs_what_waits_when_resumed(make_app, wait_until):
    """Application.pause (a managed node's deactivate): no component runs while paused, though the
    periodic activity's clock goes on; what is written meanwhile waits in the connection, and the
    triggered activity reads it once resumed (activate)."""
    app, source, _other, sink = event_rig(make_app)
    ticker = app.add(Ticker("ticker"), PeriodicActivity("periodic", 0.01))
    app.start()
    assert wait_until(lambda: ticker.updates > 2)
    app.pause(True)
    periodic = app.activities["periodic"]

    def ticks() -> int:
        summary = periodic.stats.error_summary()
        return summary.samples if summary is not None else 0

    begun = ticks()
    assert wait_until(lambda: ticks() >= begun + 2)  # a cycle under way when the pause came has ended
    held, seen = ticker.updates, ticks()
    source.out.write(7)
    assert wait_until(lambda: ticks() >= seen + 5)  # five periods
    assert ticker.updates == held and sink.values == [], "no component ran while paused"
    app.pause(False)
    assert wait_until(lambda: sink.values == [7] and ticker.updates > held)
