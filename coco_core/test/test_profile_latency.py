"""The profile's latency figures read the message stamps: a plain (not ``Stamped``) value written
through a port has the stamp of its write, so the component that records its latency
(``record_latency``, the profile's latency column) measures it as it measures a ``Stamped`` one,
in one process and when the value crossed from another process (the channel carries the stamp).
A profiled run also gives each connection the age of what its reader took (the ``age`` column),
whether or not a component records a latency.

The application: a producer writing plain numbers, a :class:`~coco_core.demo.CsvRecorder` taking
them (it records each number's stamp and latency), and a consumer of the same numbers that stops the
application after a number of them (a natural stop: waiting is on the launcher's exit)."""

from __future__ import annotations

import csv
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from coco_core import Application, BufferPolicy, Component, ConnectionPolicy, InputPort, OutputPort
from coco_core.demo.csv_recorder import CsvRecorder
from coco_core.report import profile_report

TIMEOUT = 90.0
"""Seconds a launch may take on a loaded machine (two processes start, a few dozen cycles)."""

APP = """<?xml version="1.0"?>
<package name="plain_latency">
    <components>
        <component><name>producer</name><task>CostlyProducer</task><library>coco_core</library>
            <attributes><attribute name="cost_ms" value="0.2"/></attributes></component>
        <component><name>recorder</name><task>CsvRecorder</task><library>coco_core</library>
            <attributes><attribute name="path" value="{csv}"/></attributes></component>
        <component><name>consumer</name><task>CostlyConsumer</task><library>coco_core</library>
            <attributes><attribute name="cost_ms" value="0"/><attribute name="stop_after" value="20"/></attributes>
        </component>
    </components>
    <connections>
        <connection data="BUFFER" buffersize="256">
            <src task="producer" port="out"/><dest task="recorder" port="values"/>
        </connection>
        <connection data="BUFFER" buffersize="256">
            <src task="producer" port="out"/><dest task="consumer" port="item"/>
        </connection>
    </connections>
    <activities>
        {produce}
        <activity name="record"><schedule type="periodic" period="20"/>
            <components><component name="recorder"/></components></activity>
        <activity name="consume"><schedule type="triggered"/>
            <components><component name="consumer"/></components></activity>
    </activities>
</package>
"""
PRODUCE = """<activity name="produce"><schedule type="periodic" period="5"/>
            <components><component name="producer"/></components></activity>"""


def last_cell(report: str, row: str, cells_at_least: int = 0) -> str:
    """The last column (mean / max ms, or -) of the row of a profile report that has the cell
    ``row``: a component's latency (its table has 12 columns or more), a connection's age."""
    for line in report.splitlines():
        cells = re.split(r"\s{2,}", line.strip())
        if row in cells and len(cells) >= cells_at_least:
            return cells[-1]
    raise AssertionError(f"no row of {row} in the profile:\n{report}")


def latency_cell(report: str, component: str) -> str:
    return last_cell(report, component, 12)


def milliseconds(cell: str) -> tuple[float, float]:
    match = re.fullmatch(r"(\d+\.\d+) / (\d+\.\d+)", cell)
    assert match, f"no latency figure: {cell!r}"
    return float(match[1]), float(match[2])


class Numbers(Component):
    out = OutputPort(float)


class Taker(Component):
    values = InputPort(float)


class Tuples(Component):
    values = InputPort(object)


def test_a_plain_value_gets_a_latency_from_its_message_stamp(tmp_path: Path) -> None:
    app = Application("plain-latency")
    numbers, recorder = Numbers("numbers"), CsvRecorder("recorder", path=tmp_path / "rows.csv")
    app.add(numbers)
    app.add(recorder)
    app.connect("numbers.out", "recorder.values", ConnectionPolicy(BufferPolicy.BUFFER, size=8))
    recorder.on_config()
    for value in (1.0, 2.0, 3.0):
        numbers.out.write(value)
    written = numbers.out.stamp
    recorder.on_update()
    recorder.on_stop()
    assert written is not None and recorder.stats.latency.count == 3
    assert milliseconds(latency_cell(profile_report(app), "recorder"))[1] > 0.0
    with (tmp_path / "rows.csv").open() as rows:
        recorded = list(csv.DictReader(rows))
    assert [(row["seq"], row["source"], row["value"]) for row in recorded] == \
        [(str(seq), "numbers.out", f"{seq:.6f}") for seq in (1, 2, 3)]
    assert float(recorded[-1]["stamp_s"]) == pytest.approx(written.time, abs=1e-6)


@pytest.mark.parametrize("apart", [False, True], ids=["one_process", "producer_apart"])
def test_a_plain_value_gets_a_latency_in_the_launched_profile(tmp_path: Path, apart: bool) -> None:
    """With the producer in a ``<process>`` of its own the numbers cross a shared-memory channel,
    their stamps with them: the recorder's latency is from the write in the other process."""
    rows = tmp_path / "rows.csv"
    produce = f'<process name="apart">{PRODUCE}</process>' if apart else PRODUCE
    path = tmp_path / "app.xml"
    path.write_text(APP.format(csv=rows, produce=produce))
    launched = subprocess.run([sys.executable, "-m", "coco_core.launcher", str(path), "--profile", "600"],
                              capture_output=True, text=True, timeout=TIMEOUT)
    assert launched.returncode == 0, launched.stdout + launched.stderr
    assert "(clean)" in launched.stderr, launched.stderr
    mean, biggest = milliseconds(latency_cell(launched.stdout, "recorder"))
    assert 0.0 < mean <= biggest, launched.stdout
    for connection in ("producer.out -> recorder.values", "producer.out -> consumer.item"):
        mean, biggest = milliseconds(last_cell(launched.stdout, connection))  # measured in the reader's process
        assert 0.0 < mean <= biggest, launched.stdout
    with rows.open() as file:
        recorded = list(csv.DictReader(file))
    assert len(recorded) >= 20 and {row["source"] for row in recorded} == {"producer.out"}
    assert [int(row["seq"]) for row in recorded] == list(range(1, len(recorded) + 1))
    assert all(float(row["latency_ms"]) > 0.0 for row in recorded)


@pytest.mark.parametrize("measured", [False, True], ids=["unprofiled", "profiled"])
def test_each_connection_shows_the_age_of_what_its_reader_took(measured: bool) -> None:
    """No component records a latency here: the connection's own row has the ages, from each
    message's stamp to its read, in a profiled run only (an unprofiled reader reads no clock)."""
    app = Application("ages")
    numbers, taker = Numbers("numbers"), Taker("taker")
    app.add(numbers)
    app.add(taker)
    connection = app.connect("numbers.out", "taker.values", ConnectionPolicy(BufferPolicy.BUFFER, size=8))
    app.measure_ages = measured
    app.start()
    try:
        before = time.perf_counter()
        for value in (1.0, 2.0, 3.0):
            numbers.out.write(value)
        assert [taker.values.read()[1] for _ in range(3)] == [1.0, 2.0, 3.0]
        longest = time.perf_counter() - before
    finally:
        app.stop()
    cell = last_cell(profile_report(app), "numbers.out -> taker.values")
    if not measured:
        assert connection.age is None and cell == "-"
        return
    assert connection.age is not None and connection.age.count == 3
    assert 0.0 < connection.age.mean <= connection.age.max <= longest
    assert milliseconds(cell) == pytest.approx((connection.age.mean * 1e3, connection.age.max * 1e3), abs=1e-3)


def test_every_input_of_a_merge_shows_the_age_of_what_the_merge_took() -> None:
    """The reader's port reads a merge through its first connection; the merge takes one message
    of each other input itself, and times them for their rows."""
    from coco_core.filters import Gather, GatherGroup

    app = Application("merged-ages")
    left, right, taker = Numbers("left"), Numbers("right"), Tuples("taker")
    for component in (left, right, taker):
        app.add(component)
    group = GatherGroup()
    policy = ConnectionPolicy(BufferPolicy.BUFFER, size=8)
    connections = [app.connect(f"{name}.out", "taker.values", policy, connection=Gather(policy, group))
                   for name in ("left", "right")]
    app.measure_ages = True
    app.start()
    try:
        left.out.write(1.0)
        right.out.write(2.0)
        assert taker.values.read()[1] == (1.0, 2.0)
    finally:
        app.stop()
    assert [connection.age.count for connection in connections] == [1, 1]  # type: ignore[union-attr]
