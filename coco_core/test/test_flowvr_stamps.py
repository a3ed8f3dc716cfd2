"""Message stamps (FlowVR's stamp list): every write on a port is stamped with the message's number,
the writing port and the iteration of the writing activity, read beside the value."""

from __future__ import annotations

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
from coco_core.policy import NEW_DATA, OLD_DATA
from coco_core.stamps import Stamp, Stamped

BUFFERED = ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 100)


class Counter(Component):
    """Writes its update count, plain."""

    out = OutputPort(int)

    def init(self) -> None:
        self.count = 0

    def on_update(self) -> None:
        self.out.write(self.count)
        self.count += 1


class Collector(Component):
    """Keeps every value read with its stamp."""

    sample = InputPort(object, event=True)

    def init(self) -> None:
        self.got: list[tuple[object, Stamp | None]] = []

    def on_update(self) -> None:
        while (read := self.sample.read())[0] is NEW_DATA:  # each value with its own stamp
            self.got.append((read[1], self.sample.stamp))


def test_each_write_carries_its_iteration_source_and_number(make_app, wait_until):
    app = make_app()
    counter, collector = app.add(Counter("counter")), app.add(Collector("collector"))
    app.connect("counter.out", "collector.sample", BUFFERED)
    app.add_activity(PeriodicActivity("producing", 0.002, [counter]))
    app.add_activity(TriggeredActivity("collecting", [collector]))
    app.start()
    assert wait_until(lambda: len(collector.got) >= 5)
    app.stop()
    for index, (value, stamp) in enumerate(collector.got):
        assert stamp is not None
        # The counter writes once a cycle: its value is the cycle number, its activity's iteration.
        assert (stamp.it, stamp.seq, stamp.source) == (value, index + 1, "counter.out")
    times = [stamp.time for _, stamp in collector.got if stamp is not None]
    assert times == sorted(times)
    assert counter.out.stamp is not None and counter.out.stamp.seq == len(collector.got)


def test_a_stamped_value_reaches_the_reader_unchanged_and_its_acquisition_time_is_the_messages(make_app):
    app = make_app()
    writer, reader = app.add(Counter("writer")), app.add(Collector("reader"))
    app.connect("writer.out", "reader.sample")
    sent = Stamped(3.5, Stamp(12.0, 7, "camera"))
    writer.out.write(sent)
    status, value = reader.sample.read()
    assert status is NEW_DATA and value is sent
    stamp = reader.sample.stamp
    assert stamp is not None
    assert (stamp.time, stamp.seq, stamp.source, stamp.it) == (12.0, 1, "writer.out", -1)
    # Reused: the old value keeps its stamp.
    assert reader.sample.read() == (OLD_DATA, sent) and reader.sample.stamp == stamp


def test_a_value_pushed_on_a_connection_directly_is_read_as_before():
    """Code that pushes bare values into a connection (a channel from another process does) still
    reads them; a Stamped one brings its own stamp."""
    from coco_core.connections import make_connection

    port = InputPort(object).bind(Collector("reader"), "sample")
    connection = make_connection(ConnectionPolicy())
    port.add_connection(connection)
    connection.push(4)
    assert port.read() == (NEW_DATA, 4) and port.stamp is None
    stamped = Stamped(5, Stamp(1.0, 2, "elsewhere"))
    connection.push(stamped)
    assert port.read() == (NEW_DATA, stamped) and port.stamp is stamped.stamp


def test_the_newest_read_takes_the_newest_messages_stamp(make_app):
    app = make_app()
    writer, reader = app.add(Counter("writer")), app.add(Collector("reader"))
    app.connect("writer.out", "reader.sample", BUFFERED)
    for value in range(4):
        writer.out.write(value)
    assert reader.sample.read_newest() == (NEW_DATA, 3)
    assert reader.sample.stamp is not None and reader.sample.stamp.seq == 4


def test_the_origin_of_a_value_is_its_own_stamp_or_its_messages(make_app):
    """What a latency is measured from: a Stamped value's own stamp (its source and number kept), a
    plain value's message stamp (the write), each value of a backlog with its own; an old value
    keeps its origin."""
    app = make_app()
    writer, reader = app.add(Counter("writer")), app.add(Collector("reader"))
    app.connect("writer.out", "reader.sample", BUFFERED)
    acquired = Stamp(12.0, 7, "camera", (("sent", 12.5),))
    writer.out.write(Stamped(3.5, acquired))
    writer.out.write(4)
    first = writer.out.last
    writer.out.write(5)
    assert first is not None and writer.out.stamp is not None
    assert reader.sample.read_all_origins() == [(Stamped(3.5, acquired), acquired), (4, first.stamp),
                                                (5, writer.out.stamp)]
    assert (first.stamp.seq, first.stamp.source) == (2, "writer.out")
    assert reader.sample.read() == (OLD_DATA, 5) and reader.sample.origin == writer.out.stamp
    assert reader.sample.read_all_origins() == []


def test_a_plain_value_pushed_without_a_port_has_no_origin():
    from coco_core.connections import make_connection

    port = InputPort(object).bind(Collector("reader"), "sample")
    connection = make_connection(ConnectionPolicy())
    port.add_connection(connection)
    assert port.origin is None  # nothing read yet
    connection.push(4)
    assert port.read() == (NEW_DATA, 4) and port.origin is None
    stamped = Stamped(5, Stamp(1.0, 2, "elsewhere"))
    connection.push(stamped)
    assert port.read() == (NEW_DATA, stamped) and port.origin is stamped.stamp


def test_a_peers_and_a_later_ports_messages_carry_their_activitys_iteration():
    """The activity whose cycle stamps a write is given to the ports by their component: to those
    of a peer nested after the owner was scheduled, and to a port added afterwards."""
    owner, peer = Counter("owner"), Counter("peer")
    activity = PeriodicActivity("producing", 0.01, [owner])
    owner.add_peer(peer)
    extra = peer.add_output("extra", int)
    activity.stats.cycles = 7
    for port in (owner.out, peer.out, extra):
        port.write(1)
        assert port.stamp is not None and port.stamp.it == 7, port


def test_every_policy_gives_a_port_reader_and_a_popping_reader_the_same_stamp(make_app):
    """A connection of one process keeps the write's record; the message a reader without a port
    pops (a ROS mirror, ``beginit``) is made from it with the stamp the port's reader reads."""
    for data in BufferPolicy.DATA, BufferPolicy.BUFFER, BufferPolicy.CIRCULAR:
        for sync in SyncPolicy:
            app = make_app()
            writer, reader = app.add(Counter("writer")), app.add(Collector("reader"))
            connection = app.connect("writer.out", "reader.sample", ConnectionPolicy(data, sync, 4))
            writer.out.write(Stamped(1.5, Stamp(3.0, 9, "camera")), stamps={"bbox": (0, 1)})
            assert reader.sample.read() == (NEW_DATA, Stamped(1.5, Stamp(3.0, 9, "camera")))
            read_stamp = reader.sample.stamp
            writer.out.write(2.5, stamps={"bbox": (0, 1)})
            popped = connection.pop()
            assert popped.value == 2.5 and popped.stamp == writer.out.stamp
            assert read_stamp is not None
            assert (read_stamp.time, read_stamp.seq, read_stamp.user) == (3.0, 1, {"bbox": (0, 1)})
            connection.push(4)  # the same bare value twice is two values
            assert reader.sample.read() == (NEW_DATA, 4) and reader.sample.stamp is None
            connection.push(4)
            assert reader.sample.read() == (NEW_DATA, 4)
            assert connection.counters() == {"written": 4, "read": 4, "dropped": 0, "pending": 0}
