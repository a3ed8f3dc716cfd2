"""The rings' locked path (coco_core.shm.ordering): chosen on CPUs that may reorder stores (aarch64:
a Jetson), forced anywhere with COCO_SHM_LOCKED=1, and run here, on x86-64, with the key cases of
the channels between processes. Its ends must really wait for each other: a process that holds a
ring's lock stops the other process's writer and reader (seen in /proc/locks), which the unlocked
path does not."""

from __future__ import annotations

import os
import pickle
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Iterator

import pytest

from coco_core.errors import ConfigError
from coco_core.policy import BufferPolicy, ConnectionPolicy, SyncPolicy
from coco_core.shm import FORCE_LOCKED, Arena, ChannelSpec, ShmReader, ShmWriter, leftovers, rings_locked
from coco_core.shm.channel import HEADER, READ, STORED
from coco_core.shm.segment import Segment, SegmentLock

sys.path.insert(0, str(Path(__file__).parent / "data"))
import channel_apps as apps  # noqa: E402  (the folder the launcher's processes import components from)
from channel_apps import Case, ReaderCase  # noqa: E402

WAIT = 20.0
"""Seconds a condition may take on a loaded machine before the test fails."""


def arena_in(monkeypatch: pytest.MonkeyPatch, forced: str | None) -> Iterator[Arena]:
    if forced is None:
        monkeypatch.delenv(FORCE_LOCKED, raising=False)
    else:
        monkeypatch.setenv(FORCE_LOCKED, forced)
    launch = f"test{os.getpid()}x{os.urandom(3).hex()}"
    made = Arena(launch)
    yield made
    made.close()
    assert leftovers(launch) == [], "the arena unlinks every segment"


@pytest.fixture
def locked_arena(monkeypatch: pytest.MonkeyPatch) -> Iterator[Arena]:
    yield from arena_in(monkeypatch, "1")


@pytest.fixture
def default_arena(monkeypatch: pytest.MonkeyPatch) -> Iterator[Arena]:
    yield from arena_in(monkeypatch, None)


def test_the_path_is_chosen_by_the_cpu_and_forced_by_the_environment() -> None:
    for cpu in ("aarch64", "arm64", "armv7l", "ppc64le", "riscv64"):
        assert rings_locked(cpu, {}), cpu
    for cpu in ("x86_64", "AMD64", "i686"):
        assert not rings_locked(cpu, {}), cpu
        assert not rings_locked(cpu, {FORCE_LOCKED: "0"}), cpu
        assert rings_locked(cpu, {FORCE_LOCKED: "1"}), cpu
    assert rings_locked("aarch64", {FORCE_LOCKED: "0"}), "0 leaves the choice to the CPU: never unlocked on ARM"
    with pytest.raises(ConfigError, match=r"COCO_SHM_LOCKED='yes': expected 1 .*or 0 or nothing"):
        rings_locked("x86_64", {FORCE_LOCKED: "yes"})


def test_the_launch_decides_for_every_process_of_it(locked_arena: Arena) -> None:
    """The choice travels in the channel's description, so the children follow the launcher."""
    spec = locked_arena.channel(ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 4), "a.out->b.in")
    assert spec.locked and pickle.loads(pickle.dumps(spec)).locked
    writer, reader = ShmWriter(spec), ShmReader(spec)
    assert writer.ring.lock is not None and reader.ring.lock is not None
    writer.close()
    reader.close()


WRITER = """
import pickle, sys
from coco_core.shm import ShmWriter
writer = ShmWriter(pickle.loads(bytes.fromhex(sys.argv[1])))
print("ready", flush=True)
writer.push(42)
print("pushed", flush=True)
"""

READER = """
import pickle, sys
from coco_core.shm import ShmReader
reader = ShmReader(pickle.loads(bytes.fromhex(sys.argv[1])))
print("ready", flush=True)
print("read", reader.pop(), flush=True)
"""


def _waiting_for_flock(pid: int, segment: Segment) -> bool:
    """Whether process ``pid`` waits for a ``flock`` on ``segment`` (a ``->`` line of /proc/locks)."""
    inode = os.fstat(segment.fd).st_ino
    for line in Path("/proc/locks").read_text().splitlines():
        fields = line.split()
        if len(fields) > 6 and fields[1] == "->" and fields[2] == "FLOCK" and int(fields[5]) == pid \
                and int(fields[6].rsplit(":", 1)[1]) == inode:
            return True
    return False


def _hold_while(spec: ChannelSpec, script: str) -> tuple[subprocess.Popen[str], Segment, tuple[int, int]]:
    """Start ``script`` on ``spec`` while this process holds the ring's lock, and wait until the
    script's process waits for it; then the ring's ``stored`` and ``read`` counters as they were
    then (the lock is released on return)."""
    segment = Segment(spec.segment)
    lock = SegmentLock(segment)
    with lock:
        process = subprocess.Popen([sys.executable, "-c", script, pickle.dumps(spec).hex()], stdout=subprocess.PIPE,
                                   text=True)
        assert process.stdout is not None and process.stdout.readline().strip() == "ready"
        deadline = time.monotonic() + WAIT
        while not _waiting_for_flock(process.pid, segment):
            assert process.poll() is None, "the other end went on without the lock"
            assert time.monotonic() < deadline, "the other end never waited for the lock"
            os.sched_yield()
        counters = segment.view[:HEADER].cast("q")
        seen = int(counters[STORED]), int(counters[READ])
        counters.release()
    return process, segment, seen


@pytest.mark.skipif(not Path("/proc/locks").exists(), reason="needs /proc/locks to see a process wait")
def test_a_writer_waits_for_the_lock_of_a_locked_ring(locked_arena: Arena) -> None:
    spec = locked_arena.channel(ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 4), "a.out->b.in")
    process, segment, (stored, _) = _hold_while(spec, WRITER)
    try:
        assert stored == 0, "the value was stored while another process held the lock"
        assert process.communicate(timeout=WAIT)[0].strip() == "pushed"
        reader = ShmReader(spec)
        assert reader.pop() == 42
        reader.close()
    finally:
        process.kill()
        process.wait()
        segment.close()


@pytest.mark.skipif(not Path("/proc/locks").exists(), reason="needs /proc/locks to see a process wait")
def test_a_reader_waits_for_the_lock_of_a_locked_ring(locked_arena: Arena) -> None:
    spec = locked_arena.channel(ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 4), "a.out->b.in")
    writer = ShmWriter(spec)
    writer.push(42)
    process, segment, (_, read) = _hold_while(spec, READER)
    try:
        assert read == 0, "the value was read while another process held the lock"
        assert process.communicate(timeout=WAIT)[0].strip() == "read 42"
        assert writer.read == 1
    finally:
        writer.close()
        process.kill()
        process.wait()
        segment.close()


@pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"), reason="the unlocked path is x86's")
def test_on_x86_the_rings_take_the_unlocked_path(default_arena: Arena) -> None:
    """The fast path stays x86-64's default: a writer does not wait for the segment's lock."""
    spec = default_arena.channel(ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 4), "a.out->b.in")
    assert not spec.locked
    segment = Segment(spec.segment)
    try:
        with SegmentLock(segment):
            done = subprocess.run([sys.executable, "-c", WRITER, pickle.dumps(spec).hex()], capture_output=True,
                                  text=True, timeout=WAIT)
        assert done.stdout.split() == ["ready", "pushed"], done.stderr
    finally:
        segment.close()


# --- the channels between processes, on the locked path ------------------------------------------

LOCKED_CASES = {
    "data": Case("DATA", 1, "array", 6000, 150, 5, "p0", [ReaderCase("read", False, ""),
                                                         ReaderCase("read_newest", True, "p1")]),
    "buffer": Case("BUFFER", 200, "records", 6000, 200, 5, "", [ReaderCase("read_all", True, "p0")]),
    "buffer_full": Case("BUFFER", 4, "int", 0, 200, 20, "p0", [ReaderCase("read", False, "")]),
    "circular_large": Case("CIRCULAR", 16, "array", 300_000, 60, 5, "p0", [ReaderCase("read_all", True, "p1")]),
    "pooled_frames": Case("POOL", 1, "frame", 8192, 150, 5, "p0", [ReaderCase("read_all", True, ""),
                                                                  ReaderCase("read", False, "p0"),
                                                                  ReaderCase("read_newest", True, "p1")]),
}


@pytest.mark.parametrize("name", LOCKED_CASES)
def test_channels_between_processes_on_the_locked_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                       name: str) -> None:
    """Each case runs with coco-launch in one process and over processes (the rings locked, as on
    aarch64): the same values in order where lossless, counters that add up (written = read +
    dropped + pending), no OLD_DATA of a pooled input, every slot back, nothing left in /dev/shm."""
    monkeypatch.setenv(FORCE_LOCKED, "1")
    case = LOCKED_CASES[name]
    alone, spread = apps.check(case, tmp_path)
    if name == "buffer":
        assert spread.got == [list(range(case.count))]
    if name == "buffer_full":
        assert spread.rows["src.out -> r0.value"][2] > 0, "a full BUFFER's refusals count as dropped"
    if name == "pooled_frames":
        assert spread.old == [0, 0, 0], "a pooled input gives NO_DATA, not a released slot, when nothing is new"
