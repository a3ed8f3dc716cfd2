"""Applications over two hosts, each a network namespace of this machine with real DDS over UDP
between them (``test/netns.py``), run by the installed launchers as on two machines: the same file,
one more argument (``--host NAME``).

- the demo pipeline over two hosts: every sample crosses, counted on both sides, the supervisor's
  operation calls reach the filter on the other host, and the second host's clock is measured;
- the Baxter teleoperation replay split over two hosts (replay and graph on one, view and writer on
  the other) writes the same distance CSV as on one host;
- a host killed mid-run is reported by name and the other stops cleanly (``on_error="stop_app"``);
- Ctrl-C on either host stops both;
- a link that delays and loses packets still delivers every sample of a reliable connection.

DDS domains 180-186. Skipped only where unprivileged user namespaces are missing.
"""

from __future__ import annotations

import csv
import os
import re
import signal
import subprocess
import time
from pathlib import Path
from typing import IO, Iterator

import pytest

from conftest import ROOT, connection_counters
from netns import Impairment, Network, unavailable

REASON = unavailable()
pytestmark = pytest.mark.skipif(REASON is not None, reason=f"no simulated network here: {REASON}")

LAUNCH = ROOT / "install" / "coco_core" / "lib" / "coco_core" / "coco-launch"
ROS_LAUNCHER = ROOT / "install" / "coco_ros" / "lib" / "coco_ros" / "launcher"
DEMO = ROOT / "config" / "hosts_demo_pipeline.xml"

PAIR = """<package name="pair" on_error="stop_app">
  <arg name="output"/>
  <arg name="period" default="20"/>
  <components>
    <component><name>generator</name><task>SignalGenerator</task></component>
    <component><name>supervisor</name><task>Supervisor</task>
      <attributes><attribute name="target" value="filter"/><attribute name="values" value="3, 5"/></attributes></component>
    <component><name>recorder</name><task>CsvRecorder</task>
      <attributes><attribute name="path" value="$(arg output)"/></attributes></component>
    <component><name>filter</name><task>MovingAverage</task></component>
  </components>
  <connections>
    <connection data="BUFFER" buffersize="4096"><src task="generator" port="sample"/><dest task="recorder" port="values"/></connection>
  </connections>
  <activities>
    <host name="robot">
      <activity name="acquisition"><schedule type="periodic" period="$(arg period)"/>
        <components><component name="generator"/></components></activity>
      <activity name="supervision"><schedule type="periodic" period="200"/>
        <components><component name="supervisor"/></components></activity>
    </host>
    <host name="graphics">
      <process name="rec">
        <activity name="recording"><schedule type="periodic" period="50"/>
          <components><component name="recorder"/><component name="filter"/></components></activity>
      </process>
    </host>
  </activities>
</package>
"""
"""Samples from the robot's launcher to a child process of the graphics host, and operation calls
from the robot to a component in that child process."""

def start(network: Network, host: str, log: Path, *args: str, launcher: Path = LAUNCH) -> subprocess.Popen[str]:
    """A launcher in ``host`` writing its output to ``log`` (a file: nothing blocks on a full pipe)."""
    handle: IO[str] = log.open("w")
    return network[host].popen([str(launcher), *args, "--host", host], cwd=ROOT, stdout=handle,
                               stderr=subprocess.STDOUT, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})


def wait_for(condition, timeout: float = 60.0) -> bool:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.05)
    return condition()


def rows(path: Path) -> list[dict[str, str]]:
    if not path.exists():
        return []
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


@pytest.fixture
def two_hosts() -> Iterator[Network]:
    with Network(["robot", "graphics"], domain=180) as network:
        yield network


def test_the_demo_runs_over_two_hosts_with_its_operations_and_one_clock(tmp_path: Path) -> None:
    output = tmp_path / "signal.csv"
    with Network(["sensor", "station"], domain=181) as network:
        station = start(network, "station", tmp_path / "station.log", str(DEMO), f"output:={output}", "--profile", "100")
        sensor = start(network, "sensor", tmp_path / "sensor.log", str(DEMO), "--duration", "3", "--profile", "100")
        assert sensor.wait(90) == 0, (tmp_path / "sensor.log").read_text()
        assert station.wait(30) == 0, (tmp_path / "station.log").read_text()
    sensor_log, station_log = (tmp_path / "sensor.log").read_text(), (tmp_path / "station.log").read_text()
    assert "host sensor: clock the application's clock" in sensor_log
    offset = re.search(r"host station: clock offset ([-+0-9.]+) ms \+- ([0-9.]+) ms", station_log)
    assert offset, station_log
    assert abs(float(offset.group(1))) <= float(offset.group(2)) + 0.05  # one machine: one clock
    assert "supervisor: filter.set_window -> previous value 8" in sensor_log  # an operation on the other host
    assert "stopping application hosts_demo_pipeline: host sensor: duration of 3 s reached" in station_log
    written, _, _ = connection_counters(sensor_log, "generator.sample -> filter.sample")
    assert connection_counters(station_log, "generator.sample -> filter.sample") == (written, written, 0) and written > 100
    assert len(rows(output)) == written  # every sample filtered and recorded on the other host


def test_a_host_killed_mid_run_is_named_and_the_other_stops_cleanly(two_hosts: Network, tmp_path: Path) -> None:
    app, output = tmp_path / "pair.xml", tmp_path / "values.csv"
    app.write_text(PAIR)
    graphics = start(two_hosts, "graphics", tmp_path / "graphics.log", str(app), f"output:={output}")
    start(two_hosts, "robot", tmp_path / "robot.log", str(app), f"output:={output}")
    assert wait_for(lambda: len(rows(output)) > 20), (tmp_path / "graphics.log").read_text()
    two_hosts["robot"].kill()
    assert graphics.wait(30) == 1
    log = (tmp_path / "graphics.log").read_text()
    assert re.search(r"host graphics: host robot disappeared \(no heartbeat for [0-9.]+ s\)", log), log
    assert "stopping application pair: host robot disappeared" in log and "(clean)" in log, log
    assert len(rows(output)) > 20  # what arrived was recorded and flushed


@pytest.mark.parametrize("interrupted", ["robot", "graphics"])
def test_ctrl_c_on_either_host_stops_both(two_hosts: Network, tmp_path: Path, interrupted: str) -> None:
    app, output = tmp_path / "pair.xml", tmp_path / "values.csv"
    app.write_text(PAIR)
    launched = {host: start(two_hosts, host, tmp_path / f"{host}.log", str(app), f"output:={output}",
                            launcher=ROS_LAUNCHER if host == "graphics" else LAUNCH)
                for host in ("robot", "graphics")}
    assert wait_for(lambda: len(rows(output)) > 10), (tmp_path / "graphics.log").read_text()
    launched[interrupted].send_signal(signal.SIGINT)
    other = "graphics" if interrupted == "robot" else "robot"
    for host, process in launched.items():
        assert process.wait(20) == 0, (tmp_path / f"{host}.log").read_text()
    log = (tmp_path / f"{other}.log").read_text()
    assert f"stopping application pair: host {interrupted}: received SIGINT" in log, log
    # An operation of a component in a child process of the other host, called by name.
    assert re.search(r"supervisor: filter.set_window -> previous value \d+", (tmp_path / "robot.log").read_text())


def test_a_lossy_delayed_link_still_delivers_every_sample_of_a_reliable_connection(tmp_path: Path) -> None:
    app, output = tmp_path / "pair.xml", tmp_path / "values.csv"
    app.write_text(PAIR)
    with Network(["robot", "graphics"], domain=182, impairment=Impairment(delay_s=0.02, loss=0.05, seed=7)) as network:
        graphics = start(network, "graphics", tmp_path / "graphics.log", str(app), f"output:={output}", "--profile", "100")
        robot = start(network, "robot", tmp_path / "robot.log", str(app), f"output:={output}", "--duration", "4",
                      "--profile", "100")
        assert robot.wait(90) == 0, (tmp_path / "robot.log").read_text()
        assert graphics.wait(30) == 0, (tmp_path / "graphics.log").read_text()
        dropped_on_link = sum(counts["dropped"] for counts in network.counters().values())
    assert dropped_on_link > 0  # the link did lose packets
    crossing = "generator.sample -> recorder.values"
    written, _, _ = connection_counters((tmp_path / "robot.log").read_text(), crossing)
    assert connection_counters((tmp_path / "graphics.log").read_text(), crossing) == (written, written, 0)
    assert len(rows(output)) == written > 100


def two_host_baxter(tmp_path: Path) -> Path:
    """config/baxter_teleop_replay.xml with its activities placed on two hosts, and nothing else
    changed: the replay, the transformation graph, the distance and the summary on ``robot``; the
    view process (its own frames, the display) and the writer on ``graphics``."""
    text = (ROOT / BAXTER).read_text()
    first, view = text.index('        <activity name="replay">'), text.index('        <process name="view"')
    end = text.index("        </process>", view) + len("        </process>")
    placed = (text[:first] + '        <host name="robot">\n' + text[first:view] + "        </host>\n"
              + '        <host name="graphics">\n' + text[view:end] + "\n        </host>" + text[end:])
    path = ROOT / "config" / f".test_two_hosts_{os.getpid()}.xml"  # beside the original: its paths resolve alike
    path.write_text(placed)
    return path


BAXTER = "config/baxter_teleop_replay.xml"


def test_the_baxter_replay_split_over_two_hosts_writes_the_same_distances(session, tmp_path: Path) -> None:
    folder, info = session
    one, two = tmp_path / "one", tmp_path / "two"
    alone = subprocess.run([str(LAUNCH), BAXTER, f"bag:={folder}", f"output:={one}", "display:=false", "rate:=3",
                            f"time_origin:={info.start_ns / 1e9}", "--duration", "60"], cwd=ROOT,
                           capture_output=True, text=True, timeout=120)
    assert alone.returncode == 0, alone.stderr
    app = two_host_baxter(tmp_path)
    try:
        args = (str(app), f"bag:={folder}", f"output:={two}", "rate:=3", f"time_origin:={info.start_ns / 1e9}")
        with Network(["robot", "graphics"], domain=183) as network:
            graphics = start(network, "graphics", tmp_path / "graphics.log", *args, "--profile", "100")
            robot = start(network, "robot", tmp_path / "robot.log", *args, "--duration", "60", "--profile", "100")
            assert robot.wait(150) == 0, (tmp_path / "robot.log").read_text()
            assert graphics.wait(30) == 0, (tmp_path / "graphics.log").read_text()
    finally:
        app.unlink()
    robot_log, graphics_log = (tmp_path / "robot.log").read_text(), (tmp_path / "graphics.log").read_text()
    assert "DDS to host graphics" in robot_log and "DDS from host robot" in graphics_log
    # Every distance and colour, in order. Not the timing columns: latency_ms, and time (the newest
    # input's stamp when the distance was computed: which of the first poses had reached the graph then
    # depends on timing, e.g. while the other host's display starts).
    def values(path: Path) -> list[tuple[str, ...]]:
        return [(row["seq"], row["distance"], row["r"], row["g"], row["b"]) for row in rows(path)]

    assert len(values(one / "distance.csv")) > 500  # a 12 s session
    assert values(two / "distance.csv") == values(one / "distance.csv")
    assert (two / "frames.mp4").stat().st_size > 0  # the view on the other host rendered and recorded
