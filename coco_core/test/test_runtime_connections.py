"""Connections between ports: every buffering x sync policy, counters, round robin, concurrency."""

from __future__ import annotations

import sys
import threading
import time

import pytest

from coco_core import (
    NEW_DATA,
    NO_DATA,
    OLD_DATA,
    Application,
    BufferPolicy,
    Component,
    ConnectionPolicy,
    InputPort,
    OutputPort,
    SyncPolicy,
)
from coco_core.connections import EMPTY, make_connection
from coco_core.mutex import TOKEN

SYNCS = [SyncPolicy.LOCKED, SyncPolicy.UNSYNC, SyncPolicy.LOCK_FREE]
ALL = [(data, sync) for data in (BufferPolicy.DATA, BufferPolicy.BUFFER, BufferPolicy.CIRCULAR) for sync in SYNCS]


class Source(Component):
    out = OutputPort(object)


class Sink(Component):
    inp = InputPort(object)


def pair(policy: ConnectionPolicy, sources: int = 1):
    """An application with ``sources`` writers connected to one reader; returns (outputs, input, connections)."""
    app = Application("connections")
    sink = app.add(Sink("sink"))
    outs, connections = [], []
    for index in range(sources):
        source = app.add(Source(f"source{index}"))
        connections.append(app.connect(source.out, sink.inp, policy))
        outs.append(source.out)
    return outs, sink.inp, connections


def counters(connection) -> tuple[int, int, int, int]:
    c = connection.counters()
    return c["written"], c["read"], c["dropped"], c["pending"]


# --- every buffering x sync combination ------------------------------------------------------------


@pytest.mark.parametrize("data,sync", ALL, ids=[f"{d.value}-{s.value}" for d, s in ALL])
def test_no_data_before_any_write(data, sync):
    (out,), inp, (conn,) = pair(ConnectionPolicy(data, sync, 3))
    assert inp.read() == (NO_DATA, None)
    assert inp.read() == (NO_DATA, None)
    assert inp.read_all() == []
    assert counters(conn) == (0, 0, 0, 0)
    assert conn.policy == ConnectionPolicy(data, sync, 3)


@pytest.mark.parametrize("data,sync", ALL, ids=[f"{d.value}-{s.value}" for d, s in ALL])
def test_old_data_after_a_read(data, sync):
    (out,), inp, (conn,) = pair(ConnectionPolicy(data, sync, 3))
    out.write("a")
    assert inp.read() == (NEW_DATA, "a")
    assert inp.read() == (OLD_DATA, "a")
    assert inp.read() == (OLD_DATA, "a")
    assert counters(conn) == (1, 1, 0, 0)
    out.write("b")
    status, value = inp.read()
    assert status is NEW_DATA and value == "b"
    assert inp.read() == (OLD_DATA, "b")


@pytest.mark.parametrize("data,sync", ALL, ids=[f"{d.value}-{s.value}" for d, s in ALL])
def test_none_is_a_legitimate_value(data, sync):
    (out,), inp, (conn,) = pair(ConnectionPolicy(data, sync, 3))
    out.write(None)
    assert conn.pending == 1
    assert inp.read() == (NEW_DATA, None)
    assert inp.read() == (OLD_DATA, None)
    assert counters(conn) == (1, 1, 0, 0)
    # A None read must not be confused with "nothing there" when more data follows.
    out.write(0)
    out.write(None)
    values = inp.read_all()
    # DATA keeps the latest value (None overwrote 0); the FIFOs keep both.
    assert values == ([None] if data is BufferPolicy.DATA else [0, None])
    assert inp.read() == (OLD_DATA, None)


@pytest.mark.parametrize("sync", SYNCS, ids=[s.value for s in SYNCS])
def test_data_overwrites_unread_values(sync):
    (out,), inp, (conn,) = pair(ConnectionPolicy(BufferPolicy.DATA, sync))
    for value in (1, 2, 3):
        out.write(value)
    assert counters(conn) == (3, 0, 2, 1)
    assert inp.read() == (NEW_DATA, 3)
    assert counters(conn) == (3, 1, 2, 0)
    assert inp.read() == (OLD_DATA, 3)
    out.write(4)
    assert counters(conn) == (4, 1, 2, 1)
    assert inp.read() == (NEW_DATA, 4)
    assert counters(conn) == (4, 2, 2, 0)


@pytest.mark.parametrize("sync", SYNCS, ids=[s.value for s in SYNCS])
def test_buffer_drops_new_data_when_full(sync):
    (out,), inp, (conn,) = pair(ConnectionPolicy(BufferPolicy.BUFFER, sync, 3))
    for value in range(1, 6):
        out.write(value)
    assert counters(conn) == (5, 0, 2, 3)
    assert inp.read() == (NEW_DATA, 1)
    assert counters(conn) == (5, 1, 2, 2)
    out.write(6)  # room for one again: accepted
    out.write(7)  # full again: dropped
    assert counters(conn) == (7, 1, 3, 3)
    assert inp.read_all() == [2, 3, 6]
    assert inp.read() == (OLD_DATA, 6)
    assert counters(conn) == (7, 4, 3, 0)


@pytest.mark.parametrize("sync", SYNCS, ids=[s.value for s in SYNCS])
def test_circular_drops_oldest_when_full(sync):
    (out,), inp, (conn,) = pair(ConnectionPolicy(BufferPolicy.CIRCULAR, sync, 3))
    for value in range(1, 6):
        out.write(value)
    assert counters(conn) == (5, 0, 2, 3)
    assert inp.read() == (NEW_DATA, 3)
    assert counters(conn) == (5, 1, 2, 2)
    out.write(6)
    out.write(7)  # pushes 4 out
    assert counters(conn) == (7, 1, 3, 3)
    assert inp.read_all() == [5, 6, 7]
    assert inp.read() == (OLD_DATA, 7)
    assert counters(conn) == (7, 4, 3, 0)


@pytest.mark.parametrize("data", [BufferPolicy.BUFFER, BufferPolicy.CIRCULAR])
def test_sized_policies_need_a_positive_size(data):
    with pytest.raises(ValueError, match="size"):
        ConnectionPolicy(data, SyncPolicy.LOCKED, 0)
    assert str(ConnectionPolicy(data, SyncPolicy.LOCK_FREE, 4)) == f"{data.value}/LOCK_FREE[4]"


def test_pool_policy_is_not_a_copying_connection():
    with pytest.raises(ValueError, match="pooled"):
        make_connection(ConnectionPolicy(BufferPolicy.POOL))


def test_connection_pop_returns_empty_sentinel_not_none():
    conn = make_connection(ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCK_FREE, 2))
    assert conn.pop() is EMPTY
    conn.push(None)
    assert conn.pop() is None
    assert conn.pop() is EMPTY


@pytest.mark.parametrize("data,sync", ALL, ids=[f"{d.value}-{s.value}" for d, s in ALL])
def test_read_newest_counts_what_it_skipped_as_dropped(data, sync):
    """A reader that keeps only the newest drops the older items it took: the profile must show them."""
    (out,), inp, (conn,) = pair(ConnectionPolicy(data, sync, 8))
    assert inp.read_newest() == (NO_DATA, None)
    for value in range(1, 6):
        out.write(value)
    assert inp.read_newest() == (NEW_DATA, 5)
    written, read, dropped, pending = counters(conn)
    assert (written, read, dropped, pending) == (5, 1, 4, 0)
    assert inp.read_newest() == (OLD_DATA, 5)
    out.write(6)
    assert inp.read_newest() == (NEW_DATA, 6)
    assert counters(conn) == (6, 2, 4, 0)


def test_read_newest_over_several_connections_drops_the_other_candidates():
    (a, b), inp, (ca, cb) = pair(ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 8), sources=2)
    a.write("a1")
    a.write("a2")
    b.write("b1")
    assert inp.read_newest() == (NEW_DATA, "b1")
    assert counters(ca) == (2, 0, 2, 0)
    assert counters(cb) == (1, 1, 0, 0)


# --- fan-in, fan-out, unconnected ---------------------------------------------------------------


def test_round_robin_over_three_sources():
    (a, b, c), inp, conns = pair(ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 10), sources=3)
    a.write("a1")
    a.write("a2")
    b.write("b1")
    c.write("c1")
    c.write("c2")
    c.write("c3")
    got = [inp.read() for _ in range(6)]
    assert got == [(NEW_DATA, v) for v in ("a1", "b1", "c1", "a2", "c2", "c3")]
    assert inp.read() == (OLD_DATA, "c3")
    assert [conn.read for conn in conns] == [2, 1, 3]


def test_round_robin_starts_after_the_source_that_delivered_last():
    (a, b, c), inp, _ = pair(ConnectionPolicy(BufferPolicy.DATA), sources=3)
    for _ in range(3):
        a.write("a")
        b.write("b")
        c.write("c")
        # Whatever happened before, every source gets its turn: no source is read twice in a row.
        assert sorted(v for _, v in (inp.read(), inp.read(), inp.read())) == ["a", "b", "c"]
    b.write("b")
    assert inp.read() == (NEW_DATA, "b")
    a.write("a")
    c.write("c")
    # b delivered last, so c comes before a.
    assert inp.read() == (NEW_DATA, "c")
    assert inp.read() == (NEW_DATA, "a")


def test_one_output_to_many_inputs_has_independent_counters():
    app = Application("fanout")
    source = app.add(Source("source"))
    sinks = [app.add(Sink(f"sink{i}")) for i in range(3)]
    conns = [app.connect(source.out, s.inp, ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 2))
             for s in sinks]
    for value in range(3):
        source.out.write(value)
    assert sinks[0].inp.read_all() == [0, 1]
    assert sinks[1].inp.read() == (NEW_DATA, 0)
    assert counters(conns[0]) == (3, 2, 1, 0)
    assert counters(conns[1]) == (3, 1, 1, 1)
    assert counters(conns[2]) == (3, 0, 1, 2)


def test_every_write_reaches_the_connections_given_it_as_they_come_muted_and_go():
    """A port with one connection writes straight to it: a second one, muting either, a shared one
    or a stamps-only one each change that route, and every write reaches exactly who is given it."""
    app = Application("routes")
    source = app.add(Source("source"))
    sinks = [app.add(Sink(f"sink{i}")) for i in range(4)]
    first = app.connect(source.out, sinks[0].inp)
    source.out.write(1)
    second = app.connect(source.out, sinks[1].inp)
    source.out.write(2)
    assert [sink.inp.read() for sink in sinks[:2]] == [(NEW_DATA, 2), (NEW_DATA, 2)]
    source.out.mute(second, True)
    source.out.write(3)
    assert [sink.inp.read() for sink in sinks[:2]] == [(NEW_DATA, 3), (OLD_DATA, 2)]
    source.out.mute(first, True)
    source.out.mute(second, False)
    source.out.write(4)
    assert [sink.inp.read() for sink in sinks[:2]] == [(OLD_DATA, 3), (NEW_DATA, 4)]
    stamps = app.connect(source.out, sinks[2].inp, stamps_only=True)
    source.out.write(5)
    assert sinks[1].inp.read() == (NEW_DATA, 5)
    status, stamp = sinks[2].inp.read()
    assert status is NEW_DATA and stamp.seq == 5
    source.out.mute(first, False)
    shared = app.connect(source.out, sinks[3].inp)
    source.out.share(shared)
    source.out.write(6)
    assert [sink.inp.read()[1] for sink in sinks] == [6, 6, source.out.stamp, 6]
    assert [counters(c)[0] for c in (first, second, stamps, shared)] == [4, 4, 2, 1]


def test_write_with_no_connection_is_a_noop():
    source = Source("alone")
    assert not source.out.connected
    source.out.write(1)
    source.out.write(None)
    assert source.out.connections == []
    sink = Sink("lonely")
    assert sink.inp.read() == (NO_DATA, None)
    assert sink.inp.read_all() == []


def test_application_connections_are_recorded_with_their_ports():
    (out,), inp, (conn,) = pair(ConnectionPolicy(BufferPolicy.CIRCULAR, SyncPolicy.LOCK_FREE, 2))
    assert conn.source is out and conn.sink is inp
    assert out.connections == [conn] and inp.connections == [conn]
    assert "source0.out" in repr(conn) and "sink.inp" in repr(conn)


# --- concurrency: one writer thread, one reader thread --------------------------------------------

N = 40_000


@pytest.fixture
def tight_switching():
    """Switch threads far more often than usual, so the writer and reader really interleave."""
    previous = sys.getswitchinterval()
    sys.setswitchinterval(1e-5)
    yield
    sys.setswitchinterval(previous)


def hammer(policy: ConnectionPolicy):
    """Write 0..N-1 from one thread while another reads; return (received, drained_after, connection)."""
    (out,), inp, (conn,) = pair(policy)
    received: list[int] = []
    done = threading.Event()
    started = threading.Barrier(2)

    def writer():
        write = out.write
        started.wait()
        for chunk in range(0, N, 1000):
            seen = len(received)
            for value in range(chunk, chunk + 1000):
                write(value)
            # However the OS schedules the two threads, let the reader take something between chunks,
            # so the test always exercises reads concurrent with writes into a full buffer.
            deadline = time.monotonic() + 1.0
            while len(received) == seen and time.monotonic() < deadline:
                time.sleep(0)
        done.set()

    def reader():
        read = inp.read
        started.wait()
        while not done.is_set():
            status, value = read()
            if status is NEW_DATA:
                received.append(value)

    threads = [threading.Thread(target=writer), threading.Thread(target=reader)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(20)
    assert not any(thread.is_alive() for thread in threads)
    pending_before_drain = conn.pending
    drained = inp.read_all()
    assert len(drained) == pending_before_drain
    return received, drained, conn


@pytest.mark.parametrize("sync", [SyncPolicy.LOCK_FREE, SyncPolicy.LOCKED], ids=lambda s: s.value)
@pytest.mark.parametrize("data", [BufferPolicy.BUFFER, BufferPolicy.CIRCULAR], ids=lambda d: d.value)
def test_concurrent_writer_and_reader_keep_fifo_order_and_counters(data, sync, tight_switching):
    size = 8
    received, drained, conn = hammer(ConnectionPolicy(data, sync, size))
    everything = received + drained
    # FIFO: values come out in the order they were written, each at most once.
    assert all(a < b for a, b in zip(everything, everything[1:])), "FIFO order lost"
    assert conn.written == N
    assert conn.read == len(everything)
    assert conn.pending == 0
    # What was neither read nor pending was dropped, and the counters say exactly that.
    assert conn.dropped == N - len(everything)
    assert conn.written == conn.read + conn.dropped + conn.pending
    assert conn.read > size, "the reader never ran concurrently with the writer"
    assert conn.dropped > 0, "the buffer never filled up: the test did not hammer a full buffer"
    if data is BufferPolicy.BUFFER:
        # Drop-new: the first `size` values always get in.
        assert everything[:size] == list(range(size))
    else:
        # Drop-oldest: the last value written is always kept.
        assert everything[-1] == N - 1


@pytest.mark.parametrize("sync", [SyncPolicy.LOCK_FREE, SyncPolicy.LOCKED], ids=lambda s: s.value)
def test_concurrent_data_connection_never_goes_back_in_time(sync, tight_switching):
    received, drained, conn = hammer(ConnectionPolicy(BufferPolicy.DATA, sync))
    everything = received + drained
    assert all(a < b for a, b in zip(everything, everything[1:]))
    assert conn.written == N
    assert conn.read == len(everything)
    assert conn.written == conn.read + conn.dropped + conn.pending
    assert conn.pending == 0
    assert everything[-1] == N - 1


@pytest.mark.parametrize("data", [BufferPolicy.DATA, BufferPolicy.BUFFER, BufferPolicy.CIRCULAR], ids=lambda d: d.value)
def test_a_locked_write_waits_while_the_other_side_holds_the_mutex(data):
    """The mutex is one token (coco_core.mutex): while the reader's side holds it, the writer's put
    does not store, and it stores as soon as the token is back."""
    conn = make_connection(ConnectionPolicy(data, SyncPolicy.LOCKED, 1 if data is BufferPolicy.DATA else 4))
    guard = conn._mutex
    guard.get()  # the reader's critical section, entered
    writer = threading.Thread(target=conn.push, args=("late",))
    writer.start()
    writer.join(0.05)
    assert writer.is_alive() and conn.written == 0, "a LOCKED put entered while the other side held the mutex"
    guard.put_nowait(TOKEN)
    writer.join(20)
    assert not writer.is_alive() and conn.pop() == "late"
    assert guard.qsize() == 1, "the mutex was not given back exactly once"
