"""The host level in the file: ``<host>``, each host's part, and what ``--check`` prints for it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from coco_core.builder import build_application
from coco_core.dataflow_graph import dataflow_dot
from coco_core.errors import ConfigErrors
from coco_core.filters import Cull, MaxFrequency
from coco_core.deployment import plan_deployment
from coco_core.hosts.part import split_address
from coco_core.model import AppSpec
from coco_core.policy import BufferPolicy
from coco_core.xml import load_application

APP = """<package name="spread">
  <components>
    <component><name>generator</name><task>SignalGenerator</task></component>
    <component><name>filter</name><task>MovingAverage</task></component>
    <component><name>recorder</name><task>CsvRecorder</task>
      <attributes><attribute name="path" value="{tmp}/out.csv"/></attributes></component>
    <component><name>idle</name><task>MovingAverage</task></component>
    <component><name>outsider</name><task>MovingAverage</task></component>
  </components>
  <connections>
    <connection data="BUFFER" buffersize="16"><src task="generator" port="sample"/><dest task="filter" port="sample"/>{filter}</connection>
    <connection data="BUFFER" buffersize="64"><src task="filter" port="filtered"/><dest task="recorder" port="values"/></connection>
  </connections>
  <activities>
    <host name="robot">
      <activity name="acquisition"><schedule type="periodic" period="10"/>
        <components><component name="generator"/></components></activity>
    </host>
    <host name="graphics">
      <process name="work">
        <activity name="filtering"><schedule type="triggered"/><components><component name="filter"/></components></activity>
      </process>
      <activity name="recording"><schedule type="periodic" period="100" main="true"/>
        <components><component name="recorder"/></components></activity>
    </host>
    <activity name="outside"><schedule type="periodic" period="100" main="true"/>
      <components><component name="outsider"/></components></activity>
  </activities>
</package>
"""


def part_of(spec: AppSpec, host: str) -> AppSpec:
    """``host``'s part of ``spec``, as the deployment plan cuts it."""
    return plan_deployment(spec, host=host).host(host).spec


def write(tmp_path: Path, text: str = APP, filter: str = "") -> Path:
    path = tmp_path / "spread.xml"
    path.write_text(text.format(tmp=tmp_path, filter=filter))
    return path


def test_every_activity_and_process_is_on_a_host_the_first_takes_the_rest(tmp_path: Path) -> None:
    spec = load_application(str(write(tmp_path)))
    assert [host.name for host in spec.hosts] == ["robot", "graphics"]
    assert {a.name: a.host for a in spec.activities} == {
        "acquisition": "robot", "filtering": "graphics", "recording": "graphics", "outside": "robot"}
    assert [(p.name, p.host) for p in spec.processes] == [("work", "graphics")]


def test_each_host_builds_its_own_part_and_knows_the_connections_between_hosts(tmp_path: Path) -> None:
    spec = load_application(str(write(tmp_path)))
    robot, graphics = part_of(spec, "robot"), part_of(spec, "graphics")
    assert [c.name for c in robot.components] == ["generator", "idle", "outsider"]  # no activity runs idle: the first host's
    assert [c.name for c in graphics.components] == ["filter", "recorder"]
    assert robot.connections == [] and [str(c.dest) for c in graphics.connections] == ["recorder.values"]
    assert robot.between_hosts == graphics.between_hosts  # both plan it alike, from the file alone
    (channel,) = robot.between_hosts
    assert (channel.src, channel.dest, channel.src_host, channel.dest_host, channel.dest_process) == (
        "generator.sample", "filter.sample", "robot", "graphics", "work")
    assert channel.policy.data is BufferPolicy.BUFFER and channel.policy.size == 16
    assert channel.topic == "/coco/spread/generator/sample/to/filter/sample"
    assert split_address(robot.other_hosts["filter"]) == ("graphics", "work")
    assert split_address(graphics.other_hosts["generator"]) == ("robot", "")
    app = build_application(graphics)
    assert app.elsewhere["generator"] == "@robot" and app.elsewhere["filter"] == "work"


def test_a_filter_on_a_connection_from_another_host_is_made_on_the_readers_side(tmp_path: Path) -> None:
    text = APP.replace('data="BUFFER" buffersize="16">', 'buffersize="16">')
    spec = load_application(str(write(tmp_path, text, filter='<filter type="MaxFrequency" hz="20"/>')))
    child = build_application(part_of(spec, "graphics"), "work")
    assert isinstance(child.incoming_filters["generator.sample->filter.sample"], MaxFrequency)
    assert not build_application(part_of(spec, "robot")).incoming_filters


def test_a_cull_to_another_host_is_made_on_the_writers_side_too(tmp_path: Path) -> None:
    """A routing filter decides where the message is written (coco_core.processes.routed): the
    writer's host makes it for its end, the reader's host for its side (the profile, unroutables)."""
    text = APP.replace('data="BUFFER" buffersize="16">', 'buffersize="16">')
    spec = load_application(str(write(tmp_path, text, filter='<filter type="Cull" region="0 0 1 1"/>')))
    writer = build_application(part_of(spec, "robot"))
    assert isinstance(writer.outgoing_routers["generator.sample->filter.sample"], Cull)
    assert not writer.incoming_filters
    reader = build_application(part_of(spec, "graphics"), "work")
    assert isinstance(reader.incoming_filters["generator.sample->filter.sample"], Cull)
    assert not reader.outgoing_routers


@pytest.mark.parametrize("text, message", [
    (APP.replace('<host name="graphics">', '<host name="robot">'), "host name 'robot' is already used at"),
    (APP.replace('<host name="graphics">', '<host name="graphics"><process name="x"/>').replace(
        "</activities>", "</activities>"), "<process> 'x' has no activity"),
    (APP.replace('policy="LOCKED"', "").replace('data="BUFFER" buffersize="16"',
                                                 'data="BUFFER" buffersize="16" policy="UNSYNC"'),
     "UNSYNC connection generator.sample -> filter.sample joins host 'robot' and host 'graphics'"),
    (APP.replace('period="10"/>', 'period="10" main="true"/>'),
     "which activity 'acquisition' at"),
])
def test_wrong_hosts_are_reported_with_file_and_line(tmp_path: Path, text: str, message: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigErrors) as raised:
        spec = load_application(str(path))
        part_of(spec, "robot")
    assert message in str(raised.value)
    assert "UNSYNC" in message or f"{path}:" in str(raised.value)


def test_an_unknown_host_lists_the_valid_ones(tmp_path: Path) -> None:
    spec = load_application(str(write(tmp_path)))
    with pytest.raises(ConfigErrors, match="no such host.*graphics"):
        part_of(spec, "grapics")


def test_check_prints_every_hosts_part_and_the_connections_between_them(tmp_path: Path) -> None:
    path = write(tmp_path)
    done = subprocess.run([sys.executable, "-m", "coco_core.launcher", str(path), "--check"], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert "application spread, host robot of robot, graphics (the application's clock)" in out
    assert "application spread, host graphics of robot, graphics (on robot's clock)" in out
    assert "generator.sample -> filter.sample  BUFFER/LOCKED[16], plain  (robot/launcher -> graphics/work" in out
    one = subprocess.run([sys.executable, "-m", "coco_core.launcher", str(path), "--check", "--host", "graphics"],
                         capture_output=True, text=True, timeout=120)
    assert one.returncode == 0 and "host robot of" not in one.stdout and "process work" in one.stdout
    run = subprocess.run([sys.executable, "-m", "coco_core.launcher", str(path), "--duration", "1"],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2 and "say which one this machine is with --host NAME" in run.stderr  # a wrong command line


def test_the_data_flow_graph_draws_each_host_around_its_processes(tmp_path: Path) -> None:
    dot = dataflow_dot(plan_deployment(load_application(str(write(tmp_path)))))
    robot, graphics = dot.index('label="host robot"'), dot.index('label="host graphics"')
    assert robot < dot.index('"activity acquisition') < graphics < dot.index('label="process work"')
    assert dot.index('"activity outside') < graphics  # outside any <host>: the first host's
    assert "between hosts (DDS)" in dot and dot.count("between hosts (DDS)") == 1


WEIRD = """
from coco_core import Component, InputPort, OutputPort


class Opaque:
    \"\"\"A class nobody registered as a value type: its values cannot cross between hosts.\"\"\"


class Weird(Component):
    out = OutputPort(Opaque | float)
    anything = OutputPort(object)
    into = InputPort(object)
"""


def test_a_launch_over_hosts_needs_the_key_and_only_values_that_can_cross(tmp_path: Path) -> None:
    """Without --key an application over several hosts refuses to start (and a one-host one refuses a
    key it would ignore); --check names a connection between hosts whose writer's declared type is
    no registered value type, before anything runs; a port declared ``object`` is checked as its
    values are sent."""
    path = write(tmp_path)
    launcher = [sys.executable, "-m", "coco_core.launcher"]
    done = subprocess.run([*launcher, str(path), "--host", "robot", "--duration", "1"], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 2 and "give --key FILE or --key-env NAME (coco-keygen FILE makes one" in done.stderr
    one_host = tmp_path / "one.xml"
    one_host.write_text(APP.format(tmp=tmp_path, filter="").split("<activities>")[0] + "</package>")
    done = subprocess.run([*launcher, str(one_host), "--key", str(path), "--duration", "1"], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 2 and "one.xml" not in done.stdout and "declares no <host>" in done.stderr
    (tmp_path / "weird.py").write_text(WEIRD)
    weird = tmp_path / "weird.xml"
    weird.write_text(APP.format(tmp=tmp_path, filter="").replace("<task>SignalGenerator</task>", "<task>weird:Weird</task>")
                     .replace('port="sample"/><dest task="filter"', 'port="out"/><dest task="filter"')
                     .replace('<connection data="BUFFER" buffersize="64">', '<connection data="BUFFER" buffersize="64">'
                              '<src task="generator" port="anything"/><dest task="recorder" port="values"/></connection>'
                              '<connection data="BUFFER" buffersize="64">'))
    done = subprocess.run([*launcher, str(weird), "--check"], capture_output=True, text=True, timeout=120,
                          env={**__import__("os").environ, "PYTHONPATH": f"{tmp_path}:{__import__('os').environ['PYTHONPATH']}"})
    assert done.returncode == 1, done.stdout
    assert ("connection generator.out->filter.sample between hosts robot and graphics: weird.Opaque is not a registered "
            "value type (coco_core.wire.value_type)") in done.stderr
    assert "generator.anything" not in done.stderr
