"""The original CoCo sample applications load into the expected model and validate against the schema."""

from pathlib import Path

import pytest

from coco_core.policy import BufferPolicy, SyncPolicy
from coco_core.xml import load_application, parse_application_string

WORKSPACE = Path(__file__).resolve().parents[2]
SAMPLES = Path(__file__).resolve().parents[3] / "shared" / "data" / "coco_xml"
SCHEMA = WORKSPACE / "docs" / "coco.xsd"


@pytest.fixture
def samples() -> Path:
    if not SAMPLES.is_dir():
        pytest.skip(f"the CoCo sample files are not available at {SAMPLES}")
    return SAMPLES


def by_name(items):
    return {item.name: item for item in items}


def test_later_layout_merges_the_include_where_it_stands(samples):
    app = load_application(samples / "config.xml")

    assert app.name == "Example 0"
    assert app.file == str(samples / "config.xml")
    assert [c.name for c in app.components] == ["Task2", "EzTask2", "EzTask1", "Task4", "EzTask4"]
    components = by_name(app.all_components())
    assert components["Task2"].task == "EzTask2"
    assert components["Task2"].location.file == str(samples / "config_include.xml")
    assert components["Task2"].location.line == 7
    assert [(a.name, a.value) for a in components["Task2"].attributes] == [("c", "3"), ("d", "3.3")]
    assert components["Task4"].task == "EzTask4"
    assert components["EzTask4"].task == "EzTask4"
    assert [p.name for p in components["EzTask1"].peers] == ["EzTask3"]
    assert components["EzTask1"].attributes[2].value == "1, 2,3,  5"
    assert components["EzTask1"].library == "component_1"

    assert [(str(c.src), str(c.dest)) for c in app.connections] == [
        ("EzTask1.OUT", "EzTask2.IN"),
        ("EzTask1.OUT", "Task2.IN"),
    ]
    for connection in app.connections:
        assert connection.data is BufferPolicy.BUFFER
        assert connection.policy is SyncPolicy.LOCK_FREE
        assert connection.buffersize == 10
        assert connection.event is None

    activities = by_name(app.activities)
    assert [a.name for a in app.activities] == ["activity1", "activity2", "activity3"]
    assert activities["activity1"].components == ["Task2"]
    assert activities["activity1"].schedule.type == "triggered"
    assert activities["activity1"].schedule.period_ms is None
    assert activities["activity2"].components == ["EzTask1", "EzTask4"]
    assert activities["activity2"].schedule.type == "periodic"
    assert activities["activity2"].schedule.period_ms == 10.0
    assert activities["activity2"].schedule.exclusive_affinity == [2]
    assert activities["activity3"].schedule.exclusive_affinity == [1]

    assert app.log is not None and app.log.levels == [0, 1, 3, 4]
    assert app.log.types == ["debug", "err", "log"]
    assert app.log.outfile == "log2.txt"
    assert app.paths[0] == "/home/pippo/Libraries/coco/build/lib"
    assert app.on_error == ""  # none given: continue, but a refused configuration stops the application


def test_legacy_layout_defines_components_in_their_activities(samples):
    app = load_application(samples / "legacy_config.xml")

    assert app.name == "legacy_config"
    assert [c.name for c in app.components] == ["EzTask1", "EzTask4", "EzTask2"]
    assert [p.name for p in app.components[0].peers] == ["EzTask3"]
    first, second = app.activities
    assert first.components == ["EzTask1", "EzTask4"]
    assert (first.schedule.type, first.schedule.period_ms) == ("periodic", 1000.0)
    assert first.schedule.exclusive_affinity == [2]
    assert second.components == ["EzTask2"]
    assert (second.schedule.type, second.schedule.period_ms) == ("triggered", None)
    assert app.paths == [str(samples / "buildnew" / "lib")]
    (connection,) = app.connections
    assert (connection.data, connection.policy, connection.buffersize) == (
        BufferPolicy.BUFFER,
        SyncPolicy.LOCKED,
        10,
    )
    assert app.log is not None and app.log.levels == [0, 1, 2, 3, 4]


def test_pipeline_sample_is_expanded(samples):
    app = load_application(samples / "config_pipeline.xml")

    assert [a.name for a in app.activities] == [
        "activity1",
        "pipeline1.Task2",
        "pipeline1.Task3",
        "pipeline1.Task4",
        "activity2",
    ]
    activities = by_name(app.activities)
    assert activities["activity1"].schedule.period_ms == 100.0
    assert activities["activity2"].schedule.period_ms == 500.0
    for stage in ("Task2", "Task3", "Task4"):
        activity = activities[f"pipeline1.{stage}"]
        assert activity.components == [stage]
        assert activity.schedule.type == "triggered"
        assert activity.schedule.realtime == "none"
        assert activity.schedule.priority is None

    connections = {(str(c.src), str(c.dest)): c for c in app.connections}
    assert set(connections) == {
        ("Task2.value_OUT", "Task3.value_IN"),
        ("Task3.value_OUT", "Task4.value_IN"),
        ("Task1.value_OUT", "Task2.value_IN"),
        ("Task4.value_OUT", "Task5.value_IN"),
    }
    stage_link = connections[("Task2.value_OUT", "Task3.value_IN")]
    assert (stage_link.data, stage_link.policy, stage_link.buffersize, stage_link.event) == (
        BufferPolicy.BUFFER,
        SyncPolicy.LOCKED,
        10,
        True,
    )
    # The explicit connection into the first stage wakes the pipeline; the one out of it does not.
    assert connections[("Task1.value_OUT", "Task2.value_IN")].event is True
    assert connections[("Task4.value_OUT", "Task5.value_IN")].event is None
    assert connections[("Task4.value_OUT", "Task5.value_IN")].data is BufferPolicy.DATA


def test_included_file_also_loads_on_its_own(samples):
    app = load_application(samples / "config_include.xml")
    assert [c.name for c in app.components] == ["Task2"]
    assert app.activities[0].components == ["Task2"]


# ----- schema -----------------------------------------------------------------------------------


def schema():
    xmlschema = pytest.importorskip("xmlschema")
    return xmlschema.XMLSchema(str(SCHEMA))


def application_files() -> list[Path]:
    files = sorted(SAMPLES.glob("*.xml")) if SAMPLES.is_dir() else []
    return files + sorted((WORKSPACE / "config").glob("**/*.xml"))


@pytest.mark.parametrize("path", application_files(), ids=lambda path: path.name)
def test_application_files_validate_against_the_schema(path):
    errors = [error.reason for error in schema().iter_errors(str(path))]
    assert errors == []


@pytest.mark.parametrize(
    "path", sorted((WORKSPACE / "config").glob("**/*.xml")), ids=lambda path: path.name
)
def test_workspace_applications_load(path):
    app = load_application(path)
    assert app.file == str(path)


def test_sample_files_are_there_to_validate(samples):
    assert {p.name for p in application_files()} >= {
        "config.xml",
        "config_include.xml",
        "config_pipeline.xml",
        "legacy_config.xml",
    }


EVERY_EXTENSION = """<package name="all" on_error="stop_app">
  <arg name="rate" default="250" doc="control rate"/>
  <arg name="sim" value="true"/>
  <arg name="camera" default="" if="$(arg sim)"/>
  <log><levels>0 1</levels><types>debug err</types><outfile>out.log</outfile></log>
  <paths><path>$(dirname)</path></paths>
  <components>
    <component on_error="stop_component" unless="false">
      <name>src</name>
      <task>SignalGenerator</task>
      <library>coco_core</library>
      <attributes>
        <attribute name="rate" value="$(arg rate)"/>
        <attribute name="unused" value="x" if="$(arg camera)"/>
      </attributes>
    </component>
    <component><task>MovingAverage</task></component>
    <component><task>RangeMonitor</task></component>
  </components>
  <connections>
    <connection data="CIRCULAR" policy="UNSYNC" buffersize="$(arg rate)" event="yes">
      <src task="src" port="out"/>
      <dest task="MovingAverage" port="in"/>
    </connection>
    <connection data="POOL" policy="LOCK_FREE" if="$(arg sim)">
      <src task="MovingAverage" port="out"/>
      <dest task="RangeMonitor" port="in"/>
    </connection>
  </connections>
  <activities>
    <activity name="control">
      <schedule period="$(arg rate)" realtime="FIFO" priority="80" affinity="0,1" main="true"
                nice="-5" runtime=""/>
      <components><component name="src"/></components>
    </activity>
    <pipeline name="filter">
      <schedule activity="sequential" buffersize="4" exclusive_affinity="1"/>
      <components>
        <component name="MovingAverage" in="in" out="out"/>
        <component name="RangeMonitor" in="in"/>
      </components>
    </pipeline>
  </activities>
</package>
"""


def test_every_extension_validates_and_loads():
    errors = [error.reason for error in schema().iter_errors(EVERY_EXTENSION)]
    assert errors == []
    with_schema_hint = EVERY_EXTENSION.replace(
        '<package name="all"',
        '<package xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
        'xsi:noNamespaceSchemaLocation="coco.xsd" name="all"',
    )
    assert schema().is_valid(with_schema_hint)
    assert parse_application_string(with_schema_hint).name == "all"

    app = parse_application_string(EVERY_EXTENSION, args={"rate": "500"})
    assert app.name == "all" and app.on_error == "stop_app"
    assert app.args == {"rate": "500", "sim": "true", "camera": ""}
    assert [a.name for a in app.components[0].attributes] == ["rate"]
    assert app.components[0].attributes[0].value == "500"
    assert app.components[0].on_error == "stop_component"
    control, filter_ = app.activities
    assert (control.schedule.type, control.schedule.period_ms, control.schedule.main) == (
        "periodic",
        500.0,
        True,
    )
    assert (control.schedule.realtime, control.schedule.priority, control.schedule.nice) == ("FIFO", 80, -5)
    assert control.schedule.affinity == [0, 1]
    assert filter_.name == "filter" and filter_.components == ["MovingAverage", "RangeMonitor"]
    first, second, stage_link = app.connections
    assert (first.data, first.policy, first.buffersize, first.event) == (
        BufferPolicy.CIRCULAR,
        SyncPolicy.UNSYNC,
        500,
        True,
    )
    assert (second.data, second.policy, second.event) == (BufferPolicy.POOL, SyncPolicy.LOCK_FREE, None)
    assert (stage_link.policy, stage_link.buffersize) == (SyncPolicy.UNSYNC, 4)


@pytest.mark.parametrize(
    "fragment",
    [
        '<connections><connection data="FOO"><src task="a" port="o"/><dest task="b" port="i"/></connection></connections>',
        "<activities><farm/></activities>",
        '<activities><activity><schedule realtime="DEADLINE"/><components/></activity></activities>',
        "<bogus/>",
        '<components><component><task>t</task><attributes><attribute name="a" type="dir"/></attributes></component></components>',
    ],
)
def test_schema_rejects_what_the_loader_rejects(fragment):
    assert not schema().is_valid(f"<package>{fragment}</package>")


def test_schema_keeps_the_original_copyright():
    text = SCHEMA.read_text()
    assert "Copyright (c) 2016, Scuola Superiore Sant'Anna" in text
    assert "targetNamespace" not in text
