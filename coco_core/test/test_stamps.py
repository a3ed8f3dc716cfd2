"""Stamps: the steps a stamped value passed on its way, for a latency split by step."""

from __future__ import annotations

import time

import pytest

from coco_core.stamps import Stamp


def test_steps_are_appended_in_order_and_give_the_time_from_each_one_before():
    origin = Stamp(10.0, 4, "camera")
    way = origin.step("sent", 10.002).step("received", 10.030)
    assert origin.steps == () and (way.time, way.seq, way.source) == (10.0, 4, "camera")
    assert way.steps == (("sent", 10.002), ("received", 10.030))
    assert [name for name, _ in way.intervals()] == ["sent", "received"]
    assert [seconds for _, seconds in way.intervals()] == pytest.approx([0.002, 0.028])
    assert origin.intervals() == []


def test_a_step_without_a_time_is_now():
    before = time.perf_counter()
    [(name, at)] = Stamp.now().step("meshed").steps
    assert name == "meshed" and before <= at <= time.perf_counter()
