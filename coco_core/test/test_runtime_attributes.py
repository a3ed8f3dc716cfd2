"""Typed attributes: parsing application-file text, validation with clear messages, run-time changes."""

from __future__ import annotations

import enum
import threading
from pathlib import Path

import pytest

from coco_core import (
    Attribute,
    AttributeValueError,
    Component,
    PeriodicActivity,
    UnknownNameError,
)


class Mode(enum.Enum):
    IDLE = "idle"
    TRACKING = "tracking"


class Tuned(Component):
    count = Attribute(int, 3, "how many", min=0, max=10)
    gain = Attribute(float, 1.0, "a gain", min=0.0)
    enabled_flag = Attribute(bool, False)
    label = Attribute(str, "none", choices=["none", "left", "right"])
    path = Attribute(Path, Path("/tmp/out.csv"))
    mode = Attribute(Mode, Mode.IDLE)
    ids = Attribute(list[int], [1], "a vector", min=0, max=100)
    weights = Attribute(tuple[float, ...], (0.5, 0.5))
    names = Attribute(list[str], [])
    even = Attribute(int, 0, check=lambda v: None if v % 2 == 0 else f"{v} is odd")


def test_defaults_before_anything_is_set():
    tuned = Tuned("tuned")
    assert tuned.attributes() == {
        "count": 3, "gain": 1.0, "enabled_flag": False, "label": "none", "path": Path("/tmp/out.csv"),
        "mode": Mode.IDLE, "ids": [1], "weights": (0.5, 0.5), "names": [], "even": 0,
    }
    assert Tuned.count.describe() == {"name": "count", "type": "int", "default": 3, "doc": "how many"}
    assert Tuned.ids.type_name == "list of int"


@pytest.mark.parametrize("name,text,expected", [
    ("count", "7", 7),
    ("count", " 10 ", 10),
    ("gain", "2.5", 2.5),
    ("gain", "1e-3", 0.001),
    ("gain", "4", 4.0),
    ("enabled_flag", "true", True),
    ("enabled_flag", "YES", True),
    ("enabled_flag", "1", True),
    ("enabled_flag", "off", False),
    ("enabled_flag", "0", False),
    ("label", "left", "left"),
    ("path", "data/log.csv", Path("data/log.csv")),
    ("mode", "TRACKING", Mode.TRACKING),
    ("mode", " IDLE ", Mode.IDLE),
    ("ids", "1, 2,3,  5", [1, 2, 3, 5]),
    ("ids", "4 5 6", [4, 5, 6]),
    ("ids", "", []),
    ("weights", "0.25,0.75", (0.25, 0.75)),
    ("names", "a, b ,c", ["a", "b", "c"]),
    ("even", "4", 4),
])
def test_values_parsed_from_text(name, text, expected):
    tuned = Tuned("tuned", **{name: text})
    value = getattr(tuned, name)
    assert value == expected
    assert type(value) is type(expected)
    if isinstance(expected, (list, tuple)):
        assert all(type(a) is type(b) for a, b in zip(value, expected))


@pytest.mark.parametrize("name,value,expected", [
    ("count", 4, 4),
    ("count", 5.0, 5),
    ("gain", 3, 3.0),
    ("path", "x.txt", Path("x.txt")),
    ("mode", Mode.TRACKING, Mode.TRACKING),
    ("ids", (7, 8), [7, 8]),
    ("ids", ["9", 10], [9, 10]),
    ("weights", [1, 2], (1.0, 2.0)),
])
def test_python_values_are_coerced(name, value, expected):
    tuned = Tuned("tuned")
    tuned.set_attribute_now(name, value)
    assert getattr(tuned, name) == expected
    assert type(getattr(tuned, name)) is type(expected)


@pytest.mark.parametrize("name,value,fragment", [
    ("count", "abc", "expected an integer, got 'abc'"),
    ("count", "2.5", "expected an integer"),
    ("count", True, "expected an integer"),
    ("count", -1, "expected >= 0, got -1"),
    ("count", "11", "expected <= 10, got 11"),
    ("gain", "fast", "expected a number"),
    ("gain", -0.5, "expected >= 0.0"),
    ("enabled_flag", "maybe", "expected a boolean"),
    ("enabled_flag", 1, "expected bool"),
    ("label", "center", "expected one of none, left, right, got 'center'"),
    ("mode", "RUNNING", "expected one of IDLE, TRACKING, got 'RUNNING'"),
    ("ids", "1, 2, x", "expected an integer, got 'x'"),
    ("ids", "1, 200", "expected <= 100, got 200"),
    ("ids", 5, "expected a list of int"),
    ("even", 3, "3 is odd"),
    # NaN passes min=0.0 (every comparison with it is false), and 1e999 parses as an infinity.
    ("gain", "nan", "expected a finite number, got nan"),
    ("gain", "1e999", "expected a finite number, got inf"),
    ("gain", float("-inf"), "expected a finite number, got -inf"),
    ("weights", "0.5, nan", "expected a finite number, got nan"),
    ("weights", (0.5, float("inf")), "expected a finite number, got inf"),
])
def test_violations_name_the_component_and_the_attribute(name, value, fragment):
    with pytest.raises(AttributeValueError) as info:
        Tuned("my_tuner", **{name: value})
    message = str(info.value)
    assert f"my_tuner.{name}" in message, message
    assert fragment in message, message


def test_an_attribute_that_says_it_takes_non_finite_numbers_gets_them():
    class Limited(Component):
        limit = Attribute(float, float("inf"), "largest value; inf: none", finite=False)

    assert Limited("limited", limit="inf").limit == float("inf")
    assert Limited("limited", limit="nan").limit != Limited("other").limit


def test_a_rejected_value_leaves_the_attribute_unchanged():
    tuned = Tuned("tuned", count=5)
    with pytest.raises(AttributeValueError):
        tuned.set_attribute_now("count", 99)
    assert tuned.count == 5
    with pytest.raises(AttributeValueError):
        tuned.count = "x"
    assert tuned.count == 5
    tuned.count = "6"  # plain assignment validates and parses too
    assert tuned.count == 6


def test_instances_do_not_share_values():
    a, b = Tuned("a", count=1), Tuned("b")
    a.count = 2
    assert (a.count, b.count) == (2, 3)


def test_unknown_attribute_lists_valid_ones():
    with pytest.raises(UnknownNameError) as info:
        Tuned("tuned", cout=2)
    message = str(info.value)
    assert "tuned" in message and "'cout'" in message and "did you mean 'count'" in message
    for name in ("gain", "label", "mode", "ids"):
        assert name in message


def test_set_attribute_at_run_time_from_another_thread(make_app, wait_until):
    class Controller(Tuned):
        def init(self):
            self.seen: list[tuple[int, float, int]] = []

        def on_update(self):
            self.seen.append((self.count, self.gain, threading.get_ident()))

    app = make_app("runtime-attributes")
    controller = app.add(Controller("controller", count=2), PeriodicActivity("periodic", 0.01))
    app.start()
    assert wait_until(lambda: len(controller.seen) >= 2)
    thread = controller.seen[0][2]
    results = {}

    def other_thread():
        results["set"] = controller.call("set_attribute", "gain", "3.5").result(timeout=2.0)
        results["count"] = controller.operation("set_attribute")("count", 9).result(timeout=2.0)
        results["get"] = controller.call("get_attribute", "gain").result(timeout=2.0)
        results["error"] = controller.call("set_attribute", "count", "99").exception(timeout=2.0)
        results["unknown"] = controller.call("get_attribute", "nope").exception(timeout=2.0)

    worker = threading.Thread(target=other_thread)
    worker.start()
    worker.join(5.0)
    assert not worker.is_alive()
    assert results["set"] is None and results["count"] is None and results["get"] == 3.5
    assert isinstance(results["error"], AttributeValueError)
    assert "controller.count" in str(results["error"]) and "99" in str(results["error"])
    assert isinstance(results["unknown"], UnknownNameError)
    assert wait_until(lambda: controller.seen[-1][:2] == (9, 3.5))
    assert controller.count == 9, "the rejected value changed nothing"
    assert {t for _, _, t in controller.seen} == {thread}
    # Values change between updates: each update sees either the old or the new pair, in order.
    pairs = [s[:2] for s in controller.seen]
    assert pairs[0] == (2, 1.0)
    assert sorted(set(pairs), key=pairs.index) in ([(2, 1.0), (2, 3.5), (9, 3.5)], [(2, 1.0), (9, 3.5)])
