"""The application's operations as ROS services (coco_ros.operation_services): any operation by name
through ~/call_operation (coco_interfaces/srv/CallOperation), also of a component in a child process,
and every operation without arguments as a std_srvs/Trigger. The launcher runs as the installed
script; this test is a real rclpy service client on its own DDS domain."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator

import pytest

from conftest import rclpy_peer
from test_launcher_parameters import call_service, spin_until, start_launcher

DOMAIN = "46"
APP = """<package name="ops_app">
  <components>
    <component><name>gen</name><task>SignalGenerator</task><library>coco_core</library></component>
    <component><name>avg</name><task>MovingAverage</task><library>coco_core</library>
      <attributes><attribute name="window" value="4"/></attributes></component>
    <component><name>bridge</name><task>ROSInterface</task><library>coco_ros</library>
      <attributes><attribute name="publish" value="average=ops_average:std_msgs/msg/Float64"/></attributes></component>
  </components>
  <connections>
    <connection data="BUFFER" policy="LOCKED" buffersize="64">
      <src task="gen" port="sample"/><dest task="avg" port="sample"/></connection>
    <connection data="BUFFER" policy="LOCKED" buffersize="64">
      <src task="avg" port="filtered"/><dest task="bridge" port="average"/></connection>
  </connections>
  <activities>
    <activity name="sampling"><schedule type="periodic" period="10"/>
      <components><component name="gen"/></components></activity>
    <process name="worker">
      <activity name="averaging"><schedule type="triggered"/>
        <components><component name="avg"/></components></activity>
    </process>
    <activity name="bridging"><schedule type="triggered"/>
      <components><component name="bridge"/></components></activity>
  </activities>
</package>
"""


@pytest.fixture
def peer(monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[Any, Any]]:
    yield from rclpy_peer(monkeypatch, DOMAIN, "operations_peer")


def test_operations_are_services_of_the_launchers_node(tmp_path: Path, peer: tuple[Any, Any]) -> None:
    from coco_interfaces.srv import CallOperation
    from std_srvs.srv import Trigger

    node, executor = peer
    process = start_launcher(tmp_path / "ops_app.xml", APP, "--duration", "60", "--ros-args", "-r",
                             "__node:=ops_under_test", domain=DOMAIN)
    call = node.create_client(CallOperation, "/ops_under_test/call_operation")
    counts = node.create_client(Trigger, "/ops_under_test/bridge/counts")

    def answer(client: Any, request: Any) -> Any:
        return call_service(executor, client, request)

    try:
        spin_until(executor, lambda: call.service_is_ready() and counts.service_is_ready(),
                   "the launcher's operation services")
        # An operation of a component in the child process, with an argument: it returns the old window.
        done = answer(call, CallOperation.Request(component="avg", operation="set_window", arguments="[3]"))
        assert done.success and done.result == "4" and not done.error, done
        done = answer(call, CallOperation.Request(component="avg", operation="get_attribute", arguments="{name: window}"))
        assert done.success and done.result == "3", done
        # What cannot run says why.
        unknown = answer(call, CallOperation.Request(component="avgg", operation="set_window", arguments="3"))
        assert not unknown.success and "no component 'avgg'" in unknown.error and "avg" in unknown.error
        wrong = answer(call, CallOperation.Request(component="avg", operation="set_windw", arguments="3"))
        assert not wrong.success and "set_window" in wrong.error, wrong
        bad = answer(call, CallOperation.Request(component="avg", operation="set_window", arguments="[1, 2, 3]"))
        assert not bad.success and "TypeError" in bad.error, bad
        # Hostile requests: refused at once with the limit, quoted only in part (reply and log).
        huge = answer(call, CallOperation.Request(component="avg", operation="set_window", arguments="w" * 2_000_000))
        assert not huge.success and "have 2000000 bytes, more than the limit of 65536" in huge.error, huge.error[:300]
        assert len(huge.error) < 300, huge.error[:300]
        named = answer(call, CallOperation.Request(component="x" * 1_000_000, operation="set_window", arguments="3"))
        assert not named.success and "longer than the limit of 256 characters" in named.error, named.error[:300]
        assert len(named.error) < 300, named.error[:300]
        quoted = answer(call, CallOperation.Request(component="avg", operation="set_window",
                                                    arguments="'" + "w" * 60_000 + "'"))
        assert not quoted.success and "expected an integer" in quoted.error and len(quoted.error) < 1200, \
            quoted.error[:300]
        absurd = answer(call, CallOperation.Request(component="avg", operation="set_window", arguments=str(10**12)))
        assert not absurd.success and "expected <= 100000, got 1000000000000" in absurd.error, absurd.error
        # An operation without arguments is a Trigger too.
        triggered = answer(counts, Trigger.Request())
        assert triggered.success and triggered.message, triggered
    finally:
        process.terminate()
        out, _ = process.communicate(timeout=20)
    assert process.returncode in (0, 130, 143), out
    assert max(map(len, out.splitlines())) < 2000, "a request was echoed whole into the log"
