"""Drivers of activities (coco_core.drivers) and the time grid they share (coco_core.period)."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from coco_core import Application, BufferPolicy, Component, ConnectionPolicy, InputPort, OutputPort, TriggeredActivity
from coco_core.drivers import Driving, ThreadDriver
from coco_core.errors import ActivityError
from coco_core.period import PeriodGrid
from coco_core.policy import NEW_DATA
from coco_core.profiling import ActivityStats
from coco_core.wakeup import Wakeup


class Counter(Component):
    value = InputPort(int, event=True)

    def init(self) -> None:
        self.cycles = 0
        self.values: list[int] = []

    def on_update(self) -> None:
        self.cycles += 1
        self.values += self.value.read_all()


class Source(Component):
    out = OutputPort(int)


class Stamps(Component):
    """Notes when each of its updates began and the newest value it read."""

    value = InputPort(int, event=True)

    def init(self) -> None:
        self.starts: list[float] = []
        self.seen: int | None = None

    def on_update(self) -> None:
        self.starts.append(time.perf_counter())
        status, value = self.value.read_newest()
        if status is NEW_DATA:
            self.seen = value


def test_grid_skips_missed_deadlines_and_counts_one_overrun() -> None:
    stats = ActivityStats()
    grid = PeriodGrid(0.01, stats)
    grid.begin(100.0)
    assert grid.after_cycle(100.002) == pytest.approx(100.01)
    assert stats.overruns == 0
    assert grid.after_cycle(100.035) == pytest.approx(100.04), "deadlines 100.02 and 100.03 are skipped"
    assert stats.overruns == 1


def test_grid_of_a_timer_records_its_lateness_and_skips_whole_periods() -> None:
    stats = ActivityStats()
    grid = PeriodGrid(0.01, stats)
    grid.begin(100.0)
    grid.fired(100.001)
    assert grid.deadline == pytest.approx(100.01) and stats.overruns == 0
    grid.fired(100.0325)  # more than two periods late: two skipped, 2.5 ms late for 100.03
    assert stats.overruns == 1 and grid.deadline == pytest.approx(100.04)
    summary = stats.error_summary()
    assert summary is not None and summary.max == pytest.approx(0.0025)


def test_grid_period_change_continues_from_the_last_deadline() -> None:
    grid = PeriodGrid(0.01, ActivityStats())
    grid.begin(100.0)
    grid.after_cycle(100.001)  # next deadline 100.01
    assert grid.change_period(0.02, 100.002) == pytest.approx(100.02)
    assert grid.change_period(0.001, 100.05) == pytest.approx(100.05), "a past deadline is now"
    with pytest.raises(ValueError, match="greater than 0"):
        grid.change_period(0, 100.0)


LATE_START = 0.005
"""Seconds from a driver's start of a cycle to its first component's update, at most: microseconds,
more when the thread is preempted in between on a loaded machine. The gaps between updates may be
that much shorter than the ``min_period`` between the cycles' starts; a driver that ignored the
bound would start the next cycle within a millisecond."""


@pytest.fixture(params=["eventfd", "event"])
def wakeup(request: pytest.FixtureRequest):
    """What wakes a thread driver: an eventfd (closed at teardown, after the test's application
    stopped), or None, the driver's thread event."""
    if request.param == "event":
        yield None
        return
    wakeup = Wakeup.new()
    yield wakeup
    wakeup.close()


def bounded(app: Application, wakeup: Wakeup | None, min_period: float) -> tuple[Source, Stamps]:
    """``source`` (in no activity: the test writes) -> ``stamps`` in a triggered activity ``view``
    with ``min_period``, on a thread driver woken by ``wakeup``."""
    stamps = app.add(Stamps("stamps"), TriggeredActivity("view", min_period=min_period))
    source = app.add(Source("source"))
    app.connect("source.out", "stamps.value")
    app.activity("view").drive_with(ThreadDriver(wakeup))
    return source, stamps


def test_a_min_period_keeps_cycles_apart_and_a_burst_of_wake_ups_gets_one_cycle_at_the_bound(
        wakeup, make_app, wait_until) -> None:
    min_period = 0.2
    app = make_app("bounded")
    source, stamps = bounded(app, wakeup, min_period)
    activity = app.activity("view")
    app.start()
    source.out.write(1)
    assert wait_until(lambda: stamps.seen == 1, timeout=20), "the first wake-up waits for nothing"
    for value in (2, 3, 4, 5):
        source.out.write(value)
    burst_end = time.perf_counter()
    assert wait_until(lambda: stamps.seen == 5 and not activity.wake_pending, timeout=20), \
        "the last wake-up is served"
    starts = list(stamps.starts)
    assert app.stop()
    gaps = [later - earlier for earlier, later in zip(starts, starts[1:])]
    assert gaps and min(gaps) >= min_period - LATE_START, f"cycles {gaps} s apart, bound {min_period} s"
    if burst_end < starts[0] + min_period:  # the whole burst came during the wait: one cycle serves it
        assert len(starts) == 2, f"{len(starts) - 1} cycles for a burst of 4 wake-ups within the bound"


def test_a_stop_ends_the_wait_for_the_min_period_and_the_held_wake_up_is_drained(
        wakeup, make_app, wait_until) -> None:
    min_period = 60.0
    app = make_app("bounded")
    source, stamps = bounded(app, wakeup, min_period)
    app.start()
    source.out.write(1)
    assert wait_until(lambda: stamps.seen == 1, timeout=20)
    source.out.write(2)  # held: the next cycle may start a minute after the first
    asked = time.monotonic()
    assert app.stop(), "the activity did not stop"
    assert time.monotonic() - asked < min_period / 4, "the stop waited for the min_period"
    assert stamps.seen == 2, "a natural stop drains what the held wake-up brought"


def test_a_wake_pending_before_start_goes_to_the_new_driver() -> None:
    app = Application("drivers")
    counter = app.add(Counter("counter"), TriggeredActivity("events"))
    app.add(Source("source"))
    app.connect("source.out", "counter.value", ConnectionPolicy(BufferPolicy.BUFFER, size=4))
    app.component("source").out.write(1)
    activity = app.activity("events")
    assert activity.wake_pending
    wakeup = Wakeup.new()
    try:
        activity.drive_with(ThreadDriver(wakeup))
        assert activity.wake_pending, "the pending wake-up came along"
        app.start()
        deadline = time.monotonic() + 2
        while counter.values != [1] and time.monotonic() < deadline:
            time.sleep(0.005)
        assert counter.values == [1]
        with pytest.raises(ActivityError, match="already started"):
            activity.drive_with(ThreadDriver())
    finally:
        assert app.stop()
        wakeup.close()


def test_an_eventfd_driver_is_woken_by_another_process() -> None:
    app = Application("drivers")
    counter = app.add(Counter("counter"), TriggeredActivity("events"))
    wakeup = Wakeup.new()
    fd = wakeup.fd
    app.activity("events").drive_with(ThreadDriver(wakeup))
    app.start()
    try:
        time.sleep(0.05)
        cycles = counter.cycles
        subprocess.run([sys.executable, "-c", f"import os; os.eventfd_write({fd}, 1)"], pass_fds=(fd,), check=True)
        deadline = time.monotonic() + 2
        while counter.cycles == cycles and time.monotonic() < deadline:
            time.sleep(0.005)
        time.sleep(0.05)
        assert counter.cycles == cycles + 1, "one write from another process, one cycle"
        assert not app.activity("events").wake_pending
    finally:
        assert app.stop()
        wakeup.close()


def test_a_wake_after_the_close_writes_into_no_descriptor() -> None:
    """The launcher closes its eventfds at the end while a host's receiver may still write: the write
    must not reach the file that got the number since (8 bytes in a profile or a bag)."""
    wakeup = Wakeup.new()
    number = wakeup.fd
    wakeup.wake()
    assert wakeup.pending
    wakeup.close()
    read, write = os.pipe()  # the lowest free numbers: the eventfd's, now released
    try:
        assert number in (read, write), "the test needs the released number reused"
        wakeup.wake()
        wakeup.close()  # twice: nothing
        assert not wakeup.pending and wakeup.fd == -1
        os.set_blocking(read, False)
        with pytest.raises(BlockingIOError):
            os.read(read, 8)
    finally:
        os.close(read)
        os.close(write)


def test_application_start_drives_each_activity_as_the_plan_says_and_keeps_a_given_driver() -> None:
    """The activity restates no rule of the plan: it has no driver until given one, and an
    application built in code gets its activities' drivers from the plan (the main one in the
    calling thread), while a driver given before stays."""
    app = Application("drivers")
    app.add(Counter("shown"), TriggeredActivity("gui", main=True))
    app.add(Counter("counter"), TriggeredActivity("events"))
    app.add(Counter("other"), TriggeredActivity("own"))
    assert app.activity("events").driver is None and not app.activity("events").driven
    with pytest.raises(ActivityError, match="no driver"):
        app.activity("events").start()
    given = ThreadDriver()
    app.activity("own").drive_with(given)
    app.start()
    try:
        drivers = {name: activity.driver for name, activity in app.activities.items()}
        assert {name: driver.driving for name, driver in drivers.items() if driver is not None} == {
            "gui": Driving.MAIN, "events": Driving.THREAD, "own": Driving.THREAD}
        assert drivers["own"] is given
    finally:
        app.request_stop("test done", hard=True)
        assert app.stop()
