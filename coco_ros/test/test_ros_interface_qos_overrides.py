"""ROSInterface honours rclpy's QoS override parameters (``qos_overrides.<topic>.<kind>.<policy>``),
as ``QoSOverridingOptions`` does for any rclpy node: the launcher runs as the installed script, this
test's node reads the QoS the launcher's entities offer and request through the DDS graph."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator

import pytest

from conftest import rclpy_peer
from test_launcher_parameters import spin_until, start_launcher

DOMAIN = "43"
APP = """<package name="qos_app">
  <components>
    <component><name>bridge</name><task>ROSInterface</task><library>coco_ros</library>
      <attributes>
        <attribute name="subscribe" value="incoming=/qos_in:std_msgs/msg/Float64;reliability=reliable;depth=5"/>
        <attribute name="publish" value="value=/qos_out:std_msgs/msg/Float64;reliability=reliable;depth=5"/>
      </attributes></component>
  </components>
  <connections>
    <connection data="BUFFER" policy="LOCKED" buffersize="8">
      <src task="bridge" port="incoming"/><dest task="bridge" port="value"/></connection>
  </connections>
  <activities>
    <activity name="bridging"><schedule type="triggered"/>
      <components><component name="bridge"/></components></activity>
  </activities>
</package>
"""


@pytest.fixture
def peer(monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[Any, Any]]:
    yield from rclpy_peer(monkeypatch, DOMAIN, "qos_peer")


def test_qos_override_parameters_replace_the_xmls_qos(tmp_path: Path, peer: tuple[Any, Any]) -> None:
    from rclpy.qos import ReliabilityPolicy

    node, executor = peer
    process = start_launcher(tmp_path / "qos_app.xml", APP, "--duration", "60", "--ros-args", "-r", "__node:=qos_under_test",
                             "-p", "qos_overrides./qos_out.publisher.reliability:=best_effort",
                             "-p", "qos_overrides./qos_out.publisher.depth:=3",
                             "-p", "qos_overrides./qos_in.subscription.reliability:=best_effort", domain=DOMAIN)

    def endpoint(topic: str, publishers: bool) -> Any:
        found = (node.get_publishers_info_by_topic if publishers else node.get_subscriptions_info_by_topic)(topic)
        return next((info for info in found if info.node_name == "qos_under_test"), None)

    try:
        spin_until(executor, lambda: endpoint("/qos_out", True) and endpoint("/qos_in", False),
                   "the launcher's publisher and subscription")
        published, subscribed = endpoint("/qos_out", True), endpoint("/qos_in", False)
        assert published.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
        assert subscribed.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
    finally:
        process.terminate()
        out, _ = process.communicate(timeout=20)
    assert process.returncode in (0, 130, 143), out
    # The overrides are parameters of the node, not application args: nothing is reported as unknown.
    assert "not <arg>s" not in out, out
