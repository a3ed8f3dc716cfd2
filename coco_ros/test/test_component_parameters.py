"""Component attributes as ROS parameters (coco_ros.component_parameters), read through the
parameter services as ``ros2 param`` reads them: typed, documented, ranged, read-only unless the
attribute is live; a set of a live one reaches the component, NaN and out-of-range values are
refused with the reason, and a change made through the ``set_attribute`` operation shows in
``get_parameters``.

In-process: the application runs on CoCo's threads, the node and a parameter client of this test
on their own DDS domain."""

from __future__ import annotations

import math
from typing import Any, Iterator

import pytest
from coco_core.builder import build_application
from coco_core.xml import parse_application_string
from coco_ros.component_parameters import ComponentParameters

from conftest import spinning_peer, wait_for

DOMAIN = "84"
APP = """<package name="attribute_app">
  <components>
    <component><name>gen</name><task>SignalGenerator</task><library>coco_core</library>
      <attributes><attribute name="frequency" value="0.5"/></attributes></component>
    <component><name>avg</name><task>MovingAverage</task><library>coco_core</library></component>
  </components>
  <connections>
    <connection data="DATA"><src task="gen" port="sample"/><dest task="avg" port="sample"/></connection>
  </connections>
  <activities>
    <activity name="sampling"><schedule type="periodic" period="20"/>
      <components><component name="gen"/></components></activity>
    <activity name="averaging"><schedule type="triggered"/>
      <components><component name="avg"/></components></activity>
  </activities>
</package>
"""


@pytest.fixture
def running(monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[Any, Any, Any]]:
    """(the application, running; its node with the attributes declared; a parameter client)."""
    from rclpy.node import Node
    from rclpy.parameter_client import AsyncParameterClient

    app = build_application(parse_application_string(APP))
    for peer in spinning_peer(monkeypatch, DOMAIN, "attribute_peer"):
        node = Node("attribute_app", context=peer.context)
        ComponentParameters(node, app).declare()
        peer.executor.add_node(node)
        app.start()
        client = AsyncParameterClient(peer, "attribute_app")
        assert client.wait_for_services(timeout_sec=20), "the node's parameter services never appeared"
        yield app, node, client
        app.request_stop()
        app.stop()
        node.destroy_node()


def answer(future: Any, seconds: float = 10) -> Any:
    return wait_for(lambda: future.done() and future.result(), "the parameter service's answer", seconds)


def test_descriptors_say_type_doc_range_and_what_may_change(running) -> None:
    from rcl_interfaces.msg import ParameterType

    _, _, client = running
    names = ["gen.frequency", "gen.seed", "avg.window"]
    frequency, seed, window = answer(client.describe_parameters(names)).descriptors
    assert frequency.type == ParameterType.PARAMETER_DOUBLE and not frequency.read_only
    assert "sine frequency" in frequency.description
    assert frequency.floating_point_range[0].from_value == 0.0
    assert seed.type == ParameterType.PARAMETER_INTEGER and seed.read_only
    assert "read when gen configures" in seed.additional_constraints
    assert window.read_only and window.integer_range[0].from_value == 1
    values = answer(client.get_parameters(["gen.frequency", "avg.window"])).values
    assert (values[0].double_value, values[1].integer_value) == (0.5, 8)


def test_a_live_set_reaches_the_component_and_bad_values_are_refused_with_why(running) -> None:
    from rclpy.parameter import Parameter

    app, _, client = running
    generator = app.component("gen")
    assert answer(client.set_parameters([Parameter("gen.frequency", value=2.0)])).results[0].successful
    wait_for(lambda: generator.frequency == 2.0, "the component to take the new frequency", 10)
    refused = [("gen.frequency", math.nan, "out of range"),  # rclpy's range check says it
               ("gen.frequency", -1.0, "out of range"),
               ("gen.amplitude", math.nan, "NaN and infinities are refused"),  # no range: the component's check
               ("gen.noise", math.inf, "out of range")]
    for name, value, reason in refused:
        result = answer(client.set_parameters([Parameter(name, value=value)])).results[0]
        assert not result.successful and reason in result.reason, (name, value, result.reason)
    result = answer(client.set_parameters([Parameter("gen.seed", value=3)])).results[0]
    assert not result.successful and "read-only" in result.reason
    assert answer(client.get_parameters(["gen.frequency", "gen.seed"])).values[0].double_value == 2.0
    assert (generator.frequency, generator.amplitude, generator.noise, generator.seed) == (2.0, 1.0, 0.1, 1)


def test_a_change_through_the_operation_shows_in_get_parameters(running) -> None:
    app, _, client = running
    app.operation("gen", "set_attribute")("frequency", 0.1).result(timeout=5)
    assert answer(client.get_parameters(["gen.frequency"])).values[0].double_value == 0.1
    app.operation("avg", "set_attribute")("window", 3).result(timeout=5)  # read-only for ROS, not for CoCo
    assert answer(client.get_parameters(["avg.window"])).values[0].integer_value == 3
