"""FlowVR's user stamps, stamps-only connections and routing filters (Split, Cull), in one process,
from the XML and between processes: each receiver gets exactly the messages its filter routes to
it, with their user stamps, what a filter routes away is counted, and wrong parameters get
file:line errors. Waiting is on conditions (or on the launcher's exit), never on a fixed time."""

from __future__ import annotations

import collections
import itertools
import json
import math
import os
import re
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from coco_core import (
    BufferPolicy,
    Component,
    ConnectionPolicy,
    InputPort,
    OutputPort,
    SyncPolicy,
    WiringError,
)
from coco_core.builder import build_application
from coco_core.dataflow_graph import dataflow_dot
from coco_core.deployment import plan_deployment
from coco_core.demo.routing import box_of
from coco_core.errors import ConfigErrors
from coco_core.filters import Cull, Split
from coco_core.frustum import Frustum
from coco_core.policy import NEW_DATA
from coco_core.shm import Arena, ShmReader, ShmWriter
from coco_core.stamps import Stamp
from coco_core.wakeup import Wakeup
from coco_core.xml import load_application, parse_application_string

CONFIG = Path(__file__).resolve().parents[2] / "config"
BUFFERED = ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 100)
TIMEOUT = 90.0
"""Seconds a launch may take on a loaded machine (two processes start, a hundred values)."""


class Writer(Component):
    out = OutputPort(object)


class Reader(Component):
    item = InputPort(object)


class IntReader(Component):
    item = InputPort(int)


def read_all(port: InputPort) -> list[tuple[object, Stamp]]:
    got = []
    while (read := port.read())[0] is NEW_DATA:
        stamp = port.stamp
        assert stamp is not None
        got.append((read[1], stamp))
    return got


# --- user stamps ----------------------------------------------------------------------------------

def test_user_stamps_reach_the_reader_with_the_message_and_stay_as_written(make_app):
    app = make_app()
    writer, reader = app.add(Writer("writer")), app.add(Reader("reader"))
    app.connect("writer.out", "reader.item", BUFFERED)
    box = {"bbox": (0.0, 1.0, 2.0, 3.0), "camera": 2}
    writer.out.write("mesh", stamps=box)
    box["camera"] = 7  # the writer's dict changing later changes no message written
    writer.out.write("plain")
    [(value, stamp), (plain, plain_stamp)] = read_all(reader.item)
    assert (value, dict(stamp.user), stamp.seq, stamp.source) == ("mesh", {"bbox": (0.0, 1.0, 2.0, 3.0), "camera": 2},
                                                                   1, "writer.out")
    assert plain == "plain" and dict(plain_stamp.user) == {}
    assert writer.out.stamp is not None and writer.out.stamp.seq == 2
    with pytest.raises(TypeError):
        stamp.user["camera"] = 3  # type: ignore[index]  # read-only: the message is shared by its readers


def test_a_user_stamp_needs_a_name():
    writer = Writer("writer")
    port = Writer.out.bind(writer, "out")
    with pytest.raises(TypeError, match="a user stamp's name is a non-empty string, got 3"):
        port.write(1, stamps={3: "x"})  # type: ignore[dict-item]


def test_user_stamps_cross_to_another_process_in_the_payload(make_app):
    """The ring's fixed stamp words are unchanged: the user stamps travel pickled with the value."""
    arena = Arena(f"userstamps{os.getpid()}x{os.urandom(3).hex()}")
    try:
        spec = arena.channel(BUFFERED, "writer.out->reader.item")
        writer = Writer("writer")
        port = Writer.out.bind(writer, "out")
        port.add_connection(ShmWriter(spec))
        reader = Reader("reader")
        into = Reader.item.bind(reader, "item")
        into.add_connection(ShmReader(spec))
        port.write([1, 2], stamps={"bbox": (0, 0, 1, 1)})
        port.write(3)
        [(value, stamp), (plain, plain_stamp)] = read_all(into)
        assert value == [1, 2] and dict(stamp.user) == {"bbox": (0, 0, 1, 1)}
        assert (stamp.seq, stamp.source) == (1, "writer.out")
        assert plain == 3 and dict(plain_stamp.user) == {} and plain_stamp.seq == 2
    finally:
        arena.close()


# --- stamps-only connections ----------------------------------------------------------------------

def test_a_stamps_only_connection_gives_the_stamp_without_the_payload(make_app):
    app = make_app()
    writer, full, stamps = app.add(Writer("writer")), app.add(Reader("full")), app.add(Reader("stamps"))
    app.connect("writer.out", "full.item", BUFFERED)
    only = app.connect("writer.out", "stamps.item", BUFFERED, stamps_only=True)
    writer.out.write({"big": "payload"}, stamps={"bbox": (1, 2, 3, 4)})
    assert read_all(full.item)[0][0] == {"big": "payload"}
    [(value, stamp)] = read_all(stamps.item)
    assert isinstance(value, Stamp) and value == stamp  # the stamp is the value, and read beside it
    assert (stamp.seq, stamp.source, dict(stamp.user)) == (1, "writer.out", {"bbox": (1, 2, 3, 4)})
    assert only.describe() == "BUFFER/LOCKED[100], stamps only"
    assert only.counters() == {"written": 1, "read": 1, "dropped": 0, "pending": 0}


def test_a_filter_on_a_stamps_only_connection_says_both(make_app):
    """The profile and ``--check`` name the filter and that its connection carries stamps only."""
    from coco_core.filters import Greedy

    app = make_app()
    writer, newest = app.add(Writer("writer")), app.add(Reader("newest"))
    greedy = app.connect("writer.out", "newest.item", stamps_only=True, connection=Greedy(BUFFERED))
    for value in range(3):
        writer.out.write(value)
    [(value, stamp)] = read_all(newest.item)
    assert isinstance(value, Stamp) and stamp.seq == 3
    assert greedy.describe() == "Greedy, stamps only"


def test_a_stamps_only_connection_needs_a_port_that_takes_stamps(make_app):
    """(From a pooled output too: ``test_pooled_stamps.py``.)"""
    app = make_app()
    writer, ints = app.add(Writer("writer")), app.add(IntReader("ints"))
    with pytest.raises(WiringError, match=r"gives ints.item the messages' stamps .* that port takes int"):
        app.connect("writer.out", "ints.item", stamps_only=True)
    assert app.connections == []


def test_a_stamps_only_connection_to_another_process_does_not_carry_the_payload():
    """A payload that cannot be pickled would fail the channel: only its stamp crosses."""
    arena = Arena(f"stampsonly{os.getpid()}x{os.urandom(3).hex()}")
    try:
        spec = arena.channel(BUFFERED, "writer.out->reader.item")
        port = Writer.out.bind(Writer("writer"), "out")
        port.add_connection(ShmWriter(spec), stamps_only=True)
        into = Reader.item.bind(Reader("reader"), "item")
        into.add_connection(ShmReader(spec))
        port.write(threading.Lock(), stamps={"bbox": (0, 0, 1, 1)})  # no pickle of a lock
        [(value, stamp)] = read_all(into)
        assert isinstance(value, Stamp) and value == stamp
        assert (stamp.seq, stamp.source, dict(stamp.user)) == (1, "writer.out", {"bbox": (0, 0, 1, 1)})
    finally:
        arena.close()


# --- Split ----------------------------------------------------------------------------------------

def split_app(make_app, count: int, by: str = ""):
    app = make_app()
    writer = app.add(Writer("writer"))
    readers = [app.add(Reader(f"r{index}")) for index in range(count)]
    connections = [app.connect(writer.out, reader.item, connection=Split(BUFFERED, index, count, by))
                   for index, reader in enumerate(readers)]
    return writer, readers, connections


def test_split_in_turn_gives_each_message_to_one_output(make_app):
    writer, readers, connections = split_app(make_app, 3)
    for value in range(10):
        writer.out.write(value)
    got = [[value for value, _ in read_all(reader.item)] for reader in readers]
    assert got == [[0, 3, 6, 9], [1, 4, 7], [2, 5, 8]]
    assert [c.counters() for c in connections] == [{"written": n, "read": n, "dropped": 0, "pending": 0}
                                                    for n in (4, 3, 3)]
    assert [c.routed_away for c in connections] == [6, 7, 7]
    assert connections[0].describe() == "Split(out0 of 3, in turn), routed away 6"


def test_split_by_a_stamp_routes_by_its_value_and_counts_what_it_cannot_route(make_app):
    writer, readers, connections = split_app(make_app, 2, by="part")
    for value, part in ((0, 1), (1, 4), (2, 7), (3, 2)):
        writer.out.write(value, stamps={"part": part})
    writer.out.write(4)  # no part stamp: nobody's, dropped on each output
    writer.out.write(5, stamps={"part": "left"})  # not a whole number either
    assert [[v for v, _ in read_all(reader.item)] for reader in readers] == [[1, 3], [0, 2]]
    assert [c.counters()["dropped"] for c in connections] == [2, 2]
    assert [c.routed_away for c in connections] == [2, 2]


# --- Cull -----------------------------------------------------------------------------------------

def test_cull_forwards_the_messages_whose_box_meets_the_region(make_app):
    app = make_app()
    writer, left, right = app.add(Writer("writer")), app.add(Reader("left")), app.add(Reader("right"))
    culls = [app.connect(writer.out, reader.item, connection=Cull(BUFFERED, region))
             for reader, region in ((left, (0.0, 0.0, 5.0, 1.0)), (right, (5.0, 0.0, 10.0, 1.0)))]
    for count in range(10):
        writer.out.write(count, stamps={"bbox": box_of(count, 10, 1.0)})
    writer.out.write("unboxed")  # cannot be culled: every receiver gets it
    writer.out.write("flat", stamps={"bbox": (1, 2)})  # 1-d box against a 2-d region: dropped
    writer.out.write("far", stamps={"bbox": (20, 20, 21, 21)})  # meets nobody
    assert [v for v, _ in read_all(left.item)] == [0, 1, 2, 3, 4, 5, "unboxed"]
    assert [v for v, _ in read_all(right.item)] == [4, 5, 6, 7, 8, 9, "unboxed"]
    assert [(c.routed_away, c.counters()["dropped"]) for c in culls] == [(5, 1), (5, 1)]
    assert culls[0].describe() == "Cull(bbox meets 0 0 5 1), routed away 5"


def test_cull_refuses_a_region_that_is_not_one():
    with pytest.raises(Exception, match="2k finite numbers"):
        Cull(BUFFERED, (0.0, 1.0, 2.0))
    with pytest.raises(Exception, match="each minimum must be at most its maximum"):
        Cull(BUFFERED, (3.0, 0.0, 1.0, 1.0))


# --- Cull against a frustum -----------------------------------------------------------------------

SEEN = dict(position=(0.0, 0.0, 0.0), look_at=(1.0, 0.0, 0.0), up=(0.0, 0.0, 1.0), fov_y=90.0, aspect=2.0,
            near=0.1, far=10.0)
"""A camera at the origin looking along +x (z up): 90 degrees high, twice as wide (|z| <= x,
|y| <= 2 x), from x = 0.1 to x = 10."""


def seen(point) -> list[bool]:
    """Which of the frustum's six conditions ``point`` meets, from the camera's geometry (not from
    the matrix the filter uses): left, right, bottom, top, near, far."""
    x, y, z = point  # the camera's axes are the world's here: forward +x, right -y, up +z
    half = math.tan(math.radians(SEEN["fov_y"]) / 2) * x
    return [-y <= SEEN["aspect"] * half, y <= SEEN["aspect"] * half, -z <= half, z <= half,
            x >= SEEN["near"], x <= SEEN["far"]]


@pytest.mark.parametrize("box, kept", [
    ((4, -0.5, -0.5, 5, 0.5, 0.5), True),  # in front
    ((-5, -0.5, -0.5, -4, 0.5, 0.5), False),  # behind the camera
    ((11, -0.5, -0.5, 12, 0.5, 0.5), False),  # beyond far
    ((0.0, -0.01, -0.01, 0.05, 0.01, 0.01), False),  # before near
    ((4, 11, -0.5, 5, 12, 0.5), False),  # to the left (y > 2 x)
    ((4, -0.5, 6, 5, 0.5, 7), False),  # above (z > x)
    ((4, 9, -0.5, 5, 11, 0.5), True),  # across the left plane
    ((-20, -20, -20, 20, 20, 20), True),  # around the whole frustum: no corner inside, still seen
    ((9.9, -0.5, 10.5, 11, 0.5, 12), True),  # beside the far top edge: outside, but behind no one plane
])
def test_a_frustum_keeps_a_box_unless_it_is_wholly_outside_one_plane(box, kept):
    assert Frustum.of_camera(**SEEN).meets(box[:3], box[3:]) is kept
    corners = list(itertools.product(*zip(box[:3], box[3:])))
    if any(all(seen(corner)) for corner in corners):  # the expectation, from the camera's geometry
        assert kept
    if any(not any(seen(corner)[side] for corner in corners) for side in range(6)):
        assert not kept


def test_a_frustum_never_culls_a_box_it_meets_and_culls_each_box_wholly_behind_one_plane():
    """Random boxes against the camera's own geometry: a box with a corner or its centre inside is
    kept; a box whose eight corners all fail one same condition is culled."""
    frustum = Frustum.of_camera(**SEEN)
    random = np.random.default_rng(22)
    tried: collections.Counter[tuple[bool, bool]] = collections.Counter()
    for _ in range(2000):
        low = random.uniform((-2, -25, -12), (14, 25, 12))
        high = low + random.uniform(0, 3, 3)
        corners = [*itertools.product(*zip(low, high)), (low + high) / 2]
        meets = frustum.meets(low, high)
        inside = any(all(seen(corner)) for corner in corners)
        behind = any(not any(seen(corner)[side] for corner in corners[:8]) for side in range(6))
        assert meets if inside else True, (low, high)
        assert not meets if behind else True, (low, high)
        tried[inside, behind] += 1
    assert tried[True, False] > 100 and tried[False, True] > 100  # both kinds were drawn


def test_a_cull_with_a_frustum_routes_3d_boxes_and_drops_other_ones(make_app):
    app = make_app()
    writer, viewer = app.add(Writer("writer")), app.add(Reader("viewer"))
    cull = app.connect(writer.out, viewer.item, connection=Cull(BUFFERED, frustum=Frustum.of_camera(**SEEN)))
    writer.out.write("front", stamps={"bbox": (4, -0.5, -0.5, 5, 0.5, 0.5)})
    writer.out.write("behind", stamps={"bbox": (-5, -0.5, -0.5, -4, 0.5, 0.5)})
    writer.out.write("flat", stamps={"bbox": (4, -0.5, 5, 0.5)})  # a 2-d box: not against a frustum
    writer.out.write("unboxed")
    assert [value for value, _ in read_all(viewer.item)] == ["front", "unboxed"]
    assert cull.counters() == {"written": 3, "read": 2, "dropped": 1, "pending": 0}
    assert cull.describe() == ("Cull(bbox in frustum from 0 0 0 to 1 0 0, fov_y 90, aspect 2, near 0.1, far 10), "
                               "routed away 1")
    with pytest.raises(Exception, match="a region or a frustum, not both"):
        Cull(BUFFERED, (0.0, 1.0), frustum=Frustum.of_camera(**SEEN))


# --- the XML --------------------------------------------------------------------------------------

def test_the_routing_file_builds_its_filters_in_file_order_and_draws_them():
    spec = load_application(CONFIG / "stamp_routing.xml")
    app = build_application(spec)
    by_label = {c.label: c for c in app.connections}
    left, worker1 = by_label["emitter.out -> left.item"], by_label["emitter.out -> worker1.item"]
    assert isinstance(left, Cull) and (left.low, left.high) == ((0.0, 0.0), (5.0, 1.0))
    assert isinstance(worker1, Split) and (worker1.index, worker1.count, worker1.by) == (1, 2, "")
    assert by_label["emitter.out -> monitor.item"].describe().endswith("stamps only")
    dot = dataflow_dot(plan_deployment(spec))
    assert dot.count("shape=diamond") == 4
    assert '"Cull\\nbbox meets 0 0 5 1"' in dot and '"Split\\nin turn"' in dot
    assert re.search(r'"component:emitter" -> "component:monitor" \[label="[^"]*stamps only", style="dashed"\]', dot)


ROUTED = """<package name="routed">
    <components>
        <component><name>emitter</name><task>BoxEmitter</task><library>coco_core</library></component>
        <component><name>viewer</name><task>StampRecorder</task><library>coco_core</library></component>
    </components>
    <connections>
        <connection{attributes}>
            <src task="emitter" port="out"/>
            <dest task="viewer" port="item"/>
            {filter}
        </connection>
    </connections>
</package>"""


def test_a_cull_frustum_from_the_xml_is_the_camera_or_its_view_projection_matrix():
    camera = ('<filter type="Cull" position="0 0 0" look_at="1 0 0" up="0 0 1" fov_y="90" aspect="2" near="0.1" '
              'far="10"/>')
    app = build_application(parse_application_string(ROUTED.format(attributes="", filter=camera), filename="app.xml"))
    [cull] = app.connections
    assert isinstance(cull, Cull) and cull.frustum is not None
    assert cull.frustum.matrix == pytest.approx(Frustum.of_camera(**SEEN).matrix)
    matrix = " ".join(f"{value!r}" for value in cull.frustum.matrix)
    spec = parse_application_string(ROUTED.format(attributes="", filter=f'<filter type="Cull" view_projection="{matrix}"/>'),
                                    filename="app.xml")
    [by_matrix] = build_application(spec).connections
    assert isinstance(by_matrix, Cull) and by_matrix.frustum is not None
    assert np.allclose(by_matrix.frustum.planes, cull.frustum.planes)
    assert by_matrix.describe() == "Cull(bbox in view_projection), routed away 0"
    assert '"Cull\\nbbox in view_projection"' in dataflow_dot(plan_deployment(spec))
    defaults = ROUTED.format(attributes="", filter='<filter type="Cull" position="3 0 1" look_at="0 0 0.5"/>')
    [default] = build_application(parse_application_string(defaults, filename="app.xml")).connections
    assert default.describe().startswith("Cull(bbox in frustum from 3 0 1 to 0 0 0.5, fov_y 45, aspect 1.33333, "
                                         "near 0.05, far 100)")


@pytest.mark.parametrize("attributes, filter, expected", [
    ("", '<filter type="Cull"/>', 'app.xml:10: <filter type="Cull"> needs one region for its receiver'),
    ("", '<filter type="Cull" region="0 0 1 1" position="0 0 0" look_at="1 0 0"/>',
     "got region= and a camera (position=, look_at=, ...)"),
    ("", '<filter type="Cull" position="0 0" look_at="1 0 0"/>',
     'app.xml:10: <filter type="Cull"> attribute position="0 0": expected 3 numbers'),
    ("", '<filter type="Cull" fov_y="60"/>', "with a camera needs position= and look_at="),
    ("", '<filter type="Cull" position="1 1 1" look_at="1 1 1"/>', "position 1 1 1 is its look_at point"),
    ("", '<filter type="Cull" position="0 0 0" look_at="0 0 1"/>', "up=0 0 1 is parallel to the viewing direction"),
    ("", '<filter type="Cull" position="0 0 0" look_at="1 0 0" fov_y="180"/>', "fov_y=180: expected a vertical"),
    ("", '<filter type="Cull" position="0 0 0" look_at="1 0 0" fov_y="wide"/>',
     'attribute fov_y="wide": expected a vertical field of view'),
    ("", '<filter type="Cull" position="0 0 0" look_at="1 0 0" near="5" far="1"/>', "expected 0 < near < far"),
    ("", '<filter type="Cull" view_projection="1 2 3"/>', 'view_projection="1 2 3": expected 16 numbers'),
    ("", f'<filter type="Cull" view_projection="{" ".join(["0"] * 16)}"/>', "has no left plane"),
    ("", '<filter type="Cull" region="0 1 2"/>', 'app.xml:10: <filter type="Cull"> attribute region="0 1 2": '
                                                 "expected 2k numbers"),
    ("", '<filter type="Cull" region="5 0 1 1"/>', "each minimum at most its maximum"),
    ("", '<filter type="Cull" region="0 0 1 1" stamp=""/>', 'app.xml:10: <filter type="Cull"> attribute stamp=""'),
    ("", '<filter type="Split" by=""/>', 'app.xml:10: <filter type="Split"> attribute by="": expected the name'),
    ("", '<filter type="Split" hz="3"/>', "app.xml:10: "),
    ("", '<filter type="Scatter"/>', "expected one of: PreSignal, MaxFrequency, Greedy, Merge, Gather, Split, Cull"),
    (' stamps_only="maybe"', "", "app.xml:7: "),
])
def test_wrong_routing_parameters_are_errors_with_file_and_line(attributes: str, filter: str, expected: str):
    with pytest.raises(ConfigErrors) as raised:
        build_application(parse_application_string(ROUTED.format(attributes=attributes, filter=filter),
                                                   filename="app.xml"))
    assert expected in str(raised.value), str(raised.value)


def test_a_stamps_only_connection_into_a_port_of_another_type_is_an_error_with_file_and_line():
    text = ROUTED.format(attributes=' stamps_only="true"', filter="").replace(
        '<task>StampRecorder</task>', '<task>CostlyConsumer</task>')
    with pytest.raises(ConfigErrors) as raised:
        build_application(parse_application_string(text, filename="app.xml"))
    assert "app.xml:7:" in str(raised.value) and "that port takes int" in str(raised.value), str(raised.value)


# --- between processes ----------------------------------------------------------------------------

def test_cull_split_and_stamps_only_route_the_same_between_processes(tmp_path: Path):
    """config/stamp_routing.xml with the receivers in a process of their own: each gets what it gets in
    one process (each Split and Cull decided by the writer's end of its ring), the monitor the stamps
    only, the counters and the routed-away counts in the reader's process's profile. The emitter stops the application after 100 values; a filter's
    reader does not wait for its writer at the stop, so a receiver may miss the last few: the checks
    hold for what it got up to its last message."""
    text = (CONFIG / "stamp_routing.xml").read_text()
    text, wrapped = re.subn(r'(<activity name="view">.*?</activity>)', r'<process name="apart">\1</process>',
                            text, flags=re.S)
    assert wrapped == 1
    path = tmp_path / "apart.xml"
    path.write_text(text)
    out = tmp_path / "out"
    out.mkdir()
    launched = subprocess.run([sys.executable, "-m", "coco_core.launcher", str(path), "--profile", "600",
                               "period_ms:=2", "stop_after:=100", f"out_dir:={out}"],
                              capture_output=True, text=True, timeout=TIMEOUT)
    assert launched.returncode == 0, launched.stdout + launched.stderr
    got = {name: json.loads((out / f"{name}.json").read_text())
           for name in ("left", "right", "worker0", "worker1", "monitor")}
    regions = {"left": (0.0, 5.0), "right": (5.0, 10.0)}
    for name, (low, high) in regions.items():
        seqs = [entry["seq"] for entry in got[name]]
        assert seqs, name
        expected = [seq for seq in range(1, seqs[-1] + 1) if low <= box_of(seq - 1, 10, 1.0)[0] <= high
                    or low <= box_of(seq - 1, 10, 1.0)[2] <= high]
        assert seqs == expected, name
        for entry in got[name]:
            assert entry["value"] == entry["seq"] - 1 and entry["user"]["bbox"] == list(box_of(entry["value"], 10, 1.0))
    for index in (0, 1):
        seqs = [entry["seq"] for entry in got[f"worker{index}"]]
        assert seqs and seqs == list(range(index + 1, seqs[-1] + 1, 2))
    monitor = got["monitor"]
    assert monitor and all(entry["stamps_only"] and entry["value"] is None for entry in monitor)
    assert [entry["seq"] for entry in monitor] == list(range(1, len(monitor) + 1))
    assert monitor[0]["user"] == {"bbox": [0.0, 0.0, 1.0, 1.0], "part": 0}
    rows = {cells[1]: cells for line in launched.stdout.splitlines()
            if len(cells := re.split(r"\s{2,}", line.strip())) == 8 and " -> " in cells[1]}
    left = rows["emitter.out -> left.item"]
    assert left[2].startswith("Cull(bbox meets 0 0 5 1), routed away ") and left[0] == "apart"
    written, read, dropped, pending = map(int, left[3:7])
    assert written == read + dropped + pending and read == len(got["left"])
    worker1 = rows["emitter.out -> worker1.item"]
    assert worker1[2] == "Split(out1 of 2, in turn), routed away 50"  # decided by the writer, for all 100
    assert int(worker1[3]) == 50
    monitor_row = rows["emitter.out -> monitor.item"]  # the reader's process knows it from its channel
    assert monitor_row[0] == "apart" and monitor_row[2].endswith(", stamps only"), monitor_row


def test_split_and_cull_decide_on_the_writers_side_so_what_is_routed_away_never_crosses():
    """config/stamp_routing.xml with the receivers in process ``apart``: both processes' parts built
    here and attached to real shared-memory rings. Each ring takes only its reader's messages (the
    ring's offered count: every message crossed into each ring before), each reader gets exactly
    its messages in order, and the reader's process shows the routed-away count read from the ring
    as one process does. A message that cannot be routed crosses and is dropped by the reader's
    filter, counted as in one process."""
    from coco_core.processes.channels import attach, plan_channels
    from coco_core.processes.filtered import FedRouter
    from coco_core.processes.routed import RoutingEnd

    text, wrapped = re.subn(r'(<activity name="view">.*?</activity>)', r'<process name="apart">\1</process>',
                            (CONFIG / "stamp_routing.xml").read_text(), flags=re.S)
    assert wrapped == 1
    spec = parse_application_string(text, filename="apart.xml")
    writer_app, reader_app = build_application(spec), build_application(spec, "apart")
    assert sorted(writer_app.outgoing_routers) == ["emitter.out->left.item", "emitter.out->right.item",
                                                  "emitter.out->worker0.item", "emitter.out->worker1.item"]
    arena = Arena(f"writerroute{os.getpid()}x{os.urandom(3).hex()}")
    view = Wakeup.new()
    try:
        plans = plan_channels(arena, plan_deployment(spec).host())
        attach(writer_app, plans, {"view": view})
        attach(reader_app, plans, {"view": view})
        out = writer_app.component("emitter").out
        assert sum(isinstance(c, RoutingEnd) for c in out.connections) == 4
        for count in range(10):
            out.write(count, stamps={"bbox": box_of(count, 10, 1.0), "part": count})
        out.write(10, stamps={"bbox": (1, 2), "part": 10})  # a 1-d box: the Culls cannot route it
        ends = {name: reader_app.component(name).item.connections[0]
                for name in ("left", "right", "worker0", "worker1")}
        assert all(isinstance(end, FedRouter) for end in ends.values())
        crossed = {name: end.channel.written for name, end in ends.items()}
        assert crossed == {"left": 7, "right": 7, "worker0": 6, "worker1": 5}  # not 11 each
        got = {name: [value for value, _ in read_all(reader_app.component(name).item)] for name in ends}
        assert got == {"left": [0, 1, 2, 3, 4, 5], "right": [4, 5, 6, 7, 8, 9],
                       "worker0": [0, 2, 4, 6, 8, 10], "worker1": [1, 3, 5, 7, 9]}
        assert {name: end.counters() for name, end in ends.items()} == {
            "left": {"written": 7, "read": 6, "dropped": 1, "pending": 0},
            "right": {"written": 7, "read": 6, "dropped": 1, "pending": 0},
            "worker0": {"written": 6, "read": 6, "dropped": 0, "pending": 0},
            "worker1": {"written": 5, "read": 5, "dropped": 0, "pending": 0}}
        assert ends["left"].describe() == "Cull(bbox meets 0 0 5 1), routed away 4"
        assert ends["worker1"].describe() == "Split(out1 of 2, in turn), routed away 6"
        [monitor] = reader_app.component("monitor").item.connections
        assert monitor.written == 11  # a plain connection still takes every message
    finally:
        view.close()
        arena.close()


# --- Gather: a tree of Merges ---------------------------------------------------------------------

def test_a_gather_tree_of_merges_gives_the_nested_tuple_of_one_message_of_each_leaf(make_app):
    """FlowVR's binary Gather tree composes from Merge: two merges of two leaves, each into a Relay
    (a node of the tree, which a process or host of its own could run), merged again at the root.
    The root gets ((a, b), (c, d)) once every leaf wrote; a flat Merge of four gives (a, b, c, d)."""
    from coco_core.filters import Merge, MergeGroup
    from coco_core.relay import Relay

    app = make_app()
    leaves = [app.add(Writer(name)) for name in "abcd"]
    nodes = [app.add(Relay(f"node{index}")) for index in range(2)]
    root, flat = app.add(Reader("root")), app.add(Reader("flat"))
    for index, node in enumerate(nodes):
        group = MergeGroup()
        for leaf in leaves[2 * index:2 * index + 2]:
            app.connect(leaf.out, node.input, connection=Merge(BUFFERED, group))
    top, flat_group = MergeGroup(), MergeGroup()
    for node in nodes:
        app.connect(node.output, root.item, connection=Merge(BUFFERED, top))
    for leaf in leaves:
        app.connect(leaf.out, flat.item, connection=Merge(BUFFERED, flat_group))
    for round_ in range(2):
        for leaf in leaves[:3]:
            leaf.out.write(f"{leaf.name}{round_}")
        for node in nodes:
            node.on_update()
        assert read_all(root.item) == [] and read_all(flat.item) == []  # d has not written: nothing yet
        leaves[3].out.write(f"d{round_}")
        for node in nodes:
            node.on_update()
        [(value, stamp)] = read_all(root.item)
        assert value == ((f"a{round_}", f"b{round_}"), (f"c{round_}", f"d{round_}"))
        assert stamp.source == "node0.output"  # a merge is stamped as its first input's message
        assert [v for v, _ in read_all(flat.item)] == [(f"a{round_}", f"b{round_}", f"c{round_}", f"d{round_}")]


def test_a_gather_filter_is_the_binary_tree_of_merges_in_the_reader_s_path(make_app):
    """``Gather`` as one filter: the reader gets, once each connection holds a message, what
    FlowVR's tree of two-input merges gives (neighbours in pairs, the odd one out joined a level
    up), stamped as the first connection's message; every connection keeps its counters."""
    from coco_core.filters import Gather, GatherGroup

    app = make_app()
    leaves = [app.add(Writer(name)) for name in "abcde"]
    root = app.add(Reader("root"))
    group = GatherGroup()
    connections = [app.connect(leaf.out, root.item, connection=Gather(BUFFERED, group)) for leaf in leaves]
    for round_ in range(3):
        for leaf in leaves[1:]:
            leaf.out.write(f"{leaf.name}{round_}")
    assert read_all(root.item) == []  # a has not written: no tree yet
    for round_ in range(2):
        leaves[0].out.write(f"a{round_}")
    got = read_all(root.item)
    assert [value for value, _ in got] == [((((f"a{n}", f"b{n}"), (f"c{n}", f"d{n}")), f"e{n}")) for n in range(2)]
    assert [(stamp.source, stamp.seq) for _, stamp in got] == [("a.out", 1), ("a.out", 2)]
    assert [c.counters() for c in connections] == [{"written": 2, "read": 2, "dropped": 0, "pending": 0}] + \
        [{"written": 3, "read": 2, "dropped": 0, "pending": 1}] * 4
    assert [c.describe() for c in connections] == [f"Gather(leaf {index} of 5)" for index in range(5)]


GATHER = """<package name="gathered">
    <components>
        <component><name>a</name><task>CostlyProducer</task><library>coco_core</library></component>
        <component><name>b</name><task>CostlyProducer</task><library>coco_core</library></component>
        <component><name>c</name><task>CostlyProducer</task><library>coco_core</library></component>
        <component><name>root</name><task>Relay</task><library>coco_core</library></component>
    </components>
    <connections>
        <connection buffersize="4"><src task="a" port="out"/><dest task="root" port="input"/><filter type="Gather"/></connection>
        <connection buffersize="4"><src task="b" port="out"/><dest task="root" port="input"/><filter type="Gather"/></connection>
        <connection buffersize="4"><src task="c" port="out"/><dest task="root" port="input"/><filter type="{third}"/></connection>
    </connections>
    {activities}
</package>"""


def test_the_xml_gathers_the_connections_into_one_port_in_file_order():
    from coco_core.filters import Gather, GatherGroup

    app = build_application(parse_application_string(GATHER.format(third="Gather", activities=""), filename="app.xml"))
    a, b, c = app.connections
    assert all(isinstance(x, Gather) for x in (a, b, c)) and isinstance(a.group, GatherGroup)  # type: ignore[attr-defined]
    assert a.group is b.group is c.group and [x.index for x in (a, b, c)] == [0, 1, 2]  # type: ignore[attr-defined]
    for connection, value in zip((a, b, c), (1, 2, 3)):
        assert connection.source is not None
        connection.source.write(value)
    assert app.component("root").input.read() == (NEW_DATA, ((1, 2), 3))  # type: ignore[attr-defined]


def test_a_port_whose_connections_mix_gather_and_merge_is_an_error_with_file_and_line():
    with pytest.raises(ConfigErrors) as raised:
        build_application(parse_application_string(GATHER.format(third="Merge", activities=""), filename="app.xml"))
    assert "app.xml:11:" in str(raised.value) and "root.input already reads a Gather" in str(raised.value)


def test_a_gather_joins_leaves_from_another_process_and_from_its_own():
    """One leaf in another process (its ring fed into the Gather on the reader's side, in its file
    place), two in the reader's: one tree once each has a message, stamped as the first leaf's,
    which crossed with its stamp."""
    from coco_core.filters import Gather
    from coco_core.processes.channels import attach, plan_channels
    from coco_core.processes.filtered import FedFilter
    from coco_core.stamps import Message

    far = ('<activities><process name="far"><activity name="making"><schedule type="triggered"/>'
           '<components><component name="a"/></components></activity></process></activities>')
    spec = parse_application_string(GATHER.format(third="Gather", activities=far), filename="app.xml")
    app = build_application(spec)
    arena = Arena(f"gather{os.getpid()}")
    try:
        plans = plan_channels(arena, plan_deployment(spec).host())
        attach(app, plans, {})
        root = app.component("root")
        b, c, fed = root.input.connections  # type: ignore[attr-defined]  # the channel is attached after the build
        assert isinstance(fed, FedFilter) and isinstance(fed.filter, Gather) and fed.filter.index == 0
        assert isinstance(b, Gather) and (b.index, c.index) == (1, 2) and b.group is fed.filter.group
        ShmWriter(plans[0].channel).push(Message(7, 12.5, 1, "a.out", 4))
        app.component("b").out.write(8)  # type: ignore[attr-defined]
        assert root.input.read()[0] is not NEW_DATA  # c has nothing yet  # type: ignore[attr-defined]
        app.component("c").out.write(9)  # type: ignore[attr-defined]
        assert root.input.read() == (NEW_DATA, ((7, 8), 9))  # type: ignore[attr-defined]
        stamp = root.input.stamp  # type: ignore[attr-defined]
        assert stamp is not None and (stamp.source, stamp.seq, stamp.it, stamp.time) == ("a.out", 1, 4, 12.5)
        assert fed.describe() == "Gather(leaf 0 of 3)" and fed.counters()["read"] == 1
    finally:
        arena.close()
