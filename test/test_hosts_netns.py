"""Applications over two hosts, each a network namespace of this machine with real DDS over UDP
between them (``test/netns.py``), run by the installed launchers as on two machines: the same file,
one more argument (``--host NAME``).

- the demo pipeline over two hosts: every sample crosses, counted on both sides, the supervisor's
  operation calls reach the filter on the other host, and the second host's clock is measured;
- the Baxter teleoperation replay split over two hosts (replay and graph on one, view and writer on
  the other) writes the same distance CSV as on one host;
- a host killed mid-run is reported by name and the other stops cleanly (``on_error="stop_app"``);
- Ctrl-C on either host stops both;
- a link that delays and loses packets still delivers every sample of a reliable connection;
- a third participant without the application's key neither feeds nor stops the hosts.

DDS domains 180-187. Skipped only where unprivileged user namespaces are missing.
"""

from __future__ import annotations

import csv
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import IO, Iterator

import pytest

from coco_core.hosts.channel import topic_of
from conftest import ROOT, connection_counters
from netns import Impairment, Network, unavailable

REASON = unavailable()
pytestmark = pytest.mark.skipif(REASON is not None, reason=f"no simulated network here: {REASON}")

LAUNCH = ROOT / "install" / "coco_core" / "lib" / "coco_core" / "coco-launch"
ROS_LAUNCHER = ROOT / "install" / "coco_ros" / "lib" / "coco_ros" / "launcher"
KEYGEN = ROOT / "install" / "coco_core" / "lib" / "coco_core" / "coco-keygen"
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
    """A launcher in ``host`` writing its output to ``log`` (a file: nothing blocks on a full pipe),
    with the application's key in the log's folder (made there by ``coco-keygen`` for the first
    host: every host of a test shares it)."""
    key = log.parent / "app.key"
    if not key.exists():
        subprocess.run([str(KEYGEN), str(key)], check=True, capture_output=True)
    handle: IO[str] = log.open("w")
    return network[host].popen([str(launcher), *args, "--host", host, "--key", str(key)], cwd=ROOT, stdout=handle,
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


ATTACKER = r'''
"""A participant of the application's DDS domain without its key (the third namespace): it
publishes what the probe of issue 36 did, for ``seconds``, on the demo's bus, heartbeat and data
topics, then says how many it sent."""
import os, pickle, sys, time
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from coco_core.hosts.channel import topic_of
from coco_core.hosts.messages import Heartbeat, Stage
from coco_core.messages import Call
from coco_core.stamps import Stamp, Stamped
from coco_core.wire import Encoder
from coco_interfaces.msg import HostMessage, Sample

marker, seconds = sys.argv[1], float(sys.argv[2])


class Bomb:
    def __reduce__(self):
        return os.system, (f"touch {marker}",)


rclpy.init()
node = rclpy.create_node("coco_intruder")
qos = QoSProfile(depth=64, reliability=ReliabilityPolicy.RELIABLE)
bus = node.create_publisher(HostMessage, "/coco/hosts_demo_pipeline/hosts", qos)
beats = node.create_publisher(HostMessage, "/coco/hosts_demo_pipeline/hosts/heartbeat", qos)
data = node.create_publisher(Sample, topic_of("hosts_demo_pipeline", "generator.sample", "filter.sample"), qos)
encoder = Encoder()


def message(sender, body, recipient=""):
    return HostMessage(sender=sender, recipient=recipient, body=body, session=7, counter=int(time.time() * 1e3),
                       wall=time.time(), mac=bytes(32))


sent = 0
deadline = time.monotonic() + seconds
while time.monotonic() < deadline:
    number = int(time.monotonic() * 100)
    for publisher, forged in (
            (beats, message("station", pickle.dumps(Bomb()))),
            (beats, message("station", encoder.encode(Heartbeat(Stage.STOPPING, "forged", True, True)))),
            (beats, message("sensor", encoder.encode(Heartbeat(Stage.STOPPING, "forged", True, True)))),
            (beats, message("ghost", encoder.encode(Heartbeat(Stage.RUNNING)))),
            (bus, message("sensor", encoder.encode(Call(id=1, process="", component="filter", operation="set_window",
                                                        args=(10 ** 9,))), "station")),
            (data, Sample(number=number, seq=number, source="generator.sample", codec="pickle",
                          payload=pickle.dumps(Bomb()), sender="sensor", counter=number, wall=time.time(),
                          mac=bytes(32))),
            (data, Sample(number=number + 1, seq=number + 1, source="generator.sample", codec="plain",
                          payload=encoder.encode(Stamped(float("nan"), Stamp(1.0))), sender="sensor",
                          counter=number + 1, wall=time.time(), mac=bytes(32)))):
        publisher.publish(forged)
        sent += 1
    time.sleep(0.02)
print(f"sent {sent}", flush=True)
'''


def test_a_participant_without_the_key_neither_feeds_nor_stops_the_hosts(tmp_path: Path) -> None:
    """Three namespaces: the demo over two hosts, and a third participant of the same DDS domain
    without the key that publishes pickle-bombs, forged heartbeats saying a host stops, a forged
    operation call, forged samples and heartbeats of an unknown host. Nothing runs, nothing stops:
    both hosts run to their end with exit status 0, the station records exactly what the sensor's
    generator wrote, the window is never set to 10^9, and each host's profile counts what it
    refused by topic and sender."""
    output, marker = tmp_path / "signal.csv", tmp_path / "pwned"
    attacker_script = tmp_path / "attacker.py"
    attacker_script.write_text(ATTACKER)
    with Network(["sensor", "station", "intruder"], domain=187) as network:
        station = start(network, "station", tmp_path / "station.log", str(DEMO), f"output:={output}", "--profile", "100")
        sensor = start(network, "sensor", tmp_path / "sensor.log", str(DEMO), "--duration", "4", "--profile", "100")
        assert wait_for(lambda: "host sensor is there" in (tmp_path / "station.log").read_text())
        intruder = network["intruder"].popen([sys.executable, str(attacker_script), str(marker), "4"],
                                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        assert sensor.wait(90) == 0, (tmp_path / "sensor.log").read_text()
        assert station.wait(30) == 0, (tmp_path / "station.log").read_text()
        said = intruder.communicate(timeout=30)[0]
    assert intruder.returncode == 0 and "sent " in said, said
    sensor_log, station_log = (tmp_path / "sensor.log").read_text(), (tmp_path / "station.log").read_text()
    assert not marker.exists()
    assert "stopping application hosts_demo_pipeline: host sensor: duration of 4 s reached" in station_log
    assert "1000000000" not in station_log and "forged" not in station_log + sensor_log
    written, _, _ = connection_counters(sensor_log, "generator.sample -> filter.sample")
    assert connection_counters(station_log, "generator.sample -> filter.sample") == (written, written, 0)
    assert len(rows(output)) == written and all(row["value"] != "nan" for row in rows(output))
    refused = re.compile(r"^(/coco/hosts_demo_pipeline\S*)\s+'(\w+)'\s+(.+?)\s+(\d+)$", re.MULTILINE)
    station_refused = {(topic, sender): int(count) for topic, sender, _, count in refused.findall(station_log)}
    assert station_refused[(topic_of("hosts_demo_pipeline", "generator.sample", "filter.sample"), "sensor")] > 10
    assert station_refused[("/coco/hosts_demo_pipeline/hosts/heartbeat", "ghost")] > 5
    assert station_refused[("/coco/hosts_demo_pipeline/hosts", "sensor")] > 5
    sensor_refused = {(topic, sender) for topic, sender, _, _ in refused.findall(sensor_log)}
    assert ("/coco/hosts_demo_pipeline/hosts/heartbeat", "station") in sensor_refused
