"""<pipeline>: expansion into triggered activities joined by buffered, event-carrying connections."""

import pytest

from coco_core.errors import ConfigErrors
from coco_core.policy import BufferPolicy, SyncPolicy
from coco_core.xml import parse_application_string


def pipeline_app(schedule: str, stages: str, connections: str = "", attributes: str = "") -> str:
    return f"""<package>
  <components>
    <component><task>Src</task></component>
    <component><task>S1</task></component>
    <component><task>S2</task></component>
    <component><task>S3</task></component>
  </components>
  <connections>{connections}</connections>
  <activities>
    <pipeline{attributes}>
      {schedule}
      <components>
{stages}
      </components>
    </pipeline>
  </activities>
</package>"""


STAGES = """        <component name="S1" in="i" out="o"/>
        <component name="S2" in="i" out="o"/>
        <component name="S3" in="i"/>"""


def errors_of(text: str) -> list[tuple[int | None, str]]:
    with pytest.raises(ConfigErrors) as raised:
        parse_application_string(text)
    return [(e.location.line if e.location else None, e.message) for e in raised.value.errors]


def test_parallel_pipeline_gives_each_stage_a_triggered_activity():
    app = parse_application_string(
        pipeline_app('<schedule activity="parallel" realtime="RR" priority="10" affinity="1"/>', STAGES)
    )
    assert [(a.name, a.components) for a in app.activities] == [
        ("pipeline1.S1", ["S1"]),
        ("pipeline1.S2", ["S2"]),
        ("pipeline1.S3", ["S3"]),
    ]
    for activity in app.activities:
        assert activity.schedule.type == "triggered"
        assert (activity.schedule.realtime, activity.schedule.priority) == ("RR", 10)
        assert activity.schedule.affinity == [1]
    first, second = app.activities[0].schedule, app.activities[1].schedule
    assert first is not second and first.affinity is not second.affinity
    assert [(str(c.src), str(c.dest)) for c in app.connections] == [("S1.o", "S2.i"), ("S2.o", "S3.i")]
    for connection in app.connections:
        assert connection.data is BufferPolicy.BUFFER
        assert connection.policy is SyncPolicy.LOCKED
        assert connection.buffersize == 10
        assert connection.event is True


def test_sequential_pipeline_is_one_activity_with_unsynchronised_links():
    app = parse_application_string(
        pipeline_app('<schedule activity="sequential" buffersize="3"/>', STAGES, attributes=' name="chain"')
    )
    (activity,) = app.activities
    assert (activity.name, activity.components, activity.schedule.type) == ("chain", ["S1", "S2", "S3"], "triggered")
    assert activity.schedule.activity == "sequential"
    assert [(c.policy, c.buffersize) for c in app.connections] == [(SyncPolicy.UNSYNC, 3)] * 2


def test_schedule_is_optional_and_stages_can_be_conditional():
    stages = """        <component name="S1" in="i" out="o"/>
        <component name="S2" in="i" out="o" if="false"/>
        <component name="S3" in="i"/>"""
    app = parse_application_string(pipeline_app("", stages))
    assert [a.name for a in app.activities] == ["pipeline1.S1", "pipeline1.S3"]
    assert [(str(c.src), str(c.dest)) for c in app.connections] == [("S1.o", "S3.i")]


def test_connections_into_the_first_stage_wake_the_pipeline():
    connections = """
    <connection data="BUFFER" buffersize="5"><src task="Src" port="o"/><dest task="S1" port="i"/></connection>
    <connection event="false"><src task="Src" port="o"/><dest task="S1" port="i"/></connection>
    <connection><src task="Src" port="o"/><dest task="S2" port="other"/></connection>"""
    app = parse_application_string(pipeline_app("", STAGES, connections))
    explicit = app.connections[:3]
    assert [c.event for c in explicit] == [True, False, None]


def test_pipeline_errors():
    stages = """        <component name="S1" in="i"/>
        <component name="S2" out="o"/>
        <component name="Nope" in="i"/>
        <component in="i"/>"""
    text = pipeline_app('<schedule type="periodic" period="10" buffersize="0"/>', stages)
    assert errors_of(text) == [
        (11, 'unexpected attribute type="periodic" in <schedule>; expected one of: activity, '
             "affinity, buffersize, exclusive_affinity, nice, priority, realtime, runtime"),
        (11, 'unexpected attribute period="10" in <schedule>; expected one of: activity, affinity, '
             "buffersize, exclusive_affinity, nice, priority, realtime, runtime"),
        (11, '<schedule> attribute buffersize="0": expected a buffer size of at least 1'),
        (13, "pipeline stage 'S1' needs out=: 'S2' reads from it"),
        (14, "pipeline stage 'S2' needs in=: it reads from 'S1'"),
        (15, "<component name=\"Nope\"> is not a defined component; valid: S1, S2, S3, Src"),
        (16, "<component> needs a name= attribute"),
    ]


def test_stage_scheduled_elsewhere_too():
    text = """<package>
  <components><component><task>A</task></component><component><task>B</task></component></components>
  <activities>
    <activity><schedule/><components><component name="A"/></components></activity>
    <pipeline><components><component name="A" out="o"/><component name="B" in="i"/></components></pipeline>
  </activities>
</package>"""
    assert errors_of(text) == [
        (5, "component 'A' is already scheduled in activity 'activity1' at <string>:4; "
            "a component runs in one activity"),
    ]
