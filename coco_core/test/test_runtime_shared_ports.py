"""Shared connections of an output port (a farm's source): each value goes to one of them, a free
one first, while the port's other connections still receive every value."""

from __future__ import annotations

import pytest

from coco_core import Application, BufferPolicy, Component, ConnectionPolicy, InputPort, OutputPort
from coco_core.pool import Slot
from coco_core.ports import PooledOutputPort


class Source(Component):
    out = OutputPort(int)


class Pooled(Component):
    frames = PooledOutputPort(slots=4)


class Sink(Component):
    inp = InputPort(int)


class FrameSink(Component):
    inp = InputPort(Slot)


def wired(workers: int, observers: int = 0):
    app = Application("shared")
    source = app.add(Source("source"))
    sinks = [app.add(Sink(f"worker{i}")) for i in range(workers)]
    watchers = [app.add(Sink(f"watcher{i}")) for i in range(observers)]
    policy = ConnectionPolicy(BufferPolicy.BUFFER, size=10)
    for sink in sinks:
        source.out.share(app.connect(source.out, sink.inp, policy))
    for watcher in watchers:
        app.connect(source.out, watcher.inp, policy)
    return source, sinks, watchers


def test_each_value_goes_to_one_shared_connection_in_turn():
    source, sinks, _ = wired(3)
    for value in range(6):
        source.out.write(value)
        for sink in sinks:  # every worker keeps up: the one in turn is free
            sink.inp.read_all()
    counts = [connection.written for connection in source.out.connections]
    assert counts == [2, 2, 2]


def test_a_free_worker_is_preferred_to_a_busy_one():
    source, (first, second), _ = wired(2)
    source.out.write(1)  # -> first, which does not read
    source.out.write(2)  # -> second
    assert second.inp.read_all() == [2]
    source.out.write(3)  # first still holds 1: the free second one takes 3
    assert first.inp.read_all() == [1]
    assert second.inp.read_all() == [3]


def test_when_every_worker_is_busy_the_next_in_turn_takes_the_value():
    source, sinks, _ = wired(2)
    for value in range(4):
        source.out.write(value)
    assert [sink.inp.read_all() for sink in sinks] == [[0, 2], [1, 3]]


def test_the_other_connections_still_receive_every_value():
    source, sinks, (watcher,) = wired(2, observers=1)
    for value in range(4):
        source.out.write(value)
    assert watcher.inp.read_all() == [0, 1, 2, 3]
    assert sorted(v for sink in sinks for v in sink.inp.read_all()) == [0, 1, 2, 3]


def test_only_a_connection_of_the_port_can_be_shared_and_not_a_pooled_one():
    source, (sink,), _ = wired(1)
    other = Application("other")
    stranger = other.connect(other.add(Source("s")).out, other.add(Sink("t")).inp)
    with pytest.raises(ValueError, match="is not a connection of source.out"):
        source.out.share(stranger)
    app = Application("pooled")
    camera = app.add(Pooled("camera"))
    connection = app.connect(camera.frames, app.add(FrameSink("viewer")).inp, ConnectionPolicy(BufferPolicy.POOL))
    with pytest.raises(ValueError, match="camera.frames is a pooled output"):
        camera.frames.share(connection)
