"""The ROS 2 launcher node, run through the installed ``lib/coco_ros/launcher`` as ``ros2 run`` does."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import ROOT, check_ctrl_c_stops_within_a_second_and_flushes, read_rows, run_launcher, start_launcher

APP = "config/demo_pipeline.xml"

PROBE = """
import sys, time
import rclpy
rclpy.init()
node = rclpy.create_node("coco_test_probe")
deadline = time.monotonic() + float(sys.argv[2])
names = []
while time.monotonic() < deadline:
    names = node.get_node_names()
    if sys.argv[1] in names:
        break
    time.sleep(0.1)
print("nodes:", " ".join(sorted(names)))
node.destroy_node()
rclpy.shutdown()
"""


@pytest.fixture(scope="session")
def ros_launcher() -> Path:
    """The installed launcher node, where ``ros2 run coco_ros launcher`` finds it."""
    script = ROOT / "install" / "coco_ros" / "lib" / "coco_ros" / "launcher"
    if not script.exists():
        pytest.fail(f"{script} is missing: build the workspace first (scripts/setup.sh does)")
    return script


@pytest.fixture(autouse=True)
def ros_domain(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every launcher and probe of these tests talks on its own domain, on this host only."""
    monkeypatch.setenv("ROS_DOMAIN_ID", "95")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")



def test_demo_runs_in_the_node_with_profile_and_output(ros_launcher: Path, tmp_path: Path) -> None:
    output = tmp_path / "x.csv"
    result = run_launcher(ros_launcher, APP, "--duration", "3", "--profile", "1", f"output:={output}")
    assert result.returncode == 0, result.stderr
    report = result.stdout
    assert "Profile of application 'demo_pipeline'" in report
    for name in ("acquisition", "filtering", "recording", "supervision (main)", "generator", "filter",
                 "recorder", "monitor (peer)", "supervisor"):
        assert name in report, f"{name} missing from the profile:\n{report}"
    # Hosted periodic activities report their timer's period error.
    assert re.search(r"acquisition\s+periodic 10 ms\s+\d+\s+\d+\s+[0-9.]+ / [0-9.]+ / [0-9.]+", report), report
    log = result.stderr
    assert "node /demo_pipeline hosts application demo_pipeline" in log
    assert "activity acquisition: periodic 10 ms -> wait set on its own thread (rclpy timer in its callback group)" in log
    assert "activity filtering: triggered -> wait set on its own thread (guard condition in its callback group)" in log
    assert "activity supervision: periodic 1000 ms -> main thread (main activity)" in log
    rows = read_rows(output)
    assert len(rows) > 100, f"only {len(rows)} rows in 3 s at 100 Hz"
    seqs = [int(row["seq"]) for row in rows]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    # The supervisor (main thread) reached the filter (its wait set) through a queued operation.
    assert "supervisor: filter.set_window -> previous value 8" in log


def test_node_name_is_remapped_by_ros_args(ros_launcher: Path, tmp_path: Path) -> None:
    process = start_launcher(ros_launcher, APP, f"output:={tmp_path / 'x.csv'}", "--duration", "30",
                             "--ros-args", "-r", "__node:=my_coco")
    try:
        probe = subprocess.run([sys.executable, "-c", PROBE, "my_coco", "15"], capture_output=True, text=True,
                               timeout=60)
        process.send_signal(signal.SIGINT)
        out, _ = process.communicate(timeout=10)
    finally:
        process.kill()
    assert probe.returncode == 0, probe.stderr
    names = probe.stdout.split("nodes:", 1)[-1].split()
    assert "my_coco" in names, f"the probe saw {names}; launcher said:\n{out}"
    assert "demo_pipeline" not in names
    assert "node /my_coco hosts application demo_pipeline" in out
    assert process.returncode == 0, out


def test_ctrl_c_stops_within_a_second_and_flushes(ros_launcher: Path, tmp_path: Path) -> None:
    check_ctrl_c_stops_within_a_second_and_flushes(ros_launcher, tmp_path)


def test_all_threads_runs_like_coco_launch(ros_launcher: Path, tmp_path: Path) -> None:
    output = tmp_path / "x.csv"
    result = run_launcher(ros_launcher, APP, f"output:={output}", "--duration", "1.5", "--all-threads")
    assert result.returncode == 0, result.stderr
    assert "activity acquisition: periodic 10 ms -> own thread (asked on the command line)" in result.stderr
    assert len(read_rows(output)) > 50


def test_bad_file_gives_file_line_and_exit_1(ros_launcher: Path, tmp_path: Path) -> None:
    app = tmp_path / "broken.xml"
    output = tmp_path / "never.csv"
    app.write_text((ROOT / APP).read_text()
                   .replace("<task>MovingAverage</task>", "<task>MovingAvg</task>")
                   .replace("$(arg output)", str(output)))
    lines = app.read_text().splitlines()
    task = next(number for number, text in enumerate(lines, 1) if "MovingAvg" in text)
    element = max(number for number, text in enumerate(lines[:task], 1) if "<component>" in text)
    result = run_launcher(ros_launcher, str(app), "--ros-args", "-r", "__node:=never")
    assert result.returncode == 1
    # The error names the <component> element that asks for the unknown task, and the right name.
    assert f"{app}:{element}: unknown component 'MovingAvg'" in result.stderr, result.stderr
    assert "did you mean 'MovingAverage'" in result.stderr
    assert not output.exists(), "nothing may start when the file is wrong"
    assert "hosts application" not in result.stderr


CHILD_APP = """<package name="procs">
  <components>
    <component><name>generator</name><task>SignalGenerator</task></component>
    <component><name>bridge</name><task>ROSInterface</task><library>coco_ros</library>
      <attributes><attribute name="publish" value="value=/coco_test/child_signal:std_msgs/msg/Float64;depth=50"/></attributes>
    </component>
  </components>
  <connections>
    <connection data="BUFFER" policy="LOCKED" buffersize="50"><src task="generator" port="sample"/><dest task="bridge" port="value"/></connection>
  </connections>
  <activities>
    <process name="publisher">
      <activity name="ticks"><schedule type="periodic" period="10"/>
        <components><component name="generator"/><component name="bridge"/></components></activity>
    </process>
  </activities>
</package>
"""

LISTENER = """
import sys, time
import rclpy
from std_msgs.msg import Float64
rclpy.init()
node = rclpy.create_node("coco_test_listener")
received = []
node.create_subscription(Float64, "/coco_test/child_signal", lambda m: received.append(m.data), 50)
deadline = time.monotonic() + float(sys.argv[1])
while time.monotonic() < deadline and len(received) < 50:
    rclpy.spin_once(node, timeout_sec=0.1)
print("nodes:", " ".join(sorted(node.get_node_names())))
print("received:", len(received))
node.destroy_node()
rclpy.shutdown()
"""


def test_a_child_process_hosts_ros_components_in_a_node_of_its_own(ros_launcher: Path, tmp_path: Path) -> None:
    app = tmp_path / "procs.xml"
    app.write_text(CHILD_APP)
    process = start_launcher(ros_launcher, str(app), "--duration", "30")
    try:
        listener = subprocess.run([sys.executable, "-c", LISTENER, "20"], capture_output=True, text=True, timeout=60)
    finally:
        process.send_signal(signal.SIGINT)
        out, _ = process.communicate(timeout=30)
    assert process.returncode == 0, out
    assert "received: 50" in listener.stdout, listener.stdout + listener.stderr
    assert "procs_publisher" in listener.stdout.split("received:")[0], listener.stdout
