"""Wiring errors, name lookups that list the valid names, and the component registry."""

from __future__ import annotations

import pytest

from coco_core import (
    Application,
    BufferPolicy,
    CocoError,
    Component,
    ConnectionPolicy,
    InputPort,
    OutputPort,
    PeriodicActivity,
    PooledOutputPort,
    Slot,
    Stamped,
    SyncPolicy,
    TriggeredActivity,
    UnknownNameError,
    WiringError,
    register,
)
from coco_core import registry


class Numbers(Component):
    ints = OutputPort(int)
    flags = OutputPort(bool)
    anything = OutputPort(object)
    feedback = InputPort(int)


class Texts(Component):
    text = InputPort(str)
    number = InputPort(int)
    status = OutputPort(str)


class Camera(Component):
    image = PooledOutputPort(slots=3)


class Viewer(Component):
    image = InputPort(Slot)


@pytest.fixture
def app():
    app = Application("wiring")
    app.add(Numbers("nums"))
    app.add(Texts("texts"))
    return app


def test_input_port_as_source_is_refused(app):
    with pytest.raises(WiringError) as info:
        app.connect("nums.feedback", "texts.number")
    message = str(info.value)
    assert "nums.feedback" in message and "input" in message
    assert "ints" in message, "the message lists the outputs to use instead"
    assert app.connections == []


def test_output_port_as_sink_is_refused(app):
    with pytest.raises(WiringError) as info:
        app.connect("nums.ints", "texts.status")
    message = str(info.value)
    assert "texts.status" in message and "output" in message
    assert "text" in message and "number" in message, "the message lists the inputs to use instead"


def test_incompatible_types_name_both_types(app):
    with pytest.raises(WiringError) as info:
        app.connect("nums.ints", "texts.text")
    message = str(info.value)
    assert "nums.ints" in message and "texts.text" in message
    assert "int" in message and "str" in message
    assert app.connections == []


def test_compatible_types_connect(app):
    app.connect("nums.ints", "texts.number")
    app.connect("nums.flags", "texts.number")  # bool is an int
    app.connect("nums.anything", "texts.text")  # object goes anywhere (checked at run time by nobody)
    assert len(app.connections) == 3


def test_generic_output_type_connects_to_its_unparameterised_input():
    class Sensor(Component):
        sample = OutputPort(Stamped[float])

    class Filter(Component):
        sample = InputPort(Stamped)

    app = Application("generic")
    app.add(Sensor("sensor"))
    app.add(Filter("filter"))
    # A Stamped[float] is a Stamped: the demo MovingAverage declares InputPort(Stamped).
    connection = app.connect("sensor.sample", "filter.sample")
    assert connection in app.connections


def test_pool_policy_on_a_plain_port_is_refused(app):
    with pytest.raises(WiringError, match="POOL") as info:
        app.connect("nums.ints", "texts.number", ConnectionPolicy(BufferPolicy.POOL))
    assert "nums.ints" in str(info.value)


@pytest.mark.parametrize("data", [BufferPolicy.BUFFER, BufferPolicy.CIRCULAR])
def test_copying_policy_on_a_pooled_port_is_refused(data):
    app = Application("pool")
    app.add(Camera("camera"))
    app.add(Viewer("viewer"))
    with pytest.raises(WiringError) as info:
        app.connect("camera.image", "viewer.image", ConnectionPolicy(data, SyncPolicy.LOCKED, 4))
    assert "camera.image" in str(info.value) and "POOL" in str(info.value) and data.value in str(info.value)
    assert app.connections == []


def test_unsync_across_two_activities_is_reported_at_start(make_app):
    app = make_app("unsync")
    app.add(Numbers("nums"), PeriodicActivity("fast", 0.01))
    app.add(Texts("texts"), TriggeredActivity("slow"))
    app.connect("nums.ints", "texts.number", ConnectionPolicy(BufferPolicy.DATA, SyncPolicy.UNSYNC))
    assert len(app.problems()) == 1
    with pytest.raises(CocoError) as info:
        app.start()
    message = str(info.value)
    assert "UNSYNC" in message and "fast" in message and "slow" in message
    assert "nums.ints" in message and "texts.number" in message
    assert not any(activity.running for activity in app.activities.values()), "nothing may start"


def test_unsync_inside_one_activity_is_fine(make_app):
    app = make_app("unsync-ok")
    activity = PeriodicActivity("one", 0.01)
    app.add(Numbers("nums"), activity)
    app.add(Texts("texts"), activity)
    app.connect("nums.ints", "texts.number", ConnectionPolicy(BufferPolicy.DATA, SyncPolicy.UNSYNC))
    assert app.problems() == []
    app.start()
    assert app.stop()


def test_unknown_port_name_lists_valid_ones(app):
    with pytest.raises(UnknownNameError) as info:
        app.connect("nums.int", "texts.number")
    message = str(info.value)
    assert "nums" in message and "'int'" in message
    for valid in ("ints", "flags", "anything", "feedback"):
        assert valid in message
    assert "did you mean 'ints'" in message
    with pytest.raises(UnknownNameError) as info:
        app.component("texts").port("nope")
    assert "text" in str(info.value) and "status" in str(info.value)


def test_unknown_component_name_lists_known_ones(app):
    with pytest.raises(UnknownNameError) as info:
        app.connect("numz.ints", "texts.number")
    assert "numz" in str(info.value) and "nums" in str(info.value) and "texts" in str(info.value)
    with pytest.raises(CocoError, match="component.port"):
        app.connect("ints", "texts.number")


def test_unknown_activity_name_lists_known_ones(make_app):
    app = make_app()
    app.add(Numbers("nums"), PeriodicActivity("control", 0.01))
    with pytest.raises(UnknownNameError) as info:
        app.set_period("contrl", 0.02)
    assert "control" in str(info.value)


def test_duplicate_names_are_refused():
    app = Application("dup")
    app.add(Numbers("x"))
    with pytest.raises(CocoError, match="'x'"):
        app.add(Texts("x"))
    app.add_activity(TriggeredActivity("a"))
    with pytest.raises(CocoError, match="'a'"):
        app.add_activity(PeriodicActivity("a", 0.1))
    app.add_activity(TriggeredActivity("m1", main=True))
    with pytest.raises(CocoError, match="main"):
        app.add_activity(TriggeredActivity("m2", main=True))


def test_a_component_belongs_to_one_activity():
    app = Application("twice")
    app.add(Numbers("nums"), TriggeredActivity("a"))
    with pytest.raises(ValueError, match="already in activity a"):
        app.schedule("nums", TriggeredActivity("b"))


# --- registry -------------------------------------------------------------------------------------


@register("RuntimeTestWidget")
class Widget(Component):
    pass


@register()
class RuntimeTestGadget(Component):
    pass


def test_registry_loads_registered_names():
    assert registry.load("RuntimeTestWidget") is Widget
    assert registry.load("RuntimeTestGadget") is RuntimeTestGadget
    known = registry.registrations()
    assert known["RuntimeTestWidget"].target.endswith(":Widget")


def test_registry_unknown_name_lists_known_ones():
    with pytest.raises(registry.UnknownComponentError) as info:
        registry.load("RuntimeTestWidgt")
    message = str(info.value)
    assert "RuntimeTestWidgt" in message
    assert "RuntimeTestWidget" in message and "RuntimeTestGadget" in message
    assert "did you mean 'RuntimeTestWidget'" in message
    assert isinstance(info.value, CocoError)


def test_registry_loads_module_paths_and_checks_them():
    assert registry.load("coco_core.demo.moving_average:MovingAverage").__name__ == "MovingAverage"
    with pytest.raises(registry.UnknownComponentError, match="no_such_module"):
        registry.load("no_such_module:Thing")
    with pytest.raises(CocoError, match="not a coco_core.Component"):
        registry.load("coco_core.policy:ConnectionPolicy")


def test_registry_library_mismatch_is_reported():
    library = registry.registrations()["RuntimeTestWidget"].library
    assert registry.load("RuntimeTestWidget", library) is Widget
    with pytest.raises(registry.UnknownComponentError, match="not 'elsewhere'"):
        registry.load("RuntimeTestWidget", "elsewhere")


def test_in_flight_counts_queued_data_and_busy_activities_not_latest_values() -> None:
    app = Application("flight")
    nums = app.add(Numbers("nums"), TriggeredActivity("source"))
    texts = app.add(Texts("texts"), TriggeredActivity("sink"))
    app.connect("nums.ints", "texts.number", ConnectionPolicy(BufferPolicy.BUFFER, size=4))
    app.connect("nums.anything", "texts.text")  # DATA: a latest value
    assert not app.in_flight()
    nums.anything.write("latest")
    assert not app.in_flight(), "an unread latest value is not in flight"
    nums.ints.write(1)
    assert app.in_flight(), "a queued value is"
    assert texts.number.read_all() == [1]
    assert not app.in_flight()
    sink = app.activities["sink"]
    sink.wake()
    assert app.in_flight(), "a wake-up waiting means a cycle is still to come"
    assert not app.in_flight(besides=sink), "the caller's own activity is left out"
