"""Relay: every value of its input written on, in its own activity, and what its connections drop
counted on them."""

from __future__ import annotations

from coco_core import Application, Component, InputPort, OutputPort
from coco_core.policy import BufferPolicy, ConnectionPolicy
from coco_core.relay import Relay


class Source(Component):
    out = OutputPort(object)


class Sink(Component):
    values = InputPort(object)


def test_every_value_passes_in_order_and_the_same_object() -> None:
    app = Application("relay")
    source, relay, sink = Source("source"), Relay("relay"), Sink("sink")
    for component in (source, relay, sink):
        app.add(component)
    app.connect("source.out", "relay.input", ConnectionPolicy(BufferPolicy.BUFFER, size=10))
    app.connect("relay.output", "sink.values", ConnectionPolicy(BufferPolicy.BUFFER, size=10))
    assert relay.configure()
    big = bytearray(1 << 20)
    for value in (1, big, 3):
        source.out.write(value)
    relay.step()
    received = sink.values.read_all()
    assert received == [1, big, 3] and received[1] is big, "handed over by reference in one process"
    assert relay.port("input").event, "an arrival wakes the relay's activity"


def test_a_data_input_passes_the_newest() -> None:
    app = Application("relay")
    source, relay, sink = Source("source"), Relay("relay"), Sink("sink")
    for component in (source, relay, sink):
        app.add(component)
    app.connect("source.out", "relay.input")
    app.connect("relay.output", "sink.values")
    assert relay.configure()
    for value in range(5):
        source.out.write(value)
    relay.step()
    assert sink.values.read_all() == [4]
    connection = relay.port("input").connections[0]
    assert connection.dropped == 4, "the older values count as dropped on the connection"
