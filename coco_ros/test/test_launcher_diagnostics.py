"""The profile on /diagnostics (coco_ros.diagnostics): a status per activity, component, connection
and process, levels from what changed since the last array, thresholds changed live by ``ros2 param
set``, the period read-only. The launcher runs as the installed script; this test is a real rclpy
subscriber and parameter client on its own DDS domain."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Iterator

import pytest

from conftest import rclpy_peer
from test_launcher_parameters import APP, spin_until, start_launcher

DOMAIN = "42"
# The recorder reads the average every 50 ms through a DATA connection (newest only) while it comes
# at 100 Hz: the connection drops about 4 samples in 5, which must show as a WARN.
DROPPING = APP.replace('''<connection data="BUFFER" policy="LOCKED" buffersize="64">
      <src task="avg" port="filtered"/>''', '''<connection data="DATA" policy="LOCKED">
      <src task="avg" port="filtered"/>''')


@pytest.fixture
def peer(monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[Any, Any]]:
    yield from rclpy_peer(monkeypatch, DOMAIN, "diagnostics_peer")


def test_the_profile_reaches_diagnostics_with_levels_and_live_thresholds(tmp_path: Path, peer: tuple[Any, Any]) -> None:
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient

    assert "DATA" in DROPPING
    node, executor = peer
    arrays: list[Any] = []
    node.create_subscription(DiagnosticArray, "/diagnostics", arrays.append, 10)
    process = start_launcher(tmp_path / "dropping.xml", DROPPING, f"output:={tmp_path / 'rows.csv'}", "--duration", "60",
                             "--ros-args", "-p", "diagnostics.period:=0.2", "-r", "__node:=diag_under_test", domain=DOMAIN)

    def wait_for(condition: Callable[[], Any], what: str) -> Any:
        return spin_until(executor, condition, what)

    def status(array: Any, name: str) -> Any:
        return next((s for s in array.status if s.name == f"coco/param_app: {name}"), None)

    connection = "connection avg.filtered -> rec.values"
    try:
        warned = wait_for(lambda: next((a for a in arrays if (s := status(a, connection)) is not None
                                        and s.level == DiagnosticStatus.WARN), None), "a WARN for the dropping connection")
        dropping = status(warned, connection)
        assert "samples dropped since the last report" in dropping.message
        assert {kv.key for kv in dropping.values} >= {"written", "read", "dropped", "pending"}
        # (An activity's level depends on the machine's load: only its presence is checked.)
        assert {kv.key for kv in status(warned, "activity sampling").values} >= {"cycles", "overruns"}
        assert status(warned, "component avg").level == DiagnosticStatus.OK
        assert status(warned, "process launcher") is not None

        client = AsyncParameterClient(node, "diag_under_test")
        wait_for(client.services_are_ready, "the launcher's parameter services")
        future = client.set_parameters([Parameter("diagnostics.drops_warn", value=1_000_000)])
        wait_for(future.done, "the answer to set diagnostics.drops_warn")
        assert future.result().results[0].successful
        seen = len(arrays)
        wait_for(lambda: any(status(a, connection).level == DiagnosticStatus.OK for a in arrays[seen + 1:]),
                 "the connection back to OK under the new threshold")
        refused = client.set_parameters([Parameter("diagnostics.period", value=5.0)])
        wait_for(refused.done, "the answer to set diagnostics.period")
        assert not refused.result().results[0].successful
        assert "read when the launcher starts" in refused.result().results[0].reason
        nan = client.set_parameters([Parameter("diagnostics.period_error_warn_us", value=float("nan"))])
        wait_for(nan.done, "the answer to set diagnostics.period_error_warn_us to NaN")
        assert not nan.result().results[0].successful, "NaN would make every comparison false: never WARN"
        assert "must be a finite number >= 0, got nan" in nan.result().results[0].reason
    finally:
        process.terminate()
        out, _ = process.communicate(timeout=20)
    assert process.returncode in (0, 130, 143), out


@pytest.mark.parametrize("name,value", [("diagnostics.period_error_warn_us", float("nan")),
                                        ("diagnostics.drops_warn", float("inf")), ("diagnostics.period", -1.0)])
def test_a_threshold_given_at_the_start_is_checked_too(peer: tuple[Any, Any], name: str, value: float) -> None:
    """``-p NAME:=VALUE`` declares the parameter before the change callback exists: checked apart."""
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from coco_core.errors import CocoError
    from coco_ros.diagnostics import ProfileDiagnostics

    node = Node("diag_start", context=peer[0].context, parameter_overrides=[Parameter(name, value=value)],
                automatically_declare_parameters_from_overrides=True)
    try:
        with pytest.raises(CocoError, match=rf"-p {name}:={value!r}: expected a finite number >= 0"):
            ProfileDiagnostics(node, "app", lambda: [])
    finally:
        node.destroy_node()
