"""The application's ``<arg>``s as ROS parameters of the launcher's node (coco_ros.parameters):
``-p`` and ``--params-file`` set them below ``name:=value``, ``ros2 param get`` reads what runs, and
``ros2 param set`` on an arg is refused (the args are read-only, their descriptors say how to change
them and carry their ranges), never accepted and ignored.

The launcher runs as the installed script in a subprocess; the other side is a real rclpy parameter
client of this test on its own DDS domain (localhost only)."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Callable, Iterator

import pytest

from coco_ros.parameters import arg_text, typed_value

from conftest import rclpy_peer

APP = """<package name="param_app">
  <arg name="output" doc="CSV file the recorder writes"/>
  <arg name="window" default="4" min="1" max="64" doc="moving-average window"/>
  <arg name="mode" default="fast" doc="a choice"><choice value="fast"/><choice value="slow"/></arg>
  <arg name="fixed" value="1.5"/>
  <components>
    <component><name>gen</name><task>SignalGenerator</task><library>coco_core</library></component>
    <component><name>avg</name><task>MovingAverage</task><library>coco_core</library>
      <attributes><attribute name="window" value="$(arg window)"/></attributes></component>
    <component><name>rec</name><task>CsvRecorder</task><library>coco_core</library>
      <attributes><attribute name="path" value="$(arg output)"/></attributes></component>
  </components>
  <connections>
    <connection data="BUFFER" policy="LOCKED" buffersize="64">
      <src task="gen" port="sample"/><dest task="avg" port="sample"/></connection>
    <connection data="BUFFER" policy="LOCKED" buffersize="64">
      <src task="avg" port="filtered"/><dest task="rec" port="values"/></connection>
  </connections>
  <activities>
    <activity name="sampling"><schedule type="periodic" period="10"/>
      <components><component name="gen"/></components></activity>
    <activity name="averaging"><schedule type="triggered"/>
      <components><component name="avg"/></components></activity>
    <activity name="recording"><schedule type="periodic" period="50"/>
      <components><component name="rec"/></components></activity>
  </activities>
</package>
"""
DOMAIN = "41"
WORKSPACE = Path(__file__).resolve().parents[2]
LAUNCHER = WORKSPACE / "install" / "coco_ros" / "lib" / "coco_ros" / "launcher"


def launcher_command(*words: str) -> list[str]:
    if not LAUNCHER.exists():
        pytest.skip(f"{LAUNCHER} is missing: build the workspace first (scripts/setup.sh)")
    return [str(LAUNCHER), *words]


def ros_env(domain: str = DOMAIN) -> dict[str, str]:
    """The launcher's environment: its own DDS domain (the test's), this host only."""
    return {**os.environ, "ROS_DOMAIN_ID": domain, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "PYTHONUNBUFFERED": "1"}


def start_launcher(app: Path, text: str, *words: str, domain: str) -> subprocess.Popen[str]:
    """Write the application ``text`` to ``app`` and start the installed launcher on it with
    ``words``, on DDS ``domain`` (the test's peer's)."""
    app.write_text(text)
    return subprocess.Popen(launcher_command(str(app), *words), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, env=ros_env(domain))


def spin_until(executor: Any, condition: Callable[[], Any], what: str, seconds: float = 30) -> Any:
    """Spin the test's peer until ``condition()`` gives something true (returned), or fail naming ``what``."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        found = condition()
        if found:
            return found
        executor.spin_once(timeout_sec=0.1)
    raise AssertionError(f"{what} never came within {seconds:g} s")


def call_service(executor: Any, client: Any, request: Any) -> Any:
    """The launcher's answer to ``request`` on the service ``client`` serves, the peer spinning meanwhile."""
    future = client.call_async(request)
    spin_until(executor, future.done, f"an answer to {request}")
    return future.result()


@pytest.fixture
def app_file(tmp_path: Path) -> Path:
    path = tmp_path / "param_app.xml"
    path.write_text(APP)
    return path


@pytest.fixture
def peer(monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[Any, Any]]:
    yield from rclpy_peer(monkeypatch, DOMAIN, "parameter_peer")


def test_arg_texts_and_parameter_values_convert_both_ways() -> None:
    assert typed_value("true") is True and typed_value("False") is False
    assert typed_value("4") == 4 and isinstance(typed_value("4"), int)
    assert typed_value("1.5") == 1.5 and typed_value("nan") == "nan"
    assert typed_value("out/x.csv") == "out/x.csv"
    for text in ("true", "4", "1.5", "out/x.csv"):
        assert arg_text("a", typed_value(text)) == text
    with pytest.raises(Exception, match="not an array"):
        arg_text("a", [1, 2])


def test_p_and_params_file_give_the_files_args_and_the_command_line_wins(app_file: Path, tmp_path: Path) -> None:
    # --check: a -p value reaches the arg (a choice it does not allow is refused, naming the arg).
    checked = subprocess.run(launcher_command(str(app_file), "output:=x.csv", "--check", "--ros-args", "-p", "mode:=medium"),
                             capture_output=True, text=True, timeout=60, env=ros_env())
    assert checked.returncode == 1 and "arg 'mode' is 'medium'; expected one of: fast, slow" in checked.stderr
    # A required arg given by a params file only; name:=value wins over -p for window.
    by_param = tmp_path / "by_param.csv"
    params = tmp_path / "params.yaml"
    params.write_text(f"/**:\n  ros__parameters:\n    output: {by_param}\n    window: 2\n    gian: 3\n")
    run = subprocess.run(launcher_command(str(app_file), "window:=3", "--duration", "1", "--ros-args",
                                          "--params-file", str(params), "-p", "window:=5"),
                         capture_output=True, text=True, timeout=60, env=ros_env())
    assert run.returncode == 0, run.stdout + run.stderr
    assert by_param.is_file() and len(list(csv.reader(by_param.open()))) > 2
    # A parameter no arg takes is reported (a typo would otherwise change nothing, silently).
    assert "parameters gian set with -p or --params-file are not <arg>s of application param_app" in run.stderr
    assert "valid: fixed, mode, output, window" in run.stderr


def test_param_get_reads_what_runs_and_param_set_on_an_arg_is_refused(app_file: Path, tmp_path: Path,
                                                                       peer: tuple[Any, Any]) -> None:
    from rcl_interfaces.msg import ParameterType
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient

    node, executor = peer
    output = tmp_path / "rows.csv"
    process = subprocess.Popen(launcher_command(str(app_file), f"output:={output}", "window:=6", "--duration", "60",
                                                "--ros-args", "-p", "window:=2", "-r", "__node:=params_under_test"),
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=ros_env())
    try:
        client = AsyncParameterClient(node, "params_under_test")
        deadline = time.monotonic() + 30
        while not client.services_are_ready() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        assert client.services_are_ready(), "the launcher's parameter services never appeared"

        def done(request: Any) -> Any:
            """The answer to ``request()``, asked again when none came: services_are_ready() says the
            client found the service, not that the service found the client's reply topic yet (DDS
            discovers each direction on its own), and a request answered before that gets its answer
            lost (seen once in a fresh-clone run on a loaded machine)."""
            for _ in range(3):
                future = request()
                end = time.monotonic() + 5
                while not future.done() and time.monotonic() < end:
                    executor.spin_once(timeout_sec=0.1)
                if future.done():
                    return future.result()
            raise AssertionError("the launcher's parameter service did not answer three requests")

        values = done(lambda: client.get_parameters(["output", "window", "mode", "fixed"])).values
        assert values[0].type == ParameterType.PARAMETER_STRING and values[0].string_value == str(output)
        # name:=value won over -p, and the node says so.
        assert values[1].type == ParameterType.PARAMETER_INTEGER and values[1].integer_value == 6
        assert values[2].string_value == "fast" and values[3].double_value == 1.5
        described = done(lambda: client.describe_parameters(["mode"])).descriptors[0]
        assert described.description == "a choice" and "fast, slow" in described.additional_constraints
        window = done(lambda: client.describe_parameters(["window"])).descriptors[0]
        assert window.read_only and "read when it was built" in window.additional_constraints
        assert "window:=VALUE" in window.additional_constraints
        assert (window.integer_range[0].from_value, window.integer_range[0].to_value) == (1, 64)
        result = done(lambda: client.set_parameters([Parameter("window", value=9)])).results[0]
        assert not result.successful and "read-only" in result.reason
        assert done(lambda: client.get_parameters(["window"])).values[0].integer_value == 6
        # The node's own parameters stay rclpy's.
        assert done(lambda: client.set_parameters([Parameter("use_sim_time", value=False)])).results[0].successful
    finally:
        process.terminate()
        out, _ = process.communicate(timeout=20)
    assert process.returncode in (0, 130, 143), out
    assert output.is_file()


def test_log_lines_reach_rosout_with_their_severity_and_each_processs_node_name(
        app_file: Path, tmp_path: Path, peer: tuple[Any, Any]) -> None:
    from rcl_interfaces.msg import Log
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    node, executor = peer
    received: list[Any] = []
    node.create_subscription(Log, "/rosout", received.append, QoSProfile(
        depth=1000, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    # The recorder in a child process of its own: its lines come from its own node.
    in_process = tmp_path / "in_process.xml"
    in_process.write_text(app_file.read_text().replace(
        '<activity name="recording">', '<process name="worker"><activity name="recording">').replace(
        '<components><component name="rec"/></components></activity>',
        '<components><component name="rec"/></components></activity></process>'))
    process = start_launcher(in_process, in_process.read_text(), f"output:={tmp_path / 'rows.csv'}", "--duration", "60",
                             "--ros-args", "-p", "gian:=3", "-r", "__node:=logs_under_test", domain=DOMAIN)

    def names() -> set[str]:
        return {message.name for message in received}

    def worker_publishes() -> bool:
        return any(info.node_name == "logs_under_test_worker" for info in node.get_publishers_info_by_topic("/rosout"))

    try:
        spin_until(executor, lambda: "logs_under_test.coco.parameters" in names() and worker_publishes(),
                   "the launcher's warning and the child's /rosout publisher")
        # The child's lines come when the application stops: stop it once both ends know each other.
        process.send_signal(signal.SIGINT)
        spin_until(executor, lambda: any(name.startswith("logs_under_test_worker.") for name in names()),
                   "the child's log lines")
    finally:
        out, _ = process.communicate(timeout=30)
    assert process.returncode == 0, out
    warning = next(message for message in received if message.name == "logs_under_test.coco.parameters")
    assert warning.level == Log.WARN and "gian" in warning.msg and warning.line > 0 and warning.file.endswith(".py")
    assert any(message.level == Log.INFO for message in received if message.name == "logs_under_test.coco")
    assert any(name.startswith("logs_under_test_worker.") for name in names()), sorted(names())
    # The console keeps its lines.
    assert "[WARNING] coco.parameters: parameters gian" in out


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q"]))
