"""Channels between processes behave exactly as in one process (issue 27).

Each application runs twice with a real ``coco-launch``: once with its ``<process>`` elements and
once without them (the one-process reference); ``data/channel_apps.py`` checks both runs and compares
them: the values each reader got (in order, payloads intact), the profile's counters
(written = read + dropped + pending), the pool's slots at the end, and /dev/shm afterwards. A few
seeded generated applications run here; ``bench/soak_channels.py`` runs many more.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from coco_core import NEW_DATA, InputPort
from coco_core.connections import EMPTY
from coco_core.pool import PoolReader, SlotState
from coco_core.policy import BufferPolicy, ConnectionPolicy, SyncPolicy
from coco_core.shm import Arena, ShmPoolReader, ShmReader, ShmWriter, leftovers

sys.path.insert(0, str(Path(__file__).parent / "data"))
import channel_apps as apps  # noqa: E402  (the folder the launcher's processes import components from)
from channel_apps import Case, ReaderCase  # noqa: E402


@pytest.fixture
def arena():
    launch = f"test{os.getpid()}x{os.urandom(3).hex()}"
    made = Arena(launch)
    yield made
    made.close()
    assert leftovers(launch) == [], "the arena unlinks every segment"


# --- 1. every pooled reader gets the frames, wherever it runs -------------------------------------

@pytest.mark.parametrize("writer, readers", [("p0", ("", "p1", "p2")), ("", ("p0", "", "p1"))],
                         ids=["writer_in_a_child", "writer_in_the_launcher"])
def test_every_pooled_reader_gets_every_frame_wherever_it_runs(tmp_path: Path, writer: str,
                                                               readers: tuple[str, str, str]) -> None:
    """One pooled output, three readers: in the launcher, in the writer's process or in children of
    their own (before: only the first reader across processes got frames, the others none, their
    rows 0/0/0/0)."""
    case = Case("POOL", 1, "frame", 8192, 150, 5, writer, [ReaderCase("read_all", True, readers[0]),
                                                           ReaderCase("read", False, readers[1]),
                                                           ReaderCase("read_all", True, readers[2])])
    alone, spread = apps.check(case, tmp_path)
    for index in range(3):
        assert spread.rows[f"src.frames -> r{index}.value"][1] > 0, spread.output


# --- 2. a released slot is not read again as OLD_DATA ---------------------------------------------

def test_a_pooled_reader_with_nothing_new_gets_no_data_not_its_released_slot(tmp_path: Path) -> None:
    """A periodic reader faster than the writer calls read() with nothing new most of the time: in
    one process that is NO_DATA; it was OLD_DATA with the slot already released."""
    case = Case("POOL", 1, "frame", 64, 40, 1, "", [ReaderCase("read", False, "p0")], period=10.0)
    alone, spread = apps.check(case, tmp_path)
    assert alone.old == spread.old == [0]


# --- 3. read_newest releases the frames it skips ---------------------------------------------------

FRAME_WRITER = """
import pickle, sys, time
import numpy as np
from coco_core.shm import ShmFramePool
pool = ShmFramePool(pickle.loads(bytes.fromhex(sys.argv[1])))
while pool.published < int(sys.argv[2]):
    slot = pool.acquire((16,), np.uint8)
    if slot is not None:
        pool.publish(slot)
    time.sleep(1e-4)
"""


def test_read_newest_releases_the_frames_it_skips(arena: Arena) -> None:
    """A writer process publishes while the reader takes only the newest frame: a frame published
    while read_newest takes another replaces it, and the one replaced is released (before: it stayed
    READING for good, and after a few the writer had no slot left). ShmPoolReader is a
    PoolReader, as the in-process pool's readers: they run the same pop_newest."""
    spec = arena.channel(ConnectionPolicy(BufferPolicy.POOL, SyncPolicy.LOCKED, 4), "w.frames->r.value", frames=True)
    connection = ShmPoolReader(spec)
    port = InputPort(object).bind(None)  # type: ignore[arg-type]
    port.add_connection(connection)
    writer = subprocess.Popen([sys.executable, "-c", FRAME_WRITER, pickle.dumps(spec).hex(), "20000"])
    reads = 0
    try:
        while writer.poll() is None and reads < 400:
            status, slot = port.read_newest()
            if status is NEW_DATA:
                slot.release()
                reads += 1
            elif SlotState.READING in connection.pool.states():
                break  # leaked: the writer may be stuck for want of slots
    finally:
        writer.kill()
        writer.wait()
    states = connection.pool.states()
    assert SlotState.READING not in states, f"slots leaked after {reads} reads: {states}"
    assert connection.counters()["dropped"] == connection.written - connection.read - connection.pending
    assert isinstance(connection, PoolReader)
    connection.pool.unlink_slots()  # type: ignore[attr-defined]


def test_read_newest_on_pooled_inputs_keeps_every_slot_usable(tmp_path: Path) -> None:
    case = Case("POOL", 1, "frame", 8192, 300, 20, "p0",
                [ReaderCase("read_newest", True, ""), ReaderCase("read_newest", False, "p1")], period=0.5)
    apps.check(case, tmp_path)


# --- 4. the declared slot count -------------------------------------------------------------------

def test_a_pooled_output_keeps_its_declared_slots_in_other_processes(tmp_path: Path) -> None:
    """slots=8 and a reader that holds 4 frames: no stall in one process, none across processes
    (before: 4 slots across processes, and the writer stalled almost every cycle)."""
    case = Case("POOL", 1, "frame", 64, 100, 1, "", [ReaderCase("read", False, "p0", hold=4)], source="FrameSource8")
    alone, spread = apps.check(case, tmp_path)
    for result in (alone, spread):
        assert result.pool["slots"] == "8", result.pool
        assert result.pool["row"].split()[-3:] == ["8", "100", "0"], result.pool  # slots, published, stalls


# --- 5. event inputs made in init() ---------------------------------------------------------------

@pytest.mark.parametrize("writer, reader", [("p0", ""), ("", "p0")], ids=["child_to_launcher", "launcher_to_child"])
def test_an_event_input_made_in_init_is_woken_from_another_process(tmp_path: Path, writer: str, reader: str) -> None:
    case = Case("BUFFER", 200, "int", 0, 200, 5, writer, [ReaderCase("read_all", True, reader, component="LateReader")])
    alone, spread = apps.check(case, tmp_path)
    assert alone.got == spread.got == [list(range(200))]


# --- 6. numpy arrays of any dtype -----------------------------------------------------------------

DTYPE_SAMPLES = [
    np.zeros(3, [("a", "<i4"), ("b", "<f8")]),
    np.arange(5).astype("M8[ns]"),
    np.arange(4).astype("m8[s]").reshape(2, 2),
    np.asfortranarray(np.arange(6).astype("M8[D]").reshape(2, 3)),
    np.arange(6, dtype=">f8"),
    np.array(["ab", "cde"]),
    np.array([b"x", b"yz"]),
    np.array(np.datetime64("2026-01-01T12:00", "ms")),
    np.zeros(0, [("t", "M8[us]"), ("v", "f4", (2,))]),
    np.zeros(4, [("t", "M8[us]"), ("v", "f4", (2,))])[::2],
    np.arange(10, dtype=np.float32).reshape(2, 5),
    np.array([True, False]),
]


def test_arrays_of_every_dtype_arrive_equal(arena: Arena) -> None:
    """Structured, datetime, timedelta, byte-swapped, text, 0-d, empty and strided arrays arrive
    with their dtype, shape and values (before: a structured array lost its fields, datetime64 could
    not be sent)."""
    spec = arena.channel(ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 32), "w.out->r.in")
    writer, reader = ShmWriter(spec), ShmReader(spec)
    for sample in DTYPE_SAMPLES:
        writer.push(sample)
    for sample in DTYPE_SAMPLES:
        got = reader.pop()
        assert got.dtype == sample.dtype and got.shape == sample.shape, (sample.dtype, got.dtype)
        np.testing.assert_array_equal(got, sample)
        assert got.flags.writeable, "the reader owns its copy"


def test_structured_and_datetime_arrays_cross_as_in_one_process(tmp_path: Path) -> None:
    case = Case("BUFFER", 100, "records", 6000, 100, 5, "", [ReaderCase("read_all", True, "p0")])
    alone, spread = apps.check(case, tmp_path)
    assert alone.bad == spread.bad == [0]


# --- 7. /dev/shm holds what is pending, no more ---------------------------------------------------

def _value_segments(arena: Arena) -> list[str]:
    return [name for name in leftovers(arena.launch) if ".v" in name]


def _bytes(arena: Arena) -> int:
    return sum(os.stat(f"/dev/shm/{name}").st_blocks * 512 for name in leftovers(arena.launch))


@pytest.mark.parametrize("data, size, most", [
    (BufferPolicy.BUFFER, 1000, 0), (BufferPolicy.CIRCULAR, 4, 4), (BufferPolicy.DATA, 1, 2)])
def test_large_values_use_dev_shm_only_while_pending(arena: Arena, data: BufferPolicy, size: int, most: int) -> None:
    """Values of 1 to 3 MiB: a reader that keeps up leaves /dev/shm as the ring and two spare
    segments (the last values read, kept for their pages); values nobody read stay only while the
    ring holds them (before: each slot kept a segment of the largest value it ever held, so a
    BUFFER of 1000 could reach 1000 x the largest value)."""
    spec = arena.channel(ConnectionPolicy(data, SyncPolicy.LOCKED, size), "w.out->r.in")
    writer, reader = ShmWriter(spec), ShmReader(spec)
    ring = sum(os.stat(f"/dev/shm/{name}").st_size for name in leftovers(arena.launch))
    largest = 3 * 2**20 + 4096
    for number in range(12):
        writer.push(np.full((number % 3 + 1) * 2**17, number, np.int64))
        if data is BufferPolicy.BUFFER:
            value = reader.pop()
            assert int(value[0]) == number
            assert _value_segments(arena) == [], "a value read is no longer pending"
            assert _bytes(arena) <= ring + 2 * largest, "the ring and two spares"
    assert len(_value_segments(arena)) == most, "only what is pending"
    while reader.pop() is not EMPTY:  # what is left
        pass
    assert _value_segments(arena) == [] and _bytes(arena) <= ring + 2 * largest


FULL = """
import pickle, resource, sys
import numpy as np
from coco_core.shm import ChannelError, ShmReader, ShmWriter
spec = pickle.loads(bytes.fromhex(sys.argv[1]))
writer = ShmWriter(spec)
writer.push(np.zeros(1000))                      # fits: 8 kB
resource.setrlimit(resource.RLIMIT_FSIZE, (2**20, 2**20))   # files of this process: 1 MiB at most
try:
    writer.push(np.zeros(2**18))                 # 2 MiB: cannot be stored
except ChannelError as error:
    print("error:", error)
    kept = error                                 # held (a traceback kept for a report): the writer goes on
writer.push(np.ones(1000))
reader = ShmReader(spec)
print("read:", float(reader.pop().sum()), float(reader.pop().sum()), reader.counters())
"""


def test_a_value_that_cannot_fit_is_a_clear_error_and_counts_as_dropped(arena: Arena) -> None:
    """When the kernel refuses the bytes of a large value (here a file-size limit stands in for a
    full /dev/shm), the write raises a ChannelError that says so, nothing of the value is left, and
    it counts as dropped; the values around it arrive."""
    spec = arena.channel(ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 8), "cam.out->view.in")
    done = subprocess.run([sys.executable, "-c", FULL, pickle.dumps(spec).hex()], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    error, read = done.stdout.splitlines()
    assert "connection cam.out->view.in: a value of 2.0 MiB does not fit in /dev/shm" in error, error
    assert "it was dropped" in error and "File too large" in error, error
    assert read == "read: 0.0 1000.0 {'written': 3, 'read': 2, 'dropped': 1, 'pending': 0}", read
    assert _value_segments(arena) == []


def test_large_values_leave_dev_shm_as_the_ring_once_read(tmp_path: Path) -> None:
    case = Case("BUFFER", 1000, "array", 2 * 2**20, 40, 1, "p0", [ReaderCase("read_all", True, "", watch=True)])
    alone, spread = apps.check(case, tmp_path)
    ring, spares = 64 + 1000 * (32 + 4096), 2 * (2 * 2**20 + 8192)
    assert spread.shm[0] <= ring + spares, f"{spread.shm[0]} bytes in /dev/shm once all was read"


# --- 8. a killed reader's figures stay in the profile ---------------------------------------------

def test_the_connections_of_a_killed_child_stay_in_the_final_profile(tmp_path: Path) -> None:
    """A child that reads a value channel and a frame channel is killed (SIGKILL) once it read
    everything: the launcher reports its death, and the final profile still has that child's rows,
    with the figures of the one-process run."""
    for policy, kind, size in (("BUFFER", "int", 0), ("POOL", "frame", 64)):
        case = Case(policy, 100, kind, size, 100, 5, "", [ReaderCase("read_all", True, "p0")])
        alone = apps.run(case, tmp_path / f"{policy}-alone", processes=False)
        case.readers[0].die = True
        spread = apps.run(case, tmp_path / f"{policy}-spread", processes=True)
        assert spread.returncode == 1 and "process p0" in spread.output and "SIGKILL" in spread.output
        label = f"src.{'frames' if policy == 'POOL' else 'out'} -> r0.value"
        assert label in spread.rows, spread.output
        assert spread.rows[label] == alone.rows[label] if policy == "BUFFER" else spread.rows[label][0] == 100
        assert spread.rows[label][1] == len(spread.got[0]) and spread.leftovers == []


# --- generated applications -----------------------------------------------------------------------

@pytest.mark.parametrize("seed", [0, 2, 3, 4, 5, 13])
def test_generated_applications_behave_as_in_one_process(tmp_path: Path, seed: int) -> None:
    """Policy, sizes, read modes, reader count and placement drawn from ``seed``."""
    apps.check(apps.generate(seed, count=150), tmp_path)
