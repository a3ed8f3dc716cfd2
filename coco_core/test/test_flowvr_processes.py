"""FlowVR's Figure 1 a-d with the producer and the consumer in two processes: the same checked
behaviour as in one process (the checks of test_flowvr_patterns.py), filters and beginit/endit
connections between processes included, no deadlock at the stop, the connections in the profile.

Each case runs config/flowvr_<x>.xml with a ``<process>`` around one of the two activities in a real
``coco-launch``; the consumer stops the application (a natural stop) after a number of values, and
both components write what they recorded (from the message stamps, which cross with the values)
to a file when they stop. Waiting is on the launcher's exit, never on a fixed time."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from coco_core.demo.coupling import load_record
from coco_core.shm import FORCE_LOCKED

from test_flowvr_patterns import CONFIG, check_a_bounded, check_a_every_value, check_b, check_c, check_d

TIMEOUT = 90.0
"""Seconds a launch may take on a loaded machine (two processes start, a few hundred cycles)."""
DATA = "producer.out -> consumer.item"


def spread(name: str, apart: str, tmp_path: Path, stop_after: int) -> Path:
    """config/<name> with the activity ``apart`` in a process of its own, each component recording to
    tmp_path, the consumer stopping the application after ``stop_after`` values."""
    text = (CONFIG / name).read_text()
    text, wrapped = re.subn(rf'(<activity name="{apart}">.*?</activity>)', r'<process name="apart">\1</process>',
                            text, flags=re.S)
    assert wrapped == 1
    for component, extra in (("producer", ""),
                             ("consumer", f'<attribute name="stop_after" value="{stop_after}"/>')):
        text, done = re.subn(rf"(<name>{component}</name>.*?<attributes>)",
                             rf'\1<attribute name="record" value="{tmp_path / component}.json"/>{extra}',
                             text, count=1, flags=re.S)
        assert done == 1
    path = tmp_path / name
    path.write_text(text)
    return path


def run(name: str, apart: str, tmp_path: Path, stop_after: int, env: dict[str, str] | None = None, **args: object):
    """Launch, wait for the consumer's natural stop; (producer's record, consumer's record, the
    profile's connection rows by label: written, read, dropped, pending, and the policy column)."""
    path = spread(name, apart, tmp_path, stop_after)
    launched = subprocess.run([sys.executable, "-m", "coco_core.launcher", str(path), "--profile", "600",
                               *(f"{key}:={value}" for key, value in args.items())],
                              capture_output=True, text=True, timeout=TIMEOUT,
                              env=None if env is None else {**os.environ, **env})
    assert launched.returncode == 0, launched.stdout + launched.stderr
    assert "stopped" in launched.stderr and "(clean)" in launched.stderr, launched.stderr
    rows = {}
    for line in launched.stdout.splitlines():
        cells = re.split(r"\s{2,}", line.strip())
        if len(cells) == 8 and " -> " in cells[1] and cells[3].isdigit():
            rows[cells[1]] = {"policy": cells[2], **dict(zip(("written", "read", "dropped", "pending"),
                                                             map(int, cells[3:7]))), "process": cells[0],
                              "age": cells[7]}
    return load_record(tmp_path / "producer.json"), load_record(tmp_path / "consumer.json"), rows


def counters(rows: dict, label: str = DATA) -> dict[str, int]:
    row = rows[label]
    assert row["written"] == row["read"] + row["dropped"] + row["pending"], row
    return {key: row[key] for key in ("written", "read", "dropped", "pending")}


APART = pytest.mark.parametrize("apart", ["produce", "consume"], ids=["producer_apart", "consumer_apart"])


@APART
def test_a_data_driven_between_processes(tmp_path: Path, apart: str) -> None:
    producer, consumer, rows = run("flowvr_a_data_driven.xml", apart, tmp_path, 60,
                                   period_ms=5, producer_ms=0.2, consumer_ms=0.5, queue=64)
    check_a_every_value(producer, consumer, counters(rows))
    assert consumer.consumed == producer.produced  # the natural stop let the consumer take the last ones


def test_a_data_driven_queue_is_bounded_between_processes(tmp_path: Path) -> None:
    queue = 6
    producer, consumer, rows = run("flowvr_a_data_driven.xml", "produce", tmp_path, 10,
                                   period_ms=2, producer_ms=0.1, consumer_ms=15, queue=queue)
    check_a_bounded(producer, consumer, counters(rows), queue)
    assert counters(rows)["dropped"] >= 5  # the producer wrote ~7x faster than the consumer took


@APART
@pytest.mark.parametrize("tokens", [1, 3])
def test_b_demand_driven_between_processes(tmp_path: Path, apart: str, tokens: int) -> None:
    """The consumer's endit crosses to the producer's beginit through a PreSignal on the producer's
    side (before: refused, 'works inside one process in this version')."""
    producer, consumer, rows = run("flowvr_b_demand_driven.xml", apart, tmp_path, 40,
                                   producer_ms=0.5, consumer_ms=3, tokens=tokens)
    check_b(producer, consumer, counters(rows), tokens)
    loop = rows["consume.endit -> produce.beginit"]
    assert loop["policy"] == f"PreSignal(tokens={tokens})"
    assert loop["process"] == ("apart" if apart == "produce" else "launcher"), "the filter is on the reader's side"
    assert loop["written"] == loop["read"] + loop["dropped"] + loop["pending"] and loop["dropped"] == 0


@APART
def test_c_max_frequency_between_processes(tmp_path: Path, apart: str) -> None:
    hz = 50.0
    producer, consumer, rows = run("flowvr_c_max_frequency.xml", apart, tmp_path, 60,
                                   max_hz=hz, producer_ms=0.5, consumer_ms=1)
    check_c(producer, hz)
    assert rows["produce.endit -> produce.beginit"]["policy"] == f"MaxFrequency(hz={hz:g})"
    check_a_every_value(producer, consumer, counters(rows))


@APART
def test_d_greedy_between_processes(tmp_path: Path, apart: str) -> None:
    producer, consumer, rows = run("flowvr_d_greedy.xml", apart, tmp_path, 30, producer_ms=1, consumer_ms=8)
    check_d(producer, consumer)
    greedy = rows[DATA]
    assert greedy["policy"] == "Greedy" and greedy["process"] == ("launcher" if apart == "produce" else "apart")
    assert (greedy["read"], greedy["written"]) == (consumer.consumed, producer.produced)


def test_d_greedy_between_processes_on_the_locked_path(tmp_path: Path) -> None:
    """The rings' locked path (CPUs that may reorder stores; forced here) carries the stamps and
    feeds the filters the same way."""
    producer, consumer, rows = run("flowvr_d_greedy.xml", "produce", tmp_path, 30, env={FORCE_LOCKED: "1"},
                                   producer_ms=1, consumer_ms=8)
    check_d(producer, consumer)
    assert (rows[DATA]["read"], rows[DATA]["written"]) == (consumer.consumed, producer.produced)
