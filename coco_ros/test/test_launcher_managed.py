"""The launcher as a managed (lifecycle) node (coco_ros.managed): nothing runs before configure,
configure configures every activity of every process and cycles none, activate runs them,
deactivate holds them until activate runs them again, cleanup and shutdown stop the application
naturally and end the launcher; a transition not valid from the current state is refused. The launcher runs as the
installed script; this test is a real lifecycle client (lifecycle_msgs services) and reads the
activities' cycles on /diagnostics, on its own DDS domain."""

from __future__ import annotations

import csv
import signal
import subprocess
import time
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


def cycles(array: Any) -> dict[str, int]:
    """The cycles of each activity in one /diagnostics array of the launcher's profile."""
    return {status.name.split("activity ")[1]: int(next(kv.value for kv in status.values if kv.key == "cycles"))
            for status in array.status if ": activity " in status.name}


def ended(process: subprocess.Popen[str]) -> str:
    """The launcher's output once it ended (killed after 30 s: a test that failed half-way)."""
    try:
        out, _ = process.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        process.kill()
        out, _ = process.communicate()
    return out


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
        assert state() == "inactive"
        assert transition(Transition.TRANSITION_CLEANUP)
    finally:
        out = ended(process)
    assert process.returncode == 0, out
    assert "lifecycle transition cleanup" in out and "(clean)" in out, out
    assert len(list(csv.reader(output.open()))) > 2, "the recorder flushed its rows"


def test_managed_needs_the_default_hosting(tmp_path: Path) -> None:
    app = tmp_path / "app.xml"
    app.write_text(APP)
    refused = subprocess.run(launcher_command(str(app), "output:=x.csv", "--managed", "--executor-threads", "1"),
                             capture_output=True, text=True, timeout=60, env=ros_env(DOMAIN))
    assert refused.returncode == 2 and "--managed needs the default hosting" in refused.stderr


REFUSING = "63"


@pytest.fixture
def refusing_peer(monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[Any, Any]]:
    yield from rclpy_peer(monkeypatch, REFUSING, "lifecycle_refusing_peer")


def test_an_invalid_transition_is_refused_and_a_deactivated_application_activates_again(
        tmp_path: Path, refusing_peer: tuple[Any, Any]) -> None:
    """What ``ros2 lifecycle set`` does, through the node's lifecycle services: activate before
    configure, configure twice and configure while active are refused with the valid transitions
    named, and the application runs on (with rclpy 7.1.6 alone the service never answered, the
    launcher logged "the ROS executor failed", stopped the application and exited 0); deactivate
    holds every activity, the child process's too, and activate runs them again (deactivate used to
    end the launcher)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState, GetAvailableTransitions, GetState

    node, executor = refusing_peer
    arrays: list[Any] = []
    node.create_subscription(DiagnosticArray, "/diagnostics", arrays.append, 10)
    process = start_launcher(tmp_path / "managed.xml", IN_PROCESSES, f"output:={tmp_path / 'rows.csv'}", "--managed",
                             "--ros-args", "-p", "diagnostics.period:=0.2", "-r", "__node:=refusing_under_test",
                             domain=REFUSING)
    get_state = node.create_client(GetState, "/refusing_under_test/get_state")
    change = node.create_client(ChangeState, "/refusing_under_test/change_state")
    available = node.create_client(GetAvailableTransitions, "/refusing_under_test/get_available_transitions")

    def state() -> str:
        return call_service(executor, get_state, GetState.Request()).current_state.label

    def transition(id: int = 0, label: str = "") -> bool:
        request = ChangeState.Request(transition=Transition(id=id, label=label))
        return call_service(executor, change, request).success

    def valid() -> list[str]:
        answer = call_service(executor, available, GetAvailableTransitions.Request())
        return [each.transition.label for each in answer.available_transitions]

    def sampled(activity: str = "sampling") -> int:
        return max((cycles(a).get(activity, 0) for a in arrays), default=0)

    def profiles_after(seen: int, count: int) -> list[Any]:
        """``count`` profiles of the three activities published after the first ``seen``."""
        complete = lambda: [a for a in arrays[seen:] if len(cycles(a)) == 3]  # noqa: E731
        return spin_until(executor, lambda: complete()[count - 1:] and complete(), f"{count} profiles")

    try:
        spin_until(executor, lambda: all(c.service_is_ready() for c in (get_state, change, available)),
                   "the launcher's lifecycle services")
        assert valid() == ["configure", "shutdown"]
        assert not transition(Transition.TRANSITION_ACTIVATE), "activate before configure"
        assert state() == "unconfigured"
        assert transition(Transition.TRANSITION_CONFIGURE)
        assert not transition(Transition.TRANSITION_CONFIGURE), "configure twice"
        assert state() == "inactive"
        assert transition(Transition.TRANSITION_ACTIVATE)
        spin_until(executor, lambda: sampled() > 0, "cycles after activate")
        assert not transition(Transition.TRANSITION_CONFIGURE), "configure while active"
        assert not transition(label="cleanup"), "cleanup while active, by label"
        assert state() == "active" and process.poll() is None, "the application runs on"
        before = sampled()
        spin_until(executor, lambda: sampled() > before, "cycles after the refused transitions")
        assert transition(Transition.TRANSITION_DEACTIVATE)
        assert state() == "inactive" and valid() == ["cleanup", "activate", "shutdown"]
        held = profiles_after(len(arrays), 3)  # the first may have been taken before the child held
        assert cycles(held[1]) == cycles(held[2]), "no activity cycles while inactive, in either process"
        assert transition(Transition.TRANSITION_ACTIVATE), "a deactivated node activates again"
        spin_until(executor, lambda: sampled() > cycles(held[2])["sampling"]
                   and sampled("recording") > cycles(held[2])["recording"], "cycles in both processes again")
        assert transition(label="shutdown")
    finally:
        out = ended(process)
    assert process.returncode == 0, out
    assert "the ROS executor failed" not in out, out
    assert "lifecycle transition 3 refused: not valid from state unconfigured; valid: configure (1), shutdown (5)" in out
    assert "lifecycle transition 1 refused: not valid from state inactive; valid:" in out
    assert "lifecycle transition cleanup refused: not valid from state active; valid: deactivate (4), shutdown (7)" in out
    assert "application param_app active again" in out and "(clean)" in out, out


def test_sigint_then_sigterm_while_configured_and_not_running_is_one_clean_stop(
        tmp_path: Path, refusing_peer: tuple[Any, Any]) -> None:
    """ros2 launch's burst (SIGINT, then SIGTERM) at a managed launcher that is configured, every
    activity of both processes waiting for activate: one clean stop, exit 0, within the second a
    stop takes (a second signal used to wait in its handler for a lock the first one's held)."""
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState

    node, executor = refusing_peer
    process = start_launcher(tmp_path / "managed.xml", IN_PROCESSES, f"output:={tmp_path / 'rows.csv'}", "--managed",
                             "--ros-args", "-r", "__node:=burst_under_test", domain=REFUSING)
    change = node.create_client(ChangeState, "/burst_under_test/change_state")
    try:
        spin_until(executor, change.service_is_ready, "the launcher's lifecycle services")
        configure = ChangeState.Request(transition=Transition(id=Transition.TRANSITION_CONFIGURE))
        assert call_service(executor, change, configure).success
        sent = time.monotonic()
        process.send_signal(signal.SIGINT)
        process.send_signal(signal.SIGTERM)
    finally:
        out = ended(process)
    assert process.returncode == 0, out
    assert time.monotonic() - sent < 4.0, out  # a stop's second and the interpreters' exits
    assert "stopping application param_app: received SIGINT" in out and "(clean)" in out, out
    assert "Traceback" not in out, out
