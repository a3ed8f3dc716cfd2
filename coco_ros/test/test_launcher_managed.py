"""The launcher as a managed (lifecycle) node (coco_ros.managed): nothing runs before configure,
configure configures every activity of every process and cycles none, activate runs them,
deactivate stops the application naturally and ends the launcher. The launcher runs as the
installed script; this test is a real lifecycle client (lifecycle_msgs services) and reads the
activities' cycles on /diagnostics, on its own DDS domain."""

from __future__ import annotations

import csv
import subprocess
from pathlib import Path
from typing import Any, Iterator

import pytest

from conftest import rclpy_peer
from test_launcher_parameters import APP, call_service, launcher_command, ros_env, spin_until, start_launcher

DOMAIN = "47"
# The recorder in a child process: configure and activate reach every process.
IN_PROCESSES = APP.replace('<activity name="recording">', '<process name="worker"><activity name="recording">').replace(
    '<components><component name="rec"/></components></activity>',
    '<components><component name="rec"/></components></activity></process>')


@pytest.fixture
def peer(monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[Any, Any]]:
    yield from rclpy_peer(monkeypatch, DOMAIN, "lifecycle_peer")


def test_configure_then_activate_then_deactivate(tmp_path: Path, peer: tuple[Any, Any]) -> None:
    from diagnostic_msgs.msg import DiagnosticArray
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState, GetState

    assert "<process" in IN_PROCESSES
    node, executor = peer
    arrays: list[Any] = []
    node.create_subscription(DiagnosticArray, "/diagnostics", arrays.append, 10)
    output = tmp_path / "rows.csv"
    process = start_launcher(tmp_path / "managed.xml", IN_PROCESSES, f"output:={output}", "--managed", "--ros-args",
                             "-p", "diagnostics.period:=0.2", "-r", "__node:=managed_under_test", domain=DOMAIN)
    get_state = node.create_client(GetState, "/managed_under_test/get_state")
    change = node.create_client(ChangeState, "/managed_under_test/change_state")

    def answer(client: Any, request: Any) -> Any:
        return call_service(executor, client, request)

    def state() -> str:
        return answer(get_state, GetState.Request()).current_state.label

    def transition(id: int) -> bool:
        return answer(change, ChangeState.Request(transition=Transition(id=id))).success

    def cycles(array: Any) -> dict[str, int]:
        return {status.name.split("activity ")[1]: int(next(kv.value for kv in status.values if kv.key == "cycles"))
                for status in array.status if ": activity " in status.name}

    try:
        spin_until(executor, lambda: get_state.service_is_ready() and change.service_is_ready(),
                   "the launcher's lifecycle services")
        assert state() == "unconfigured"
        assert transition(Transition.TRANSITION_CONFIGURE)
        assert state() == "inactive"
        seen = len(arrays)
        configured = spin_until(executor, lambda: next((a for a in arrays[seen:] if len(cycles(a)) == 3), None),
                                "a profile of the three activities after configure")
        assert cycles(configured) == {"sampling": 0, "averaging": 0, "recording": 0}, "nothing cycles before activate"
        assert transition(Transition.TRANSITION_ACTIVATE)
        assert state() == "active"
        spin_until(executor, lambda: any(cycles(a).get("recording", 0) > 0 and cycles(a).get("sampling", 0) > 0
                                         for a in arrays), "cycles of the launcher's and the child's activities")
        assert transition(Transition.TRANSITION_DEACTIVATE)
    finally:
        try:
            out, _ = process.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()
            out, _ = process.communicate()
    assert process.returncode == 0, out
    assert "lifecycle transition deactivate" in out and "(clean)" in out, out
    assert len(list(csv.reader(output.open()))) > 2, "the recorder flushed its rows"


def test_managed_needs_the_default_hosting(tmp_path: Path) -> None:
    app = tmp_path / "app.xml"
    app.write_text(APP)
    refused = subprocess.run(launcher_command(str(app), "output:=x.csv", "--managed", "--executor-threads", "1"),
                             capture_output=True, text=True, timeout=60, env=ros_env(DOMAIN))
    assert refused.returncode == 2 and "--managed needs the default hosting" in refused.stderr
