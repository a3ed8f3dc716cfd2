"""``<pipeline>``: a chain of components, each fed by the one before it, expanded into plain parts.

A pipeline is shorthand. Its stages are joined by buffered, event-carrying connections
(``out`` of one stage to ``in`` of the next), so that each stage runs when its input arrives:
``parallel`` gives each stage its own triggered activity (named ``<pipeline>.<component>``), so
stages overlap; ``sequential`` runs all stages in order in one triggered activity named after the
pipeline, with unsynchronised connections since writer and reader share that thread.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

from ..errors import AttributeValueError, Location
from ..model import ActivitySpec, ConnectionSpec, PortRef, ScheduleSpec
from ..policy import BufferPolicy, SyncPolicy
from .draft import Draft, Scheduled
from .reader import CONDITIONS, FileReader
from .schedule import PIPELINE_SCHEDULE_ATTRIBUTES, read_schedule
from .tree import Element
from .values import parse_int

PIPELINE_ATTRIBUTES = ("name", *CONDITIONS)
STAGE_ATTRIBUTES = ("in", "name", "out", *CONDITIONS)
DEFAULT_BUFFER_SIZE = 10


@dataclass
class Stage:
    component: str
    input: str
    output: str
    element: Element

    @property
    def location(self) -> Location:
        return self.element.location


@dataclass
class Pipeline:
    """A pipeline as read: its stages, the schedule each stage's activity gets, the buffer size of
    the connections between stages."""

    name: str
    schedule: ScheduleSpec
    buffer_size: int
    stages: list[Stage]
    element: Element

    @property
    def sequential(self) -> bool:
        return self.schedule.activity == "sequential"


def read_pipeline(reader: FileReader, element: Element, draft: Draft) -> None:
    """Add the activities and connections of a ``<pipeline>`` whose conditions held to ``draft``."""
    values = reader.attributes(element, PIPELINE_ATTRIBUTES)
    draft.pipeline_count += 1
    pipeline = read_stages(reader, element, values.get("name", "").strip() or f"pipeline{draft.pipeline_count}")
    check_stages(reader, pipeline.stages)
    draft.connections.extend(stage_connections(pipeline, lambda name: name))
    draft.activities.extend(stage_activities(pipeline, pipeline.name, lambda name: name, draft))
    if pipeline.stages and pipeline.stages[0].input:
        first = pipeline.stages[0]
        draft.pipeline_inputs.append(PortRef(first.component, first.input, first.location))


def read_stages(reader: FileReader, element: Element, name: str) -> Pipeline:
    """The schedule and stages of a ``<pipeline>`` (on its own or in a ``<farm>``)."""
    children = reader.children(element, ("components", "schedule"))
    schedule_element = reader.once(element, children, "schedule")
    schedule = ScheduleSpec(location=element.location)
    buffer_size = DEFAULT_BUFFER_SIZE
    if schedule_element is not None:
        schedule_values = reader.attributes(schedule_element, PIPELINE_SCHEDULE_ATTRIBUTES)
        reader.empty(schedule_element)
        schedule = read_schedule(reader, schedule_element, schedule_values)
        buffer_size = (
            reader.parsed(schedule_element, schedule_values, "buffersize", _buffer_size)
            or DEFAULT_BUFFER_SIZE
        )
    stages: list[Stage] = []
    components_element = reader.once(element, children, "components")
    if components_element is None:
        reader.error("<pipeline> needs <components>: its stages, in order", element)
    else:
        for child in reader.container(components_element, ("component",)):
            if reader.kept(child):
                stage = _read_stage(reader, child)
                if stage is not None:
                    stages.append(stage)
    return Pipeline(name, schedule, buffer_size, stages, element)


def check_stages(reader: FileReader, stages: list[Stage]) -> None:
    """Each stage but the last needs ``out=``, each but the first ``in=``."""
    for before, after in zip(stages, stages[1:]):
        if not before.output:
            reader.error(
                f"pipeline stage {before.component!r} needs out=: {after.component!r} reads from it",
                before.element,
            )
        if not after.input:
            reader.error(
                f"pipeline stage {after.component!r} needs in=: it reads from {before.component!r}",
                after.element,
            )


def stage_connections(pipeline: Pipeline, rename: Callable[[str], str]) -> list[ConnectionSpec]:
    """Each stage's output to the next one's input (components named through ``rename``)."""
    sync = SyncPolicy.UNSYNC if pipeline.sequential else SyncPolicy.LOCKED
    return [
        ConnectionSpec(
            src=PortRef(rename(before.component), before.output, before.location),
            dest=PortRef(rename(after.component), after.input, after.location),
            data=BufferPolicy.BUFFER,
            policy=sync,
            buffersize=pipeline.buffer_size,
            event=True,
            location=before.location,
        )
        for before, after in zip(pipeline.stages, pipeline.stages[1:])
        if before.output and after.input
    ]


def stage_activities(
    pipeline: Pipeline, name: str, rename: Callable[[str], str], draft: Draft
) -> list[ActivitySpec]:
    """The activities that run the stages: one per stage named ``name.component`` (parallel), or
    one named ``name`` (sequential); the components are noted as scheduled in ``draft``."""
    stages = pipeline.stages
    if pipeline.sequential:
        groups = [(name, stages, pipeline.element.location)]
    else:
        groups = [(f"{name}.{rename(stage.component)}", [stage], stage.location) for stage in stages]
    activities = []
    for activity_name, members, location in groups:
        schedule = replace(
            pipeline.schedule,
            affinity=list(pipeline.schedule.affinity),
            exclusive_affinity=list(pipeline.schedule.exclusive_affinity),
        )
        components = [rename(stage.component) for stage in members]
        activities.append(ActivitySpec(activity_name, schedule, components, location))
        draft.scheduled.extend(
            Scheduled(component, activity_name, stage.location) for component, stage in zip(components, members)
        )
    return activities


def _read_stage(reader: FileReader, element: Element) -> Stage | None:
    values = reader.attributes(element, STAGE_ATTRIBUTES, required=("name",))
    reader.empty(element)
    component = values.get("name", "").strip()
    if not component:
        return None
    return Stage(component, values.get("in", "").strip(), values.get("out", "").strip(), element)


def _buffer_size(text: str) -> int:
    expected = "a buffer size of at least 1"
    size = parse_int(text, expected)
    if size < 1:
        raise AttributeValueError(expected)
    return size
