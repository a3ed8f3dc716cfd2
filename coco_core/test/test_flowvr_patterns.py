"""FlowVR's Figure 1 a-d, as the application files config/flowvr_*.xml run them: the same producer and
consumer, coupled data-driven, demand-driven (PreSignal), frequency-bounded (MaxFrequency) or greedy.

The checks read what the two components recorded from the message stamps (each write's iteration
and times, each taken value's iteration and when it was asked for) and the connection's counters;
they count and compare, and wait on conditions only, so that a loaded machine makes them slower,
not wrong."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from coco_core.builder import build_application
from coco_core.demo.coupling import CostlyConsumer, CostlyProducer, Written
from coco_core.filters import Greedy
from coco_core.xml import load_application

CONFIG = Path(__file__).resolve().parents[2] / "config"
FILES = sorted(CONFIG.glob("flowvr_*.xml"))
TIMEOUT = 30.0
"""Seconds a condition may take on a loaded machine (a few hundred cycles of a few ms)."""


@pytest.fixture
def run_file(wait_until):
    """``run_file(name, until, **args)``: build config/<name> with ``args``, run it until
    ``until(app)`` holds (asserted), stop it and return it."""
    apps = []

    def run(name: str, until, **args):
        app = build_application(load_application(CONFIG / name, args={k: str(v) for k, v in args.items()}))
        apps.append(app)
        app.start()
        assert wait_until(lambda: until(app), timeout=TIMEOUT), "the application did not get there in time"
        assert app.stop()
        return app

    yield run
    for app in apps:
        app.stop()


def parts(app) -> tuple[CostlyProducer, CostlyConsumer]:
    producer, consumer = app.component("producer"), app.component("consumer")
    assert isinstance(producer, CostlyProducer) and isinstance(consumer, CostlyConsumer)
    return producer, consumer


def data_connection(app):
    [connection] = [c for c in app.connections if c.label == "producer.out -> consumer.item"]
    return connection


def test_the_four_files_share_the_two_components_and_differ_in_the_coupling_only():
    assert [path.name for path in FILES] == ["flowvr_a_data_driven.xml", "flowvr_b_demand_driven.xml",
                                             "flowvr_c_max_frequency.xml", "flowvr_d_greedy.xml"]
    for path in FILES:
        spec = load_application(path)
        assert [(c.name, c.task) for c in spec.components] == [("producer", "CostlyProducer"),
                                                               ("consumer", "CostlyConsumer")]
        assert [(a.name, a.components) for a in spec.activities] == [("produce", ["producer"]),
                                                                     ("consume", ["consumer"])]


@pytest.mark.parametrize("path", FILES, ids=lambda path: path.name)
def test_coco_launch_checks_and_runs_each_file(path):
    check = subprocess.run([sys.executable, "-m", "coco_core.launcher", str(path), "--check"],
                           capture_output=True, text=True, timeout=60)
    assert check.returncode == 0, check.stderr
    assert "producer.out -> consumer.item" in check.stdout
    run = subprocess.run([sys.executable, "-m", "coco_core.launcher", str(path), "--duration", "0.5",
                          "--profile", "60"], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    assert "consume" in run.stdout


# The checks of each coupling, on what the producer and the consumer recorded (live components, or
# their records read back from another process: test_flowvr_processes.py) and the data connection's
# counters (the profile's row).

def check_a_every_value(producer, consumer, counters: dict[str, int]) -> None:
    assert counters["dropped"] == 0
    assert consumer.consumed + counters["pending"] == producer.produced
    # Every value, once, in order: the new message numbers the consumer saw are 1, 2, 3, ... A cycle may
    # find nothing new: the consumer takes every value waiting, so a value written while a cycle ran
    # is taken by that cycle and its own wake-up then finds it taken (the consumer works on it again,
    # not new: seen once between processes on a loaded machine). Such a cycle re-reads the newest.
    taken = list(consumer.taken)
    assert [t.seq for t in taken if t.new] == list(range(1, consumer.consumed + 1))
    assert all(t.seq == before.seq for before, t in zip(taken, taken[1:]) if not t.new) and taken[0].new


def check_a_bounded(producer, consumer, counters: dict[str, int], queue: int) -> None:
    # Bounded: a full buffer refuses new values, and the profile's counters say where each went.
    assert counters["pending"] <= queue
    assert counters["written"] == producer.produced == counters["read"] + counters["dropped"] + counters["pending"]
    seqs = [taken.seq for taken in consumer.taken]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)


def check_b(producer, consumer, counters: dict[str, int], tokens: int) -> None:
    # The producer is six times faster alone; coupled it runs at the consumer's rate, never more
    # than the tokens ahead, and nothing is lost.
    assert 0 <= producer.produced - consumer.consumed <= tokens
    assert counters["dropped"] == 0


def check_c(producer, hz: float) -> None:
    writes = list(producer.writes)
    rate = (len(writes) - 1) / (writes[-1].stamped - writes[0].stamped)
    # Alone the producer would run at ~2 kHz; the filter keeps it at most hz (5 % for the timing of
    # one update's sleep), and it is not starved either (a loose bound: the machine may be loaded).
    assert hz / 5 <= rate <= hz * 1.05
    assert [w.it for w in writes] == list(range(len(writes)))


def check_d(producer, consumer) -> None:
    writes, taken = list(producer.writes), list(consumer.taken)
    # Independent rates: the producer is not held back by the slower consumer.
    assert producer.produced >= 2 * len(taken)
    for index, one in enumerate(taken):
        # The newest value that was written before the request, or one written during the read.
        assert latest(writes, one.requested, done=True) <= one.it <= latest(writes, one.answered, done=False)
        if not one.new:  # told to reuse: nothing newer had come, and it is the value it had
            assert index > 0 and one.it == taken[index - 1].it


def latest(writes: list[Written], before: float, done: bool) -> int:
    """The iteration of the newest write that had finished (``done``) or begun before ``before``."""
    return max((w.it for w in writes if (w.done if done else w.stamped) < before), default=-1)


def test_a_data_driven_consumer_takes_every_value_at_the_producers_rate(run_file):
    app = run_file("flowvr_a_data_driven.xml", lambda app: parts(app)[1].consumed >= 60,
                   period_ms=5, producer_ms=0.2, consumer_ms=0.5, queue=64)
    check_a_every_value(*parts(app), data_connection(app).counters())


def test_a_data_driven_queue_grows_to_its_size_when_the_consumer_is_slower(run_file):
    queue = 6
    app = run_file("flowvr_a_data_driven.xml",
                   lambda app: data_connection(app).pending == queue and data_connection(app).dropped >= 5,
                   period_ms=2, producer_ms=0.1, consumer_ms=15, queue=queue)
    check_a_bounded(*parts(app), data_connection(app).counters(), queue)


@pytest.mark.parametrize("tokens", [1, 3])
def test_b_demand_driven_producer_runs_once_per_consumption(run_file, tokens):
    app = run_file("flowvr_b_demand_driven.xml", lambda app: parts(app)[1].consumed >= 40,
                   producer_ms=0.5, consumer_ms=3, tokens=tokens)
    producer, consumer = parts(app)
    check_b(producer, consumer, data_connection(app).counters(), tokens)
    assert app.activity("produce").stats.cycles == producer.produced


def test_c_max_frequency_bounds_the_producers_rate(run_file):
    hz = 50.0
    app = run_file("flowvr_c_max_frequency.xml", lambda app: parts(app)[0].produced >= 60,
                   max_hz=hz, producer_ms=0.5, consumer_ms=1)
    check_c(parts(app)[0], hz)


def test_d_greedy_consumer_always_gets_the_newest_value_at_its_own_rate(run_file):
    app = run_file("flowvr_d_greedy.xml", lambda app: parts(app)[1].consumed >= 30,
                   producer_ms=1, consumer_ms=8)
    producer, consumer = parts(app)
    check_d(producer, consumer)
    [greedy] = [c for c in app.connections if isinstance(c, Greedy)]
    assert greedy.reused == consumer.reused
    assert greedy.read == consumer.consumed
    assert greedy.written == producer.produced == greedy.read + greedy.dropped + greedy.pending
