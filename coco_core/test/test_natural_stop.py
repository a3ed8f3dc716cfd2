"""The edge at the end of a run: a natural stop (the application asks for it itself: a replay that is
done, ``--duration``) stops the activities feeders first, and a triggered activity processes what its
feeders wrote last (a display's last frame, for the writer that records it) instead of leaving it
pending; a hard stop (Ctrl-C, a fault) still ends everything within a second."""

from __future__ import annotations

import time

from coco_core import (
    BufferPolicy,
    Component,
    ConnectionPolicy,
    InputPort,
    OutputPort,
    PeriodicActivity,
    SyncPolicy,
    TriggeredActivity,
)

QUEUE = ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 10_000)


class Counter(Component):
    """Writes 1, 2, 3, ... one a cycle, and "final" when it stops."""

    out = OutputPort(object)

    def init(self) -> None:
        self.count = 0

    def on_update(self) -> None:
        self.count += 1
        self.out.write(self.count)

    def on_stop(self) -> None:
        self.out.write("final")


class SlowRecorder(Component):
    """Takes one value a cycle and works ``work`` seconds on it: slower than its feeder, so a backlog
    waits on its event input when the application stops."""

    inp = InputPort(object, event=True)

    def init(self) -> None:
        self.values: list[object] = []
        self.work = 0.002

    def on_update(self) -> None:
        status, value = self.inp.read()
        if status.name == "NEW_DATA":
            self.values.append(value)
            time.sleep(self.work)


class Relay(Component):
    """Passes on what it reads (a middle stage of a pipeline)."""

    inp = InputPort(object, event=True)
    out = OutputPort(object)

    def on_update(self) -> None:
        for value in self.inp.read_all():
            self.out.write(value)


def pipeline(make_app, work: float = 0.002):
    app = make_app("edges")
    counter = app.add(Counter("counter"), PeriodicActivity("produce", 0.001))
    app.add(Relay("relay"), TriggeredActivity("relaying"))
    recorder = app.add(SlowRecorder("recorder"), TriggeredActivity("recording"))
    recorder.work = work
    app.connect("counter.out", "relay.inp", QUEUE)
    app.connect("relay.out", "recorder.inp", QUEUE)
    return app, counter, recorder


def test_a_natural_stop_processes_everything_the_feeders_wrote(make_app, wait_until) -> None:
    app, counter, recorder = pipeline(make_app)
    app.start()
    assert wait_until(lambda: counter.count >= 60, timeout=10.0)
    queue = app.connections[1]
    assert wait_until(lambda: queue.pending > 5, timeout=10.0), "the recorder should lag behind its feeder"
    app.request_stop("the work is done")
    assert app.stop() is True
    # Every value, the one the counter wrote in on_stop included, went through both stages.
    assert recorder.values == [*range(1, counter.count + 1), "final"]
    assert all(connection.pending == 0 and connection.dropped == 0 for connection in app.connections)


def test_a_hard_stop_does_not_wait_for_the_backlog(make_app, wait_until) -> None:
    app, counter, recorder = pipeline(make_app, work=0.05)
    app.start()
    queue = app.connections[1]
    assert wait_until(lambda: queue.pending > 20, timeout=10.0)
    app.request_stop("Ctrl-C", hard=True)
    begun = time.monotonic()
    assert app.stop() is True
    assert time.monotonic() - begun < 1.0
    # What was left is counted where the profile shows it, not lost silently.
    assert queue.pending > 0 and queue.written == queue.read + queue.pending + queue.dropped


def test_a_drain_ends_when_a_cycle_takes_nothing(make_app, wait_until) -> None:
    """A triggered component that does not read its input cannot hold the stop forever."""

    class Deaf(Component):
        inp = InputPort(object, event=True)

        def init(self) -> None:
            self.updates = 0

        def on_update(self) -> None:
            self.updates += 1

    app = make_app("deaf")
    counter = app.add(Counter("counter"), PeriodicActivity("produce", 0.001))
    deaf = app.add(Deaf("deaf"), TriggeredActivity("ignoring"))
    app.connect("counter.out", "deaf.inp", QUEUE)
    app.start()
    assert wait_until(lambda: counter.count >= 10 and deaf.updates > 0)
    app.request_stop("done")
    assert app.stop() is True
    assert app.connections[0].pending == counter.count + 1  # left there, and shown as pending


def test_the_stop_order_puts_feeders_first(make_app) -> None:
    app = make_app("order")
    app.add(Counter("counter"), PeriodicActivity("produce", 0.01))
    app.add(Relay("first"), TriggeredActivity("one"))
    app.add(Relay("second"), TriggeredActivity("two"))
    app.add(Relay("left"), TriggeredActivity("loop_a"))
    app.add(Relay("right"), TriggeredActivity("loop_b"))
    app.add(Relay("gui"), TriggeredActivity("gui", main=True))
    app.connect("second.out", "first.inp", QUEUE)  # declared out of order on purpose
    app.connect("counter.out", "second.inp", QUEUE)
    app.connect("left.out", "right.inp", QUEUE)
    app.connect("right.out", "left.inp", QUEUE)
    app.connect("first.out", "gui.inp", QUEUE)
    order, fed = app.stop_order()
    names = [activity.name for activity in order]
    assert names.index("produce") < names.index("two") < names.index("one"), names
    assert sorted(names) == sorted(app.activities)
    # A cycle does not wait on itself; the main activity never waits (its thread stops the others).
    assert fed == {"one", "two"}, fed
