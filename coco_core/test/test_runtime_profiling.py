"""Profiling: executions, compute and service time statistics match what actually ran."""

from __future__ import annotations

import random
import statistics
import time

import pytest

from coco_core import (
    BufferPolicy,
    Component,
    ConnectionPolicy,
    InputPort,
    OutputPort,
    PeriodicActivity,
    Stamp,
    Stamped,
    SyncPolicy,
    TriggeredActivity,
)
from coco_core.profiling import ActivityStats, ComponentStats, RunningStats


def test_running_stats_match_the_textbook_formulas():
    rng = random.Random(7)
    values = [rng.uniform(0.0, 5.0) for _ in range(500)]
    stats = RunningStats()
    for value in values:
        stats.add(value)
    assert stats.count == 500
    assert stats.total == pytest.approx(sum(values))
    assert stats.mean == pytest.approx(statistics.fmean(values))
    assert stats.variance == pytest.approx(statistics.variance(values))
    assert stats.std == pytest.approx(statistics.stdev(values))
    assert stats.max == max(values)


def test_running_stats_small_counts():
    stats = RunningStats()
    assert (stats.count, stats.mean, stats.variance) == (0, 0.0, 0.0)
    stats.add(2.0)
    assert (stats.count, stats.mean, stats.variance, stats.max) == (1, 2.0, 0.0, 2.0)
    for value in (4.0, 4.0, 5.0):
        stats.add(value)
    assert stats.mean == pytest.approx(3.75)
    assert stats.variance == pytest.approx(1.5833333333)


def test_component_stats_compute_and_service_times():
    stats = ComponentStats()
    stats.record(10.0, 10.5)
    stats.record(12.0, 12.25)
    stats.record(13.0, 13.75)
    assert stats.executions == 3
    assert stats.compute.mean == pytest.approx(0.5)
    assert stats.compute.max == pytest.approx(0.75)
    assert stats.service.count == 2
    assert stats.service.mean == pytest.approx(1.5)
    assert stats.service.variance == pytest.approx(0.5)


class Worker(Component):
    """Sleeps ``work`` seconds per update and records what it did."""

    def init(self):
        self.work = 0.002
        self.durations: list[float] = []
        self.starts: list[float] = []

    def on_update(self):
        start = time.perf_counter()
        self.starts.append(start)
        time.sleep(self.work)
        self.durations.append(time.perf_counter() - start)


def test_profile_of_a_periodic_component_is_consistent_with_what_ran(make_app, wait_until):
    period = 0.01
    app = make_app("profile")
    worker = app.add(Worker("worker"), PeriodicActivity("periodic", period))
    app.start()
    assert wait_until(lambda: len(worker.durations) >= 15)
    assert app.stop()
    stats = worker.stats
    n = len(worker.durations)
    assert stats.executions == n == app.activity("periodic").stats.cycles
    assert stats.compute.mean >= 0.002, "each update slept 2 ms"
    assert stats.compute.mean >= statistics.fmean(worker.durations) * 0.99
    assert stats.compute.mean <= statistics.fmean(worker.durations) + 0.001
    assert stats.compute.max >= max(worker.durations) * 0.99
    assert stats.compute.total == pytest.approx(stats.compute.mean * n)
    assert stats.compute.variance >= 0.0
    # Service time: between the starts of successive executions.
    assert stats.service.count == n - 1
    own = [b - a for a, b in zip(worker.starts, worker.starts[1:])]
    assert stats.service.mean == pytest.approx(statistics.fmean(own), abs=0.0005)
    assert stats.service.mean >= period * 0.95
    assert stats.service.variance == pytest.approx(statistics.variance(own), rel=0.5, abs=1e-6)


def test_profile_of_a_triggered_component_counts_every_trigger(make_app, wait_until):
    class Source(Component):
        out = OutputPort(int)

    class Sink(Worker):
        inp = InputPort(int, event=True)

        def on_update(self):
            super().on_update()
            self.inp.read_all()

    app = make_app("triggered-profile")
    source = app.add(Source("source"))
    sink = app.add(Sink("sink"), TriggeredActivity("triggered"))
    sink.work = 0.0
    app.connect("source.out", "sink.inp", ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 10))
    app.start()
    for expected in range(1, 6):
        source.out.write(expected)
        assert wait_until(lambda: sink.stats.executions == expected)
        time.sleep(0.02)
    assert sink.stats.executions == 5
    assert sink.stats.service.count == 4
    assert sink.stats.service.mean >= 0.02
    assert sink.stats.compute.mean < sink.stats.service.mean


def test_disabled_component_is_not_profiled(make_app, wait_until):
    app = make_app("disabled")
    worker = app.add(Worker("worker"), PeriodicActivity("periodic", 0.005))
    worker.work = 0.0
    worker.enabled = False
    app.start()
    assert wait_until(lambda: app.activity("periodic").stats.cycles >= 5)
    assert worker.stats.executions == 0 and worker.durations == []


def test_activity_period_error_summary():
    stats = ActivityStats()
    assert stats.error_summary() is None
    for error in (0.001, 0.002, 0.003, 0.004, 0.010):
        stats.record_error(error)
    summary = stats.error_summary()
    assert summary.samples == 5
    assert summary.p50 == 0.003 and summary.max == 0.010
    assert summary.mean == pytest.approx(0.004)
    stats.reset()
    assert stats.error_summary() is None


def test_latency_from_a_stamp():
    worker = Worker("worker")
    stamp = Stamp(time.perf_counter() - 0.05, seq=3, source="camera")
    worker.record_latency(stamp)
    assert worker.stats.latency.count == 1
    assert 0.05 <= worker.stats.latency.mean < 5.0
    sample = Stamped(1.5)
    assert 0.0 <= sample.stamp.age() < 5.0 and sample.value == 1.5
