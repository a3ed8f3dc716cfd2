"""Pooled frames carry FlowVR's whole stamp list, as plain values do: user stamps written with a
frame reach its readers (in one process, from shared memory in another process, from a real
launch), a stamps-only connection from a pooled output gives its reader the frames' stamps without
holding a slot (routed by a ``Cull`` too), and a frame whose ``Slot.stamp`` is an acquisition stamp
is timed from it (``port.stamp``'s time, ``port.origin``). Waiting is on conditions (or on the
launcher's exit), never on a fixed time."""

from __future__ import annotations

import json
import os
import pickle
import re
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from coco_core import (
    BufferPolicy,
    CocoError,
    Component,
    ConnectionPolicy,
    InputPort,
    PooledOutputPort,
    Slot,
    SlotState,
    SyncPolicy,
    WiringError,
)
from coco_core.demo.routing import box_of
from coco_core.filters import Cull
from coco_core.policy import NEW_DATA
from coco_core.shm import Arena, ShmFramePool
from coco_core.stamps import Stamp, Stamped
from coco_core.xml import parse_application_string

DATA = Path(__file__).parent / "data"
BUFFERED = ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 100)
POOLED = ConnectionPolicy(BufferPolicy.POOL)
TIMEOUT = 90.0
"""Seconds a launch may take on a loaded machine (two processes start, fifty frames)."""


@pytest.fixture
def arena():
    """The segments of one test's pools, unlinked at the end (a frame pool changes state under its
    lock on every CPU: no path to choose, unlike a ring)."""
    made = Arena(f"pooledstamps{os.getpid()}x{os.urandom(3).hex()}")
    yield made
    made.close()


class Camera(Component):
    frames = PooledOutputPort(slots=3)


class Viewer(Component):
    frames = InputPort(Slot)


class Monitor(Component):
    stamps = InputPort(Stamp)


def publish(port: PooledOutputPort, number: int, own: object = None, **stamps: object) -> Slot:
    """Frame ``number`` (its pixels say it) written on ``port`` with ``own`` as its ``Slot.stamp``."""
    slot = port.acquire((2, 2), np.int64)
    assert slot is not None, port.pool.states()
    slot.array[:] = number
    slot.stamp = own
    port.write(slot, stamps=stamps or None)
    return slot


def take(port: InputPort) -> tuple[int, Stamp, Stamp]:
    """The new frame on ``port``: its number, ``port.stamp`` and ``port.origin``; released."""
    status, slot = port.read()
    assert status is NEW_DATA, status
    with slot:
        stamp, origin = port.stamp, port.origin
        assert stamp is not None and origin is not None
        return int(slot.array[0, 0]), stamp, origin


# --- user stamps ----------------------------------------------------------------------------------

def test_user_stamps_written_with_a_pooled_frame_reach_every_reader(make_app):
    app = make_app()
    camera, near, far = app.add(Camera("camera")), app.add(Viewer("near")), app.add(Viewer("far"))
    for viewer in (near, far):
        app.connect(camera.frames, viewer.frames, POOLED)
    box = {"bbox": (0.0, 0.0, 1.0, 1.0), "camera": 2}
    publish(camera.frames, 1, **box)
    box["camera"] = 7  # the writer's dict changing later changes no frame written
    for viewer in (near, far):
        number, stamp, _ = take(viewer.frames)
        assert (number, stamp.seq, stamp.source) == (1, 1, "camera.frames")
        assert dict(stamp.user) == {"bbox": (0.0, 0.0, 1.0, 1.0), "camera": 2}, viewer.name
    assert camera.frames.stamp is not None and dict(camera.frames.stamp.user)["camera"] == 2
    publish(camera.frames, 2)
    assert dict(take(near.frames)[1].user) == {}, "a frame without user stamps has none"


def pool_pair(arena: Arena, slots: int = 3) -> tuple[Camera, ShmFramePool]:
    """A camera whose pooled output uses a pool in shared memory (as its process does when a
    reader runs in another), and the pool's description for that reader."""
    spec = arena.channel(ConnectionPolicy(BufferPolicy.POOL, SyncPolicy.LOCKED, slots), "camera.frames->far.frames",
                         frames=True, readers=1)
    camera = Camera("camera")
    pool = ShmFramePool(spec)
    camera.frames.use_pool(pool)
    return camera, pool


FAR_READER = """
import json, sys, pickle, time
from coco_core import InputPort, Slot
from coco_core.policy import NEW_DATA
from coco_core.shm import ShmPoolReader
spec = pickle.loads(bytes.fromhex(sys.argv[1]))
port = InputPort(Slot).bind(None, "frames")
port.add_connection(ShmPoolReader(spec))
deadline = time.monotonic() + 30
got = []
while len(got) < int(sys.argv[2]):
    status, slot = port.read()
    if status is NEW_DATA:
        with slot:
            stamp, origin = port.stamp, port.origin
            got.append({"value": int(slot.array[0, 0]), "seq": stamp.seq, "source": stamp.source,
                        "user": dict(stamp.user), "time": stamp.time, "steps": stamp.steps,
                        "origin": [origin.time, origin.seq, origin.source, origin.steps]})
        print(json.dumps(got[-1]), flush=True)
    elif time.monotonic() > deadline:
        sys.exit("no frame")
    else:
        time.sleep(0.001)
"""


def test_user_stamps_and_the_frames_own_stamp_cross_to_a_reader_in_another_process(arena: Arena):
    """In the slot's record: the reader process reads them beside the frame it maps, the frame is
    not copied; the frame's own acquisition stamp times it there as here."""
    camera, pool = pool_pair(arena)
    spec = pool.spec
    reader = subprocess.Popen([sys.executable, "-c", FAR_READER, pickle.dumps(spec).hex(), "3"],
                              stdout=subprocess.PIPE, text=True)
    try:
        acquired = Stamp(5.0, 41, "sensor").step("exposed", 5.25)
        lines = []
        for number, own, stamps in ((1, acquired, {"bbox": (0.0, 0.0, 1.0, 1.0), "part": 3}),
                                    (2, 7, {}),
                                    (3, None, {"bbox": (2.0, 2.0, 3.0, 3.0)})):
            publish(camera.frames, number, own, **stamps)
            lines.append(json.loads(reader.stdout.readline()))  # type: ignore[union-attr]
        assert reader.wait(timeout=30) == 0
    finally:
        if reader.poll() is None:
            reader.kill()
        camera.frames.pool.unlink_slots()  # type: ignore[attr-defined]
        pool.close()
    first, second, third = lines
    assert (first["value"], first["seq"], first["source"]) == (1, 1, "camera.frames")
    assert first["user"] == {"bbox": [0.0, 0.0, 1.0, 1.0], "part": 3}
    assert (first["time"], first["steps"]) == (5.0, [["exposed", 5.25]]), "timed from its acquisition"
    assert first["origin"] == [5.0, 41, "sensor", [["exposed", 5.25]]]
    assert second["user"] == {} and second["origin"][1:3] == [2, "camera.frames"], "a count is no acquisition stamp"
    assert second["time"] != 5.0
    assert third["user"] == {"bbox": [2.0, 2.0, 3.0, 3.0]} and third["origin"][1:3] == [3, "camera.frames"]


def test_user_stamps_too_large_for_a_frames_record_are_refused_with_the_limit(arena: Arena):
    camera, pool = pool_pair(arena)
    try:
        slot = camera.frames.acquire((2, 2), np.int64)
        assert slot is not None
        with pytest.raises(CocoError, match=r"camera.frames->far.frames: a frame's user stamps of \d+ bytes "
                                            r"pickled are larger than 504"):
            camera.frames.write(slot, stamps={"points": tuple(float(i) for i in range(100))})
        assert pool.published == 0
    finally:
        camera.frames.pool.unlink_slots()  # type: ignore[attr-defined]
        pool.close()


# --- a frame's own acquisition stamp --------------------------------------------------------------

@dataclass(frozen=True)
class Layout:
    """A frame's metadata with a stamp of its own, as a mesh's MeshInfo."""

    rows: int
    stamp: Stamp | None


@pytest.mark.parametrize("own, expected", [
    (Stamp(2.5, 9, "sensor", (("exposed", 2.75),)), Stamp(2.5, 9, "sensor", (("exposed", 2.75),))),
    (Stamped("frame", Stamp(3.5, 4, "sensor")), Stamp(3.5, 4, "sensor")),
    (Layout(480, Stamp(4.5, 5, "depth")), Stamp(4.5, 5, "depth")),
    (Layout(480, None), None),
    (12, None),
])
def test_a_pooled_frames_origin_is_its_own_acquisition_stamp(make_app, own: object, expected: Stamp | None):
    """``port.origin`` is the frame's own stamp, as a ``Stamped`` value's; ``port.stamp`` keeps the
    write's number, source and iteration with the acquisition's time and steps. A ``Slot.stamp``
    without one times the frame from its write, as before."""
    app = make_app()
    camera, viewer = app.add(Camera("camera")), app.add(Viewer("viewer"))
    app.connect(camera.frames, viewer.frames, POOLED)
    before = time.perf_counter()
    publish(camera.frames, 1, own)
    _, stamp, origin = take(viewer.frames)
    assert (stamp.seq, stamp.source) == (1, "camera.frames")
    assert stamp == camera.frames.stamp, "the writer's stamp of the write is the readers'"
    if expected is None:
        assert origin == stamp and stamp.time >= before and stamp.steps == ()
    else:
        assert origin == expected
        assert (stamp.time, stamp.steps) == (expected.time, expected.steps)


# --- stamps-only connections from a pooled output -------------------------------------------------

def test_a_stamps_only_connection_from_a_pooled_output_gives_the_stamps_and_holds_no_slot(make_app):
    """The monitor never reads during the writes, yet the writer never stalls: its connection holds
    stamps, not slots; every stamp comes with its user stamps, the counters add up."""
    app = make_app()
    camera, viewer, monitor = app.add(Camera("camera")), app.add(Viewer("viewer")), app.add(Monitor("monitor"))
    app.connect(camera.frames, viewer.frames, POOLED)
    only = app.connect(camera.frames, monitor.stamps, BUFFERED, stamps_only=True)
    acquired = Stamp(1.5, 77, "sensor")
    for number in range(10):
        publish(camera.frames, number, acquired if number == 9 else None, bbox=box_of(number, 10, 1.0), part=number)
    assert camera.frames.pool.stalls == 0
    assert SlotState.READING not in camera.frames.pool.states()
    assert take(viewer.frames)[0] == 9
    got = []
    while (read := monitor.stamps.read())[0] is NEW_DATA:
        assert isinstance(read[1], Stamp) and read[1] == monitor.stamps.stamp
        got.append(read[1])
    assert [stamp.seq for stamp in got] == list(range(1, 11))
    assert [stamp.user["part"] for stamp in got] == list(range(10))
    assert all(stamp.source == "camera.frames" and stamp.user["bbox"] == box_of(stamp.seq - 1, 10, 1.0)
               for stamp in got)
    assert got[-1].time == 1.5, "the frame's own acquisition time, as its readers see it"
    assert only.describe() == "BUFFER/LOCKED[100], stamps only"
    assert only.counters() == {"written": 10, "read": 10, "dropped": 0, "pending": 0}
    assert SlotState.READING not in camera.frames.pool.states()


def test_a_cull_routes_the_stamps_of_pooled_frames_by_their_box(make_app):
    app = make_app()
    camera, left, right = app.add(Camera("camera")), app.add(Monitor("left")), app.add(Monitor("right"))
    culls = [app.connect(camera.frames, monitor.stamps, connection=Cull(BUFFERED, region), stamps_only=True)
             for monitor, region in ((left, (0.0, 0.0, 5.0, 1.0)), (right, (5.0, 0.0, 10.0, 1.0)))]
    for number in range(10):
        publish(camera.frames, number, bbox=box_of(number, 10, 1.0))
    assert [stamp.seq - 1 for stamp in left.stamps.read_all()] == [0, 1, 2, 3, 4, 5]
    assert [stamp.seq - 1 for stamp in right.stamps.read_all()] == [4, 5, 6, 7, 8, 9]
    assert [c.routed_away for c in culls] == [4, 4]
    assert camera.frames.pool.stalls == 0


def test_a_stamps_only_connection_from_a_pooled_output_carries_no_frames(make_app):
    app = make_app()
    camera, monitor = app.add(Camera("camera")), app.add(Monitor("monitor"))
    with pytest.raises(WiringError, match="a stamps-only connection from camera.frames carries the messages' "
                                          "stamps, not frames: .* not POOL"):
        app.connect(camera.frames, monitor.stamps, POOLED, stamps_only=True)
    assert app.connections == []


# --- a launch: the source in a process of its own -------------------------------------------------

APP = """<package name="pooled_stamps">
    <components>
        <component><name>camera</name><task>pooled_stamp_components:BoxFrameSource</task>
            <attributes><attribute name="stop_after" value="{frames}"/></attributes></component>
        <component><name>viewer</name><task>pooled_stamp_components:FrameRecorder</task>
            <attributes><attribute name="out_dir" value="{out}"/></attributes></component>
        <component><name>monitor</name><task>StampRecorder</task><library>coco_core</library>
            <attributes><attribute name="out_dir" value="{out}"/></attributes></component>
    </components>
    <connections>
        <connection data="POOL"><src task="camera" port="frames"/><dest task="viewer" port="frames"/></connection>
        <connection buffersize="256" stamps_only="true">
            <src task="camera" port="frames"/><dest task="monitor" port="item"/>
            <filter type="Cull" region="0 0 5 1"/>
        </connection>
    </connections>
    <activities>
        <process name="cam"><activity name="shoot"><schedule type="periodic" period="4"/>
            <components><component name="camera"/></components></activity></process>
        <activity name="view"><schedule type="triggered"/>
            <components><component name="viewer"/><component name="monitor"/></components></activity>
    </activities>
</package>"""


@pytest.mark.parametrize("apart", [True, False], ids=["camera in a process of its own", "one process"])
def test_pooled_frames_stamps_reach_a_frame_reader_and_a_culled_stamps_only_connection(tmp_path: Path, apart: bool):
    """The camera in process ``cam`` (or, the same file without its ``<process>``, in the
    launcher's): the viewer reads the frames (from shared memory) with their user stamps and their
    own acquisition stamps; the monitor's stamps-only connection, through a Cull on its side, gets
    the stamps of the frames whose box meets its region (from a ring, no slot held). A filter's
    reader does not wait for its writer at the stop, so the monitor may miss the last few: the
    checks hold for what it got up to its last message."""
    out = tmp_path / "out"
    out.mkdir()
    path = tmp_path / "app.xml"
    text = APP.format(frames=50, out=out)
    path.write_text(text if apart else re.sub(r'<process name="cam">(.*?)</process>', r"\1", text, flags=re.S))
    env = dict(os.environ, PYTHONPATH=f"{DATA}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    launched = subprocess.run([sys.executable, "-m", "coco_core.launcher", str(path), "--profile", "600"],
                              capture_output=True, text=True, timeout=TIMEOUT, env=env)
    assert launched.returncode == 0, launched.stdout + launched.stderr
    viewer = json.loads((out / "viewer.json").read_text())
    assert viewer, "the viewer got frames"
    for entry in viewer:
        number = entry["value"]
        assert (entry["seq"], entry["source"]) == (number + 1, "camera.frames"), entry
        assert entry["user"] == {"bbox": list(box_of(number, 10, 1.0)), "part": number}, entry
        assert entry["timed_from_acquisition"] and entry["origin_is_own"] and entry["origin"] == [number, "sensor"]
    monitor = json.loads((out / "monitor.json").read_text())
    seqs = [entry["seq"] for entry in monitor]
    assert seqs, "the monitor got stamps"
    assert seqs == [seq for seq in range(1, seqs[-1] + 1) if (seq - 1) % 10 <= 5]
    assert all(entry["stamps_only"] and entry["user"]["part"] == entry["seq"] - 1 for entry in monitor)
    rows = {cells[-7]: cells for line in launched.stdout.splitlines()  # [process,] connection, policy, 4 counters, age
            if len(cells := re.split(r"\s{2,}", line.strip())) in (7, 8) and " -> " in cells[-7]}
    culled = rows["camera.frames -> monitor.item"]
    assert culled[-6].startswith("Cull(bbox meets 0 0 5 1), routed away ")
    assert culled[:-7] == (["launcher"] if apart else []), "the reader's process reports the connection"
    written, read, dropped, pending = map(int, culled[-5:-1])
    assert written == read + dropped + pending and read == len(monitor)


def test_a_stamps_only_connection_between_processes_from_a_pooled_output_carries_no_frames():
    """data=POOL on it is refused at planning, with file:line."""
    from coco_core.errors import ConfigError
    from coco_core.deployment import plan_deployment
    from coco_core.processes.channels import plan_channels

    text = APP.format(frames=1, out="").replace('buffersize="256"', 'data="POOL"')
    text = re.sub(r'\s*<filter type="Cull"[^>]*/>', "", text)
    sys.path.insert(0, str(DATA))
    arena = Arena(f"poolstamps{time.monotonic_ns()}")
    try:
        spec = parse_application_string(text, filename="app.xml")
        with pytest.raises(ConfigError, match="a stamps-only connection from camera.frames carries the messages' "
                                              "stamps, not frames") as raised:
            plan_channels(arena, plan_deployment(spec).host())
        assert str(raised.value).startswith("app.xml:12:"), str(raised.value)  # the <connection>
    finally:
        sys.path.remove(str(DATA))
        arena.close()
