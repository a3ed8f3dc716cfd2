"""Shared-memory channels (coco_core.shm): the in-process policies' semantics and counters, between
real processes; pooled frames read in place by other processes; no segment left behind."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from coco_core import Application, Component, InputPort, NEW_DATA, NO_DATA, OLD_DATA, OutputPort, PooledOutputPort, Stamp, Stamped
from coco_core.connections import Connection
from coco_core.errors import PoolError
from coco_core.policy import BufferPolicy, ConnectionPolicy, SyncPolicy
from coco_core.pool import FramePool, LocalFramePool, PoolReader, Slot, SlotState
from coco_core.shm import (FORCE_LOCKED, Arena, ChannelError, ChannelStats, FrameStats, Segment, ShmFrameNotifier,
                           ShmFramePool, ShmPoolReader, ShmReader, ShmWriter, leftovers, sweep)
from coco_core.stamps import Message
from coco_core.shm.channel import (CURSOR, FINISHED, HEADER, IT, LARGE, LENGTH, NUM, OFFERED, READ, ROUTED,
                                   SLOT_HEADER, STAMP, STORED, TIME)

DOCS = Path(__file__).resolve().parents[2] / "docs" / "processes.md"


@pytest.fixture(params=["unlocked", "locked"])
def arena(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch):
    """Every test runs on both paths of the rings: the CPU's (unlocked on x86-64) and the locked one
    of CPUs that may reorder stores (aarch64), forced here with COCO_SHM_LOCKED=1."""
    if request.param == "locked":
        monkeypatch.setenv(FORCE_LOCKED, "1")
    else:
        monkeypatch.delenv(FORCE_LOCKED, raising=False)
    launch = f"test{os.getpid()}x{os.urandom(3).hex()}"
    made = Arena(launch)
    yield made
    made.close()
    assert leftovers(launch) == [], "the arena unlinks every segment"


def ends(arena: Arena, data: BufferPolicy, size: int = 1) -> tuple[ShmWriter, ShmReader]:
    spec = arena.channel(ConnectionPolicy(data, SyncPolicy.LOCKED, size), "a.out->b.in")
    return ShmWriter(spec), ShmReader(spec)


def drain(reader: ShmReader) -> list[object]:
    port = InputPort(object).bind(None)  # type: ignore[arg-type]
    port.add_connection(reader)
    return port.read_all()


def test_data_gives_the_newest_value_once(arena: Arena) -> None:
    writer, reader = ends(arena, BufferPolicy.DATA)
    port = InputPort(object).bind(None)  # type: ignore[arg-type]
    port.add_connection(reader)
    assert port.read() == (NO_DATA, None)
    for value in range(5):
        writer.push(value)
    assert port.read() == (NEW_DATA, 4)
    assert port.read() == (OLD_DATA, 4)
    assert reader.counters() == {"written": 5, "read": 1, "dropped": 4, "pending": 0}


def test_buffer_refuses_new_values_when_full(arena: Arena) -> None:
    writer, reader = ends(arena, BufferPolicy.BUFFER, 3)
    for value in range(5):
        writer.push(value)
    assert writer.counters() == {"written": 5, "read": 0, "dropped": 2, "pending": 3}
    assert drain(reader) == [0, 1, 2]
    writer.push(5)
    assert drain(reader) == [5]
    assert reader.counters() == {"written": 6, "read": 4, "dropped": 2, "pending": 0}


def test_a_reader_that_wants_the_newest_counts_what_it_skipped(arena: Arena) -> None:
    writer, reader = ends(arena, BufferPolicy.BUFFER, 8)
    port = InputPort(object).bind(None)  # type: ignore[arg-type]
    port.add_connection(reader)
    for value in range(5):
        writer.push(value)
    assert port.read_newest() == (NEW_DATA, 4)
    assert reader.counters() == {"written": 5, "read": 1, "dropped": 4, "pending": 0}


def test_circular_drops_the_oldest(arena: Arena) -> None:
    writer, reader = ends(arena, BufferPolicy.CIRCULAR, 3)
    for value in range(7):
        writer.push(value)
    assert writer.counters()["pending"] == 3
    assert drain(reader) == [4, 5, 6]
    assert reader.counters() == {"written": 7, "read": 3, "dropped": 4, "pending": 0}


def test_values_keep_their_type_and_arrays_their_contents(arena: Arena) -> None:
    writer, reader = ends(arena, BufferPolicy.BUFFER, 4)
    sample = Stamped(np.arange(19, dtype=np.float64), Stamp(1.5, 7, "bag"))
    writer.push(sample)
    writer.push(None)
    got = drain(reader)
    assert got[1] is None
    assert isinstance(got[0], Stamped) and got[0].stamp == sample.stamp
    np.testing.assert_array_equal(got[0].value, sample.value)


def test_one_writer_encodes_each_value_afresh(arena: Arena) -> None:
    """A writer keeps one pickler for all its values (issue 24): each value still crosses whole and
    on its own (no memo reference back to an earlier value, an object shared inside one value stays
    shared), a value that cannot be encoded is refused without harming the next, and the writer
    keeps no reference to the arrays it sent."""
    import weakref

    writer, reader = ends(arena, BufferPolicy.BUFFER, 8)
    names = ["a", "b"]
    writer.push((names, names))
    names.append("c")  # the same list again, changed: its new contents cross, not a memo reference
    writer.push((names, 1))
    with pytest.raises(ChannelError, match="cannot be sent"):
        writer.push((names, lambda: None))
    array = np.arange(5.0)
    gone = weakref.ref(array)
    writer.push({"positions": array, "names": names})
    del array
    assert gone() is None, "the writer still holds the array it sent"
    first, second, third = drain(reader)
    assert first == (["a", "b"], ["a", "b"]) and first[0] is first[1]
    assert second == (["a", "b", "c"], 1)
    assert third["names"] == ["a", "b", "c"]
    np.testing.assert_array_equal(third["positions"], np.arange(5.0))
    assert (writer.written, reader.read, reader.dropped, reader.pending) == (3, 3, 0, 0)


def test_arrays_arrive_whole_and_writable_whatever_their_layout(arena: Arena) -> None:
    writer, reader = ends(arena, BufferPolicy.BUFFER, 4)
    grid = np.arange(24, dtype=np.float32).reshape(4, 6)
    sent = [grid, grid[:, ::2], np.asfortranarray(grid), {"names": ["a", "b"], "positions": grid[0]}]
    for value in sent:
        writer.push(value)
    got = drain(reader)
    for before, after in zip(sent[:3], got[:3]):
        np.testing.assert_array_equal(before, after)
        after[0, 0] = -1  # the reader owns its copy
    np.testing.assert_array_equal(got[3]["positions"], grid[0])
    assert got[3]["names"] == ["a", "b"] and grid[0, 0] == 0


def test_values_larger_than_a_slot_cross_through_the_overflow_segment(arena: Arena) -> None:
    spec = arena.channel(ConnectionPolicy(BufferPolicy.CIRCULAR, SyncPolicy.LOCKED, 2), "cam.frame->view.image",
                         capacity=1024)
    writer, reader = ShmWriter(spec), ShmReader(spec)
    images = [np.full((240, 320, 3), k, np.uint8) for k in range(5)]
    for image in images[:3]:
        writer.push(image)
    got = drain(reader)
    assert [int(image[0, 0, 0]) for image in got] == [1, 2], "the oldest was dropped, the others are whole"
    writer.push(np.zeros(10, np.uint8))  # a small one in the same slot again
    writer.push(np.full((480, 640, 3), 9, np.uint8))  # larger still: the overflow grows
    small, large = drain(reader)
    assert small.shape == (10,) and large.shape == (480, 640, 3) and int(large.sum()) == 9 * 480 * 640 * 3
    with pytest.raises(ChannelError, match="cannot be sent to another process"):
        writer.push(lambda: None)
    assert writer.counters()["written"] == 5


WRITER = """
import sys
from coco_core.shm import ShmWriter
spec = __import__("pickle").loads(bytes.fromhex(sys.argv[1]))
writer = ShmWriter(spec)
for value in range(int(sys.argv[2])):
    writer.push(("sample", value))
"""


@pytest.mark.parametrize("data, size, expect", [
    (BufferPolicy.BUFFER, 5000, list(range(5000))),
    (BufferPolicy.CIRCULAR, 10, list(range(4990, 5000))),
])
def test_values_cross_between_processes_with_their_counters(arena: Arena, data: BufferPolicy, size: int,
                                                            expect: list[int]) -> None:
    spec = arena.channel(ConnectionPolicy(data, SyncPolicy.LOCKED, size), "w.out->r.in")
    subprocess.run([sys.executable, "-c", WRITER, pickle.dumps(spec).hex(), "5000"], check=True, timeout=60)
    reader = ShmReader(spec)
    values = [value for _, value in drain(reader)]
    assert values == expect
    assert ChannelStats(spec).counters() == {"written": 5000, "read": len(expect),
                                             "dropped": 5000 - len(expect), "pending": 0}


FRAME_READER = """
import sys, pickle, time
from coco_core.shm import ShmPoolReader
spec = pickle.loads(bytes.fromhex(sys.argv[1]))
reader = ShmPoolReader(spec)
slot = None
deadline = time.monotonic() + 20
while slot is None or slot is __import__("coco_core").connections.EMPTY:
    slot = reader.pop()
    if time.monotonic() > deadline:
        sys.exit("no frame")
print(slot.array.shape, slot.array.dtype, int(slot.array.sum()), slot.stamp, slot.array.base is not None, flush=True)
sys.stdin.readline()   # hold the slot until told
slot.release()
print("released", flush=True)
"""


def test_frames_are_read_in_place_by_two_processes_with_the_slot_protocol(arena: Arena) -> None:
    spec = arena.channel(ConnectionPolicy(BufferPolicy.POOL, SyncPolicy.LOCKED, 4), "cam.frames->view.frames",
                         frames=True)
    pool = ShmFramePool(spec)
    slot = pool.acquire((480, 640, 3), np.uint8)
    assert slot is not None and pool.states()[slot.index] is SlotState.WRITING
    slot.array[:] = 3
    slot.stamp = Stamp(2.0, 11, "camera")
    pool.publish(slot)
    readers = [subprocess.Popen([sys.executable, "-c", FRAME_READER, pickle.dumps(spec).hex()],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True) for _ in range(2)]
    try:
        for reader in readers:
            line = reader.stdout.readline()  # type: ignore[union-attr]
            assert line.strip() == f"(480, 640, 3) uint8 {480 * 640 * 3 * 3} {Stamp(2.0, 11, 'camera')} True", line
        assert pool.states()[slot.index] is SlotState.READING
        # The writer goes on while the frame is read: the read slot is not reused.
        for _ in range(5):
            fresh = pool.acquire((480, 640, 3), np.uint8)
            assert fresh is not None and fresh.index != slot.index
            pool.publish(fresh)
        for reader in readers:
            reader.stdin.write("\n")  # type: ignore[union-attr]
            reader.stdin.flush()  # type: ignore[union-attr]
            assert reader.stdout.readline().strip() == "released"  # type: ignore[union-attr]
            assert reader.wait(timeout=10) == 0
        assert pool.states()[slot.index] is SlotState.FREE, "released by both and no longer the newest"
    finally:
        for reader in readers:
            if reader.poll() is None:
                reader.kill()
    local = ShmPoolReader(spec)
    newest = local.pop()
    assert newest.seq == 6 and newest.array.shape == (480, 640, 3)
    newest.release()
    bigger = pool.acquire((1080, 1920, 3), np.uint8)  # a size change: a new segment for that slot
    assert bigger is not None and bigger.array.shape == (1080, 1920, 3)
    bigger.array[0, 0] = 9
    pool.publish(bigger)
    frame = local.pop()
    assert frame.array.shape == (1080, 1920, 3) and frame.array[0, 0, 0] == 9
    frame.release()
    pool.unlink_slots()


def test_sweep_removes_what_a_killed_owner_left(tmp_path: Path) -> None:
    launch = f"killed{os.getpid()}"
    script = textwrap.dedent(f"""
        import os, signal
        from coco_core.policy import BufferPolicy, ConnectionPolicy
        from coco_core.shm import Arena, ShmFramePool
        arena = Arena({launch!r})
        arena.channel(ConnectionPolicy(BufferPolicy.BUFFER, size=8), "a.b->c.d")
        pool = ShmFramePool(arena.channel(ConnectionPolicy(BufferPolicy.POOL, size=4), "e.f->g.h", frames=True))
        pool.publish(pool.acquire((4, 4), "uint8"))
        os.kill(os.getpid(), signal.SIGKILL)
    """)
    subprocess.run([sys.executable, "-c", script], timeout=60)
    assert len(leftovers(launch)) == 3, leftovers(launch)
    assert len(sweep(launch)) == 3
    assert leftovers(launch) == []


# --- the contracts: Connection and FramePool as protocols, the ring's named layout, one pool path -

def test_connection_and_frame_pool_are_protocols_the_shared_memory_ends_implement(arena: Arena) -> None:
    """Before, the shared-memory ends skipped Connection.__init__ (setting its fields by hand) and
    ShmFramePool only looked like a FramePool (``type: ignore`` wherever one was expected)."""
    with pytest.raises(TypeError, match="abstract"):
        Connection(ConnectionPolicy())  # type: ignore[abstract]
    with pytest.raises(TypeError, match="abstract"):
        FramePool()  # type: ignore[abstract]
    values = arena.channel(ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 2), "a.out->b.in")
    frames = arena.channel(ConnectionPolicy(BufferPolicy.POOL, SyncPolicy.LOCKED, 3), "c.frames->d.in", frames=True,
                           readers=1)
    ends: list[Connection] = [ShmWriter(values), ShmReader(values), ChannelStats(values), ShmPoolReader(frames),
                              ShmFrameNotifier(frames), FrameStats(frames)]
    for end in ends:
        assert isinstance(end, Connection)
        assert (end.source, end.sink, end.trigger) == (None, None, None), type(end).__name__
        assert end.counters() == {"written": 0, "read": 0, "dropped": 0, "pending": 0}, type(end).__name__
    reader = ends[3]
    assert isinstance(reader, PoolReader) and isinstance(reader.pool, FramePool) and reader.pool.count == 3
    reader.pool.close()


def test_the_ring_has_the_documented_layout(arena: Arena) -> None:
    """The ring's words by name, as docs/processes.md lists them (before: bare indexes 0, 1, 2 into
    each slot's header)."""
    documented = {}
    for line in DOCS.read_text().splitlines():
        cells = [cell.strip(" `") for cell in line.strip().strip("|").split("|")]
        if len(cells) == 4 and cells[0] in ("header", "slot") and cells[1].isdigit():
            documented[cells[2]] = (cells[0], int(cells[1]))
    assert documented == {"OFFERED": ("header", OFFERED), "STORED": ("header", STORED), "READ": ("header", READ),
                          "CURSOR": ("header", CURSOR), "FINISHED": ("header", FINISHED), "ROUTED": ("header", ROUTED),
                          "STAMP": ("slot", STAMP), "LENGTH": ("slot", LENGTH), "LARGE": ("slot", LARGE),
                          "NUM": ("slot", NUM), "IT": ("slot", IT), "TIME": ("slot", TIME)}
    spec = arena.channel(ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 2), "a.out->b.in", capacity=1024)
    writer, reader = ShmWriter(spec), ShmReader(spec)
    writer.push(Message(b"small", 12.5, 1, "a.out", 7))  # as a port writes: the value and its stamp
    writer.push(np.zeros(4096, np.uint8))  # larger than a slot: in a segment of its own; bare, no message
    writer.push(1)  # refused: the BUFFER of 2 is full
    reader.pop()
    writer.writer_done()
    segment = Segment(spec.segment)
    words = segment.view.cast("q")
    slot = (SLOT_HEADER + spec.capacity) // 8
    try:
        header = [words[name] for name in (OFFERED, STORED, READ, CURSOR, FINISHED)]
        assert header == [3, 2, 1, 1, 1]
        first, second = HEADER // 8, HEADER // 8 + slot
        assert (words[first + STAMP], words[first + LARGE]) == (1, 0) and 0 < words[first + LENGTH] < spec.capacity
        assert (words[second + STAMP], words[second + LARGE]) == (2, 1) and words[second + LENGTH] > 4096
        assert (words[first + NUM], words[first + IT], words[second + NUM]) == (1, 7, 0)
        times = segment.view.cast("d")
        assert times[first + TIME] == 12.5
        times.release()
    finally:
        words.release()
        segment.close()


def test_a_pooled_outputs_pool_is_given_once_before_it_is_live(arena: Arena) -> None:
    """The process level gives a pooled output its pool in shared memory through use_pool, with the
    readers it already has in its process; nothing else can replace it, and not once frames went
    through (before: ``out.pool = ShmFramePool(...)`` on the port and on each of its connections)."""
    app = Application("pool")
    camera = app.add(Camera("camera"))
    viewer = app.add(Viewer("viewer"))
    local = app.connect(camera.frames, viewer.frames, ConnectionPolicy(BufferPolicy.POOL))
    with pytest.raises(AttributeError):
        camera.frames.pool = LocalFramePool(3)  # type: ignore[misc]
    wrong = ShmFramePool(arena.channel(ConnectionPolicy(BufferPolicy.POOL, SyncPolicy.LOCKED, 4), "x.y->z.w",
                                       frames=True))
    with pytest.raises(PoolError, match="camera.frames has 3 slots, the pool given to it 4"):
        camera.frames.use_pool(wrong)
    wrong.close()
    spec = arena.channel(ConnectionPolicy(BufferPolicy.POOL, SyncPolicy.LOCKED, 3), "camera.frames->far.in",
                         frames=True, readers=1)
    shared = ShmFramePool(spec)
    camera.frames.use_pool(shared)
    assert camera.frames.pool is shared and local.pool is shared, "the readers in this process read it too"
    slot = camera.frames.acquire((2, 2))
    assert slot is not None
    slot.array[:] = 7
    camera.frames.write(slot)
    far = ShmPoolReader(spec)
    for reader in (viewer.frames, far):
        status, frame = reader.read() if isinstance(reader, InputPort) else (NEW_DATA, reader.pop())
        assert status is NEW_DATA and int(frame.array.sum()) == 28
        frame.release()
    with pytest.raises(PoolError, match="camera.frames: its pool is in use"):
        camera.frames.use_pool(LocalFramePool(3))
    far.pool.close()
    shared.unlink_slots()
    shared.close()


class Camera(Component):
    frames = PooledOutputPort(slots=3)


class Viewer(Component):
    frames = InputPort(Slot)


class Sampler(Component):
    out = OutputPort(object)
    frames = PooledOutputPort(slots=3)


class Taker(Component):
    value = InputPort(object)
    frame = InputPort(Slot)


@pytest.mark.parametrize("payload", ["plain", "stamped", "large"])
def test_the_message_stamp_crosses_the_channels_as_in_one_process(arena: Arena, payload: str) -> None:
    """A reader in another process reads the stamp the writing port gave each value and frame
    (number, source, iteration, time; a Stamped value's acquisition time and steps), as a reader in
    the writer's process does (before: a plain value and a frame arrived with no stamp, a Stamped
    one with its own stamp only, its number and source lost)."""
    app = Application("stamps")
    source, near = app.add(Sampler("source")), app.add(Taker("near"))
    app.connect(source.out, near.value, ConnectionPolicy(BufferPolicy.BUFFER, size=4))
    app.connect(source.frames, near.frame, ConnectionPolicy(BufferPolicy.POOL))
    values = arena.channel(ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 4), "source.out->far.value",
                           capacity=256)
    frames = arena.channel(ConnectionPolicy(BufferPolicy.POOL, SyncPolicy.LOCKED, 3), "source.frames->far.frame",
                           frames=True, readers=1)
    source.out.add_connection(ShmWriter(values))
    source.frames.use_pool(ShmFramePool(frames))
    far = Taker("far")
    far.value.add_connection(ShmReader(values))
    far.frame.add_connection(ShmPoolReader(frames))
    value = {"plain": 41, "stamped": Stamped(41, Stamp(3.25).step("sent", 3.5)), "large": np.arange(512.0)}[payload]
    for _ in range(2):
        source.out.write(value)
        slot = source.frames.acquire((2, 2))
        assert slot is not None
        source.frames.write(slot)
    written = source.out.stamp
    assert written is not None and written.seq == 2 and written.source == "source.out"
    if payload == "stamped":
        assert (written.time, written.steps) == (3.25, (("sent", 3.5),))
    for reader in (near, far):
        assert len(reader.value.read_all()) == 2
        assert reader.value.stamp == written, reader.name
        status, frame = reader.frame.read()
        assert status is NEW_DATA
        assert reader.frame.stamp == source.frames.stamp and frame.message.seq == 2, reader.name
        frame.release()
    stamp = far.frame.stamp
    assert stamp is not None and stamp.source == "source.frames"
    far.value.connections[0].close()  # type: ignore[attr-defined]
    far.frame.connections[0].pool.close()  # type: ignore[attr-defined]
    source.frames.pool.unlink_slots()  # type: ignore[attr-defined]
