"""The ROS launcher's command line, in-process: argument splitting, node names, --check, errors.

Running applications end to end through the installed script is tested at the workspace level
(test/test_ros_launcher.py); nothing here starts an application or initialises rclpy.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import rclpy

from coco_ros import launcher

APP = """<package name="cli-app">
  <arg name="period" default="10"/>
  <components>
    <component><name>gen</name><task>SignalGenerator</task><library>coco_core</library></component>
    <component><name>avg</name><task>MovingAverage</task><library>coco_core</library></component>
  </components>
  <connections>
    <connection data="BUFFER" policy="LOCKED" buffersize="8">
      <src task="gen" port="sample"/><dest task="avg" port="sample"/>
    </connection>
  </connections>
  <activities>
    <activity name="sampling"><schedule type="periodic" period="$(arg period)"/>
      <components><component name="gen"/></components></activity>
    <activity name="averaging"><schedule type="triggered"/>
      <components><component name="avg"/></components></activity>
  </activities>
</package>
"""


@pytest.fixture(autouse=True)
def ros_domain(monkeypatch: pytest.MonkeyPatch) -> None:
    """Should a regression start ROS, it stays on this test's domain and host."""
    monkeypatch.setenv("ROS_DOMAIN_ID", "94")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


@pytest.fixture
def app_file(tmp_path: Path) -> Path:
    path = tmp_path / "app.xml"
    path.write_text(APP)
    return path


def test_ros_arguments_are_split_off_and_the_rest_parsed_intermixed() -> None:
    argv = ["app.xml", "--duration", "2", "out:=x.csv", "--ros-args", "-r", "__node:=my_coco", "-p", "a:=1"]
    own, ros = launcher.split_ros_args(argv)
    assert own == ["app.xml", "--duration", "2", "out:=x.csv"]
    assert ros == ["--ros-args", "-r", "__node:=my_coco", "-p", "a:=1"]
    options = launcher.make_ros_parser().parse_intermixed_args(own + ["--threads", "a,b", "--threads", "c"])
    assert options.duration == 2.0 and options.args == ["out:=x.csv"]
    assert launcher._threads(options.threads) == ["a", "b", "c"]
    # A section closed by "--" gives the words after it back to the launcher.
    assert launcher.split_ros_args(["app.xml", "--ros-args", "-r", "__node:=n", "--", "--profile", "1"])[0] == \
        ["app.xml", "--profile", "1"]


@pytest.mark.parametrize("name, expected", [
    ("demo_pipeline", "demo_pipeline"), ("cli-app", "cli_app"), ("my app.v2", "my_app_v2"),
    ("2d_viewer", "coco_2d_viewer"), ("", "coco"),
])
def test_node_name_is_a_valid_ros_name(name: str, expected: str) -> None:
    assert launcher.node_name(name) == expected


def test_check_prints_the_tree_and_where_each_activity_runs(app_file: Path, capsys) -> None:
    assert launcher.main([str(app_file), "--check", "--threads", "averaging"]) == 0
    out = capsys.readouterr().out
    assert "application cli-app" in out
    assert "activity sampling: periodic 10 ms -> wait set on its own thread (rclpy timer in its callback group)" in out
    assert "activity averaging: triggered -> own thread (asked on the command line)" in out
    assert launcher.main([str(app_file), "--check", "--executor-threads", "2"]) == 0
    out = capsys.readouterr().out
    assert "activity sampling: periodic 10 ms -> executor (rclpy timer in its callback group)" in out
    assert "activity averaging: triggered -> executor (guard condition in its callback group)" in out


def test_check_writes_the_data_flow_graph_and_refuses_a_bad_path(app_file: Path, tmp_path: Path, capsys) -> None:
    graph = tmp_path / "graph.dot"
    assert launcher.main([str(app_file), "--check", "--graph", str(graph)]) == 0
    assert f"data-flow graph written to {graph}" in capsys.readouterr().out
    text = graph.read_text()
    assert '"activity sampling\\nperiodic 10 ms"' in text
    assert '"component:gen" -> "component:avg" [label="sample -> sample\\nBUFFER/LOCKED[8]"];' in text
    assert launcher.main([str(app_file), "--check", "--graph", str(tmp_path / "no" / "graph.dot")]) == 1
    assert f"--graph {tmp_path / 'no' / 'graph.dot'}: its folder {tmp_path / 'no'} does not exist" in capsys.readouterr().err
    assert not rclpy.ok()


def test_fast_period_is_planned_on_a_thread(app_file: Path, capsys) -> None:
    assert launcher.main([str(app_file), "period:=1", "--check"]) == 0
    out = capsys.readouterr().out
    assert "activity sampling: periodic 1 ms -> own thread (period 1 ms < 5 ms)" in out
    assert "activity averaging: triggered -> wait set on its own thread (guard condition in its callback group)" in out


def test_unknown_thread_name_is_an_error_before_anything_starts(app_file: Path, capsys) -> None:
    assert launcher.main([str(app_file), "--threads", "averagin"]) == 2  # a wrong command line (README)
    err = capsys.readouterr().err
    assert "no activity 'averagin'" in err and "averaging" in err
    assert not rclpy.ok(), "rclpy must not be initialised for a wrong command line"


def test_bad_file_names_file_and_line_and_starts_nothing(tmp_path: Path, capsys) -> None:
    path = tmp_path / "bad.xml"
    path.write_text(APP.replace("<task>MovingAverage</task>", "<task>MovingAvrage</task>"))
    assert launcher.main([str(path), "--duration", "1"]) == 1
    err = capsys.readouterr().err
    assert f"{path}:5:" in err and "MovingAvrage" in err
    assert not rclpy.ok()


@pytest.mark.parametrize("word, said", [("period=1", "argument 'period=1' must look like name:=value"),
                                        ("perod:=1", "arg 'perod' was given (perod:=1) but no file declares it")])
def test_a_wrong_name_value_word_is_a_usage_error(app_file: Path, word: str, said: str, capsys) -> None:
    """Exit 2 (the README's status for a wrong command line), as coco-launch; it was 1."""
    assert launcher.main([str(app_file), word, "--duration", "0.1"]) == 2
    assert said in capsys.readouterr().err
    assert not rclpy.ok()


def test_malformed_ros_args_is_a_usage_error(app_file: Path, capsys) -> None:
    assert launcher.main([str(app_file), "--ros-args", "-r"]) == 2
    assert "malformed --ros-args section" in capsys.readouterr().err
    assert not rclpy.ok()


def test_executor_threads_must_be_positive(app_file: Path, capsys) -> None:
    with pytest.raises(SystemExit) as exited:
        launcher.main([str(app_file), "--executor-threads", "0"])
    assert exited.value.code == 2
    assert "expected a number of threads >= 1" in capsys.readouterr().err


def test_missing_file_argument_is_a_usage_error(capsys) -> None:
    assert launcher.main([]) == 2
    assert "an application file is needed" in capsys.readouterr().err


def test_application_arguments_are_not_taken_for_ros_remap_rules() -> None:
    """rcl reads `name:=value` outside --ros-args as a deprecated remap rule; the launcher must keep
    them for the application's <arg>s and give rcl only the --ros-args sections."""
    from coco_ros.launcher import split_ros_args

    own, ros = split_ros_args(["app.xml", "bag:=/tmp/session", "--ros-args", "-r", "__node:=n",
                               "-p", "gain:=2.0", "--", "--duration", "3", "output:=out/x"])
    assert own == ["app.xml", "bag:=/tmp/session", "--duration", "3", "output:=out/x"]
    assert ros == ["--ros-args", "-r", "__node:=n", "-p", "gain:=2.0"]


def test_a_childs_node_keeps_its_own_name_under_a_node_rename() -> None:
    from coco_ros.child import without_node_renames

    words = ["--ros-args", "-r", "__node:=mine", "--remap", "launcher:__name:=x", "-r", "chatter:=talk", "-p", "a:=1"]
    assert without_node_renames(words) == ["--ros-args", "-r", "chatter:=talk", "-p", "a:=1"]
