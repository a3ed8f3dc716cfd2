"""<composite>: a sub-application in a file of its own, instantiated several times with different
args, its names scoped per instance, its exposed ports reached from outside, its errors reported
all at once at the inner file's line with the instantiating element's."""

import csv
import subprocess
import sys
from pathlib import Path

import pytest

from coco_core.builder import build_application
from coco_core.errors import ConfigErrors
from coco_core.policy import BufferPolicy
from coco_core.xml import load_application

CONFIG = Path(__file__).resolve().parents[2] / "config"
TIMEOUT = 30.0
"""Seconds a condition may take on a loaded machine."""

PIPELINE = """<package>
  <arg name="frequency"/>
  <arg name="window" default="8"/>
  <arg name="period" default="10"/>
  <ports>
    <port name="out" task="filter" port="filtered"/>
    <port name="raw" task="gen" port="sample"/>
    <port name="done" activity="filtering" port="endit"/>
  </ports>
  <components>
    <component><name>gen</name><task>SignalGenerator</task>
      <attributes><attribute name="frequency" value="$(arg frequency)"/></attributes></component>
    <component><name>filter</name><task>MovingAverage</task>
      <attributes><attribute name="window" value="$(arg window)"/></attributes></component>
  </components>
  <connections>
    <connection data="BUFFER" buffersize="16"><src task="gen" port="sample"/><dest task="filter" port="sample"/></connection>
  </connections>
  <activities>
    <activity name="acquisition"><schedule period="$(arg period)"/><components><component name="gen"/></components></activity>
    <activity name="filtering"><schedule/><components><component name="filter"/></components></activity>
  </activities>
</package>"""


def write(directory: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = directory / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def errors_of(path: Path, **kwargs) -> list[tuple[str, int | None, str]]:
    with pytest.raises(ConfigErrors) as raised:
        load_application(path, **kwargs)
    return [
        (Path(e.location.file).name if e.location else "", e.location.line if e.location else None, e.message)
        for e in raised.value.errors
    ]


def two_instances(tmp_path: Path, outer: str = "", second_args: str = '<arg name="frequency" value="2"/>') -> Path:
    write(tmp_path, {
        "parts/pipeline.xml": PIPELINE,
        "app.xml": f"""<package>
  <components>
    <composite name="cam1" file="parts/pipeline.xml">
      <arg name="frequency" value="0.5"/>
      <arg name="window" value="4"/>
    </composite>
    <composite name="cam2" file="parts/pipeline.xml">
      {second_args}
    </composite>
    <component><name>rec1</name><task>CsvRecorder</task></component>
    <component><name>rec2</name><task>CsvRecorder</task></component>
  </components>
  <connections>
    <connection data="BUFFER" buffersize="64"><src task="cam1" port="out"/><dest task="rec1" port="values"/></connection>
    <connection data="BUFFER" buffersize="64"><src task="cam2" port="out"/><dest task="rec2" port="values"/></connection>
    {outer}
  </connections>
  <activities>
    <activity name="recording"><schedule period="50"/><components>
      <component name="rec1"/><component name="rec2"/></components></activity>
  </activities>
</package>""",
    })
    return tmp_path / "app.xml"


def test_two_instances_get_scoped_names_their_own_args_and_resolved_connections(tmp_path):
    spec = load_application(two_instances(tmp_path))
    components = {c.name: c for c in spec.components}
    assert list(components) == ["cam1/gen", "cam1/filter", "cam2/gen", "cam2/filter", "rec1", "rec2"]
    attributes = {name: {a.name: a.value for a in c.attributes} for name, c in components.items()}
    assert attributes["cam1/gen"] == {"frequency": "0.5"} and attributes["cam1/filter"] == {"window": "4"}
    assert attributes["cam2/gen"] == {"frequency": "2"} and attributes["cam2/filter"] == {"window": "8"}
    assert components["cam1/gen"].location.file == str(tmp_path / "parts" / "pipeline.xml")
    assert [(a.name, a.components, a.schedule.period_ms) for a in spec.activities] == [
        ("cam1/acquisition", ["cam1/gen"], 10.0), ("cam1/filtering", ["cam1/filter"], None),
        ("cam2/acquisition", ["cam2/gen"], 10.0), ("cam2/filtering", ["cam2/filter"], None),
        ("recording", ["rec1", "rec2"], 50.0),
    ]
    assert [(str(c.src), str(c.dest), c.buffersize) for c in spec.connections] == [
        ("cam1/gen.sample", "cam1/filter.sample", 16),
        ("cam2/gen.sample", "cam2/filter.sample", 16),
        ("cam1/filter.filtered", "rec1.values", 64),   # the exposed port "out" of cam1
        ("cam2/filter.filtered", "rec2.values", 64),
    ]
    # The outer connection keeps its own line; the composite's connections keep the inner file's.
    assert spec.connections[2].src.location.file == str(tmp_path / "app.xml")
    assert spec.connections[0].src.location.file == str(tmp_path / "parts" / "pipeline.xml")
    [cam1, cam2] = spec.composites
    assert (cam1.name, cam1.args) == ("cam1", {"frequency": "0.5", "window": "4", "period": "10"})
    assert cam2.args == {"frequency": "2", "window": "8", "period": "10"}
    assert cam1.file == str(tmp_path / "parts" / "pipeline.xml") and cam1.location.line == 3
    assert {name: str(ref) for name, ref in cam2.ports.items()} == {
        "out": "cam2/filter.filtered", "raw": "cam2/gen.sample", "done": "cam2/filtering.endit"}
    assert cam2.ports["done"].activity
    assert cam1.components == ["cam1/gen", "cam1/filter"]
    assert cam1.activities == ["cam1/acquisition", "cam1/filtering"]


def test_an_exposed_activity_port_and_a_nested_instance_resolve_through_every_level(tmp_path):
    write(tmp_path, {
        "parts/pipeline.xml": PIPELINE,
        "parts/pair.xml": """<package>
  <arg name="base" default="1"/>
  <ports>
    <port name="left" task="a" port="out"/>
    <port name="left_done" task="a" port="done"/>
  </ports>
  <components>
    <composite name="a" file="pipeline.xml"><arg name="frequency" value="$(arg base)"/></composite>
    <composite name="b" file="pipeline.xml"><arg name="frequency" value="$(eval 2 * float(arg('base')))"/></composite>
  </components>
</package>""",
        "app.xml": """<package>
  <components>
    <composite name="pair" file="parts/pair.xml"><arg name="base" value="3"/></composite>
    <component><name>rec</name><task>CsvRecorder</task></component>
  </components>
  <connections>
    <connection data="BUFFER" buffersize="8"><src task="pair" port="left"/><dest task="rec" port="values"/></connection>
    <connection><src task="pair" port="left_done"/><dest activity="recording" port="beginit"/></connection>
  </connections>
  <activities>
    <activity name="recording"><schedule/><components><component name="rec"/></components></activity>
  </activities>
</package>""",
    })
    spec = load_application(tmp_path / "app.xml")
    assert [c.name for c in spec.composites] == ["pair", "pair/a", "pair/b"]
    frequencies = {c.name: c.attributes[0].value for c in spec.components if c.task == "SignalGenerator"}
    assert frequencies == {"pair/a/gen": "3", "pair/b/gen": "6.0"}
    outer = spec.connections[-2:]
    assert [(str(c.src), str(c.dest)) for c in outer] == [
        ("pair/a/filter.filtered", "rec.values"), ("pair/a/filtering.endit", "recording.beginit")]
    assert outer[1].src.activity and outer[1].dest.activity
    build_application(spec)  # the builder accepts the resolved ports and the activity ports


def test_the_example_runs_both_instances_with_their_own_rates(tmp_path, wait_until):
    """config/composite_signals.xml: one composite file, two instances (5 ms and 10 ms sampling),
    each recorded through its exposed "filtered" port to a CSV file of its own."""
    spec = load_application(CONFIG / "composite_signals.xml", args={"out_dir": str(tmp_path)})
    assert [c.name for c in spec.composites] == ["slow", "fast"]
    app = build_application(spec)
    try:
        app.start()
        slow, fast = app.component("slow_recorder"), app.component("fast_recorder")
        assert wait_until(lambda: getattr(slow, "rows", 0) >= 20 and getattr(fast, "rows", 0) >= 20, timeout=TIMEOUT)
    finally:
        assert app.stop()
    periods = {a.name: a.schedule.period_ms for a in spec.activities}
    assert periods["slow/acquisition"] == 10.0 and periods["fast/acquisition"] == 5.0
    for name in ("slow", "fast"):
        with open(tmp_path / f"composite_{name}.csv") as file:
            rows = list(csv.DictReader(file))
        assert rows and {row["source"] for row in rows} == {f"{name}/generator"}
    assert app.component("slow/filter").window == 4 and app.component("fast/filter").window == 16


def test_check_prints_the_instances_in_the_tree():
    check = subprocess.run([sys.executable, "-m", "coco_core.launcher", str(CONFIG / "composite_signals.xml"),
                            "--check"], capture_output=True, text=True, timeout=60)
    assert check.returncode == 0, check.stderr
    lines = check.stdout.splitlines()
    start = lines.index("  composites:")
    assert lines[start + 1].startswith("    slow: ") and lines[start + 1].endswith("composite_signals.xml:15)")
    assert "      args: frequency=0.5, window=4, rate_ms=10, seed=1" in lines
    assert "      port filtered -> fast/filter.filtered" in lines
    assert "      port smoothed -> fast/filtering.endit (activity)" in lines
    assert "      components: fast/generator, fast/filter" in lines
    assert "  activity fast/acquisition: periodic 5 ms -> own thread" in lines
    assert "  fast/filter.filtered -> fast_recorder.values  BUFFER/LOCKED[256]" in lines


def test_a_missing_and_an_unknown_arg_are_reported_for_each_instance_at_both_lines(tmp_path):
    app = two_instances(tmp_path, second_args='<arg name="frequncy" value="2"/>')
    context = f" (in composite instance 'cam2' of {tmp_path / 'parts' / 'pipeline.xml'}, instantiated at {app}:7)"
    assert errors_of(app) == [
        ("app.xml", 8, "composite parts/pipeline.xml declares no arg 'frequncy'; did you mean 'frequency'? "
                       "valid: frequency, period, window" + context),
        ("pipeline.xml", 2, "arg 'frequency' has no value: give it (<arg name=\"frequency\" value=\"...\"/> in "
                            "the <composite>) or declare a default=" + context),
    ]


def test_the_composite_sees_only_its_own_args(tmp_path):
    write(tmp_path, {"inner.xml": """<package>
  <components><component><name>gen</name><task>SignalGenerator</task>
    <attributes><attribute name="frequency" value="$(arg rate)"/></attributes></component></components>
</package>""", "app.xml": """<package>
  <arg name="rate" default="3"/>
  <components><composite name="c" file="inner.xml"/></components>
</package>"""})
    [(file, line, message)] = errors_of(tmp_path / "app.xml")
    assert (file, line) == ("inner.xml", 3)
    assert message.startswith("<attribute> attribute value=\"$(arg rate)\": $(arg rate): no <arg> named 'rate'")
    assert message.endswith(f"(in composite instance 'c' of {tmp_path / 'inner.xml'}, instantiated at "
                            f"{tmp_path / 'app.xml'}:3)")


def test_unresolved_ports_and_names_are_each_reported_once_with_the_instance(tmp_path):
    write(tmp_path, {
        "inner.xml": """<package>
  <ports>
    <port name="out" task="filtr" port="filtered"/>
    <port name="tick" activity="nowhere" port="endit"/>
  </ports>
  <components><component><name>filter</name><task>MovingAverage</task></component></components>
  <connections>
    <connection><src task="gen" port="sample"/><dest task="filter" port="sample"/></connection>
  </connections>
  <activities>
    <activity name="run"><schedule/><components><component name="fliter"/></components></activity>
  </activities>
</package>""",
        "app.xml": """<package>
  <components>
    <composite name="c" file="inner.xml"/>
    <component><name>rec</name><task>CsvRecorder</task></component>
  </components>
  <connections>
    <connection><src task="c" port="out"/><dest task="rec" port="values"/></connection>
    <connection><src task="c" port="outt"/><dest task="rec" port="values"/></connection>
  </connections>
  <activities>
    <activity name="a"><schedule/><components><component name="c"/></components></activity>
  </activities>
</package>""",
    })
    context = f" (in composite instance 'c' of {tmp_path / 'inner.xml'}, instantiated at {tmp_path / 'app.xml'}:3)"
    assert errors_of(tmp_path / "app.xml") == [
        ("app.xml", 8, "<src task=\"c\" port=\"outt\">: composite instance 'c' (" + str(tmp_path / "inner.xml")
         + ") exposes no port 'outt'; did you mean 'out'? valid: out, tick"),
        ("app.xml", 11, "<component name=\"c\"> is a composite instance (" + str(tmp_path / "inner.xml") + "): its "
         "own activities run its components; name one of its exposed ports, or schedule components of the application"),
        ("inner.xml", 3, "exposed port 'out' names 'c/filtr', which is not a component of the composite; "
         "did you mean 'c/filter'? valid: c/filter" + context),
        ("inner.xml", 4, "exposed port 'tick' names 'c/nowhere', which is not an activity of the composite; "
         "valid: c/run" + context),
        ("inner.xml", 8, "<src task=\"c/gen\"> is not a defined component; valid: c/filter" + context),
        ("inner.xml", 11, "<component name=\"c/fliter\"> is not a defined component; did you mean 'c/filter'? "
         "valid: c/filter" + context),
    ]


def test_instance_names_are_plain_and_unique(tmp_path):
    write(tmp_path, {"parts/pipeline.xml": PIPELINE, "app.xml": """<package>
  <components>
    <composite name="a/b" file="parts/pipeline.xml"><arg name="frequency" value="1"/></composite>
    <composite name="c" file="parts/pipeline.xml"><arg name="frequency" value="1"/></composite>
    <composite name="c" file="parts/pipeline.xml"><arg name="frequency" value="1"/></composite>
    <component><name>d</name><task>CsvRecorder</task></component>
    <composite name="d" file="parts/pipeline.xml"><arg name="frequency" value="1"/></composite>
    <composite name="e" file="parts/missing.xml"/>
  </components>
</package>"""})
    errors = errors_of(tmp_path / "app.xml")
    assert errors[0][:2] == ("app.xml", 3) and 'an instance name cannot contain "/"' in errors[0][2]
    assert errors[1][:2] == ("app.xml", 5) and errors[1][2].startswith("composite instance name 'c' is already used")
    assert errors[2][:2] == ("app.xml", 8)
    assert errors[2][2].startswith("<composite> 'parts/missing.xml' not found; tried: ")
    assert len(errors) == 3  # a missing file stops the whole-application checks, as for <include>
    (tmp_path / "app.xml").write_text((tmp_path / "app.xml").read_text().replace(
        '<composite name="a/b" file="parts/pipeline.xml">', '<composite name="b" file="parts/pipeline.xml">').replace(
        '<composite name="e" file="parts/missing.xml"/>', ""))
    assert errors_of(tmp_path / "app.xml") == [
        ("app.xml", 5, f"composite instance name 'c' is already used at {tmp_path / 'app.xml'}:4; instance names "
                       "must be unique"),
        ("app.xml", 7, f"composite instance name 'd' is already used by the component at {tmp_path / 'app.xml'}:6; "
                       "instance and component names must be unique"),
    ]


def test_a_composite_that_instantiates_itself_directly_or_not_is_a_cycle(tmp_path):
    write(tmp_path, {
        "self.xml": '<package><components><composite name="again" file="self.xml"/></components></package>',
        "a.xml": '<package><components><composite name="b" file="b.xml"/></components></package>',
        "b.xml": '<package><components><composite name="a" file="a.xml"/></components></package>',
        "app.xml": """<package><components>
  <composite name="s" file="self.xml"/>
  <composite name="x" file="a.xml"/>
</components></package>""",
    })
    errors = errors_of(tmp_path / "app.xml")
    assert [(file, line) for file, line, _ in errors] == [("self.xml", 1), ("b.xml", 1)]
    direct, indirect = (message for _, _, message in errors)
    assert direct.startswith(f"composite cycle: {tmp_path / 'self.xml'} -> {tmp_path / 'self.xml'} (in composite "
                             f"instance 's' of {tmp_path / 'self.xml'}, instantiated at {tmp_path / 'app.xml'}:2)")
    assert indirect.startswith(f"composite cycle: {tmp_path / 'a.xml'} -> {tmp_path / 'b.xml'} -> {tmp_path / 'a.xml'}")
    assert indirect.endswith(f"(in composite instance 'b' of {tmp_path / 'b.xml'}, instantiated at "
                             f"{tmp_path / 'a.xml'}:1) (in composite instance 'x' of {tmp_path / 'a.xml'}, "
                             f"instantiated at {tmp_path / 'app.xml'}:3)")


def test_pipelines_processes_and_default_names_inside_a_composite_are_scoped(tmp_path):
    write(tmp_path, {"inner.xml": """<package>
  <components>
    <component><name>gen</name><task>SignalGenerator</task></component>
    <component><name>filter</name><task>MovingAverage</task></component>
  </components>
  <activities>
    <process name="worker">
      <activity><schedule period="5"/><components><component name="gen"/></components></activity>
    </process>
    <pipeline name="chain"><components><component name="filter" in="sample"/></components></pipeline>
  </activities>
</package>""", "app.xml": """<package><components>
  <composite name="p" file="inner.xml"/><composite name="q" file="inner.xml"/>
</components></package>"""})
    spec = load_application(tmp_path / "app.xml")
    assert [(a.name, a.process) for a in spec.activities] == [
        ("p/activity1", "p/worker"), ("p/chain.filter", ""), ("q/activity1", "q/worker"), ("q/chain.filter", "")]
    assert [p.name for p in spec.processes] == ["p/worker", "q/worker"]


def test_outer_connections_may_use_the_policy_they_need(tmp_path):
    spec = load_application(two_instances(tmp_path, outer="""<connection data="CIRCULAR" buffersize="3">
      <src task="cam2" port="raw"/><dest task="rec1" port="values"/></connection>"""))
    last = spec.connections[-1]
    assert (str(last.src), last.data, last.buffersize) == ("cam2/gen.sample", BufferPolicy.CIRCULAR, 3)


def test_a_value_the_builder_refuses_names_the_instance_that_gave_it(tmp_path):
    spec = load_application(two_instances(tmp_path, second_args='<arg name="frequency" value="2"/>'
                                                                 '<arg name="window" value="wide"/>'))
    with pytest.raises(ConfigErrors) as raised:
        build_application(spec)
    [error] = raised.value.errors
    assert str(error.location) == f"{tmp_path / 'parts' / 'pipeline.xml'}:14"
    assert error.message == (f"attribute cam2/filter.window (int): expected an integer, got 'wide' (in composite "
                             f"instance 'cam2' of {tmp_path / 'parts' / 'pipeline.xml'}, instantiated at "
                             f"{tmp_path / 'app.xml'}:7)")


def test_a_wrong_port_behind_an_exposed_port_is_reported_at_the_outer_connection(tmp_path):
    spec = load_application(two_instances(tmp_path, outer="""<connection>
      <src task="cam1" port="raw"/><dest task="cam2/filter" port="window"/></connection>"""))
    with pytest.raises(ConfigErrors) as raised:
        build_application(spec)
    [error] = raised.value.errors
    assert error.location.file == str(tmp_path / "app.xml") and error.location.line == 16
    assert "cam2/filter" in error.message and "window" in error.message
    assert "(in composite instance" not in error.message  # the connection is the application's


def test_the_rgbd_example_gives_each_camera_its_own_mesh_pipeline():
    """config/composite_rgbd_meshes.xml: the issue's two cameras, each with its own RGB-D -> mesh
    pipeline (config/composites/rgbd_mesh.xml), each mesh into a tree builder of the application."""
    spec = load_application(CONFIG / "composite_rgbd_meshes.xml", args={"bag": "/data/session"})
    assert [c.name for c in spec.composites] == ["front", "side"]
    components = {c.name: c for c in spec.all_components()}
    assert [name for name in components if name.startswith(("front/", "side/"))] == [
        "front/camera", "front/recording", "front/mesher", "side/camera", "side/recording", "side/mesher"]
    strides = {name: {a.name: a.value for a in components[name].attributes}["stride"]
               for name in ("front/mesher", "side/mesher")}
    assert strides == {"front/mesher": "2", "side/mesher": "4"}
    assert {a.name: a.value for a in components["side/recording"].attributes}["path"] == "/data/session"
    assert {a.name: a.schedule.period_ms for a in spec.activities if a.name.endswith("acquisition")} == {
        "front/acquisition": 33.0, "side/acquisition": 66.0}
    assert [(str(c.src), str(c.dest), c.data) for c in spec.connections[-2:]] == [
        ("front/mesher.mesh", "front_tree.cloud", BufferPolicy.POOL),
        ("side/mesher.mesh", "side_tree.cloud", BufferPolicy.POOL)]


def test_an_exposed_endit_cannot_end_a_connection(tmp_path):
    app = two_instances(tmp_path, outer="""<connection>
      <src activity="recording" port="endit"/><dest task="cam1" port="done"/></connection>""")
    assert errors_of(app) == [
        ("app.xml", 17, "<dest> names activity 'cam1/filtering''s endit port (an exposed port), but a connection "
                        "ends at an activity's beginit"),
    ]
