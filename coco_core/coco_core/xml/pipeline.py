"""``<pipeline>``: a chain of components, each fed by the one before it, expanded into plain parts.

A pipeline is shorthand. Its stages are joined by buffered, event-carrying connections
(``out`` of one stage to ``in`` of the next), so that each stage runs when its input arrives:
``parallel`` gives each stage its own triggered activity (named ``<pipeline>.<component>``), so
stages overlap; ``sequential`` runs all stages in order in one triggered activity named after the
pipeline, with unsynchronised connections since writer and reader share that thread.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from ..errors import Location
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
class _Stage:
    component: str
    input: str
    output: str
    element: Element

    @property
    def location(self) -> Location:
        return self.element.location


def read_pipeline(reader: FileReader, element: Element, draft: Draft) -> None:
    """Add the activities and connections of a ``<pipeline>`` whose conditions held to ``draft``."""
    values = reader.attributes(element, PIPELINE_ATTRIBUTES)
    draft.pipeline_count += 1
    name = values.get("name", "").strip() or f"pipeline{draft.pipeline_count}"
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

    stages: list[_Stage] = []
    components_element = reader.once(element, children, "components")
    if components_element is None:
        reader.error("<pipeline> needs <components>: its stages, in order", element)
    else:
        for child in reader.container(components_element, ("component",)):
            if reader.kept(child):
                stage = _read_stage(reader, child)
                if stage is not None:
                    stages.append(stage)

    sequential = schedule.activity == "sequential"
    sync = SyncPolicy.UNSYNC if sequential else SyncPolicy.LOCKED
    _join_stages(reader, draft, stages, sync, buffer_size)
    if sequential:
        activities = [(name, stages, element.location)]
    else:
        activities = [(f"{name}.{stage.component}", [stage], stage.location) for stage in stages]
    for activity_name, members, location in activities:
        copy = replace(
            schedule,
            affinity=list(schedule.affinity),
            exclusive_affinity=list(schedule.exclusive_affinity),
        )
        draft.activities.append(
            ActivitySpec(activity_name, copy, [stage.component for stage in members], location)
        )
        draft.scheduled.extend(
            Scheduled(stage.component, activity_name, stage.location) for stage in members
        )


def _join_stages(
    reader: FileReader, draft: Draft, stages: list[_Stage], sync: SyncPolicy, buffer_size: int
) -> None:
    """Connect each stage's output to the next one's input, and note the pipeline's input."""
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
        if before.output and after.input:
            draft.connections.append(
                ConnectionSpec(
                    src=PortRef(before.component, before.output, before.location),
                    dest=PortRef(after.component, after.input, after.location),
                    data=BufferPolicy.BUFFER,
                    policy=sync,
                    buffersize=buffer_size,
                    event=True,
                    location=before.location,
                )
            )
    if stages and stages[0].input:
        first = stages[0]
        draft.pipeline_inputs.append(PortRef(first.component, first.input, first.location))


def _read_stage(reader: FileReader, element: Element) -> _Stage | None:
    values = reader.attributes(element, STAGE_ATTRIBUTES, required=("name",))
    reader.empty(element)
    component = values.get("name", "").strip()
    if not component:
        return None
    return _Stage(component, values.get("in", "").strip(), values.get("out", "").strip(), element)


def _buffer_size(text: str) -> int:
    expected = "a buffer size of at least 1"
    size = parse_int(text, expected)
    if size < 1:
        raise ValueError(expected)
    return size
