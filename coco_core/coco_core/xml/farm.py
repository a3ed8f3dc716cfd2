"""``<farm>``: a pipeline replicated over workers, fed by one source and collected by one gather.

The original CoCo launcher's element, built from this project's parts as the original builds it
(``GraphLoader::startFarm``): the source runs in an activity with the source's own schedule, each
worker is a copy of the pipeline (worker 0 uses the components as defined, worker *i* copies named
``name_i``, peers included), run as a pipeline is, and the gather runs in a triggered activity. The
source's output hands each value to one worker, a free one first (a *shared* connection, see
:meth:`~coco_core.ports.OutputPort.share`); every worker's last stage feeds the gather.

    <farm name="detect">
      <schedule workers="3"/>
      <source><schedule type="periodic" period="33"/><component name="camera" out="image"/></source>
      <pipeline><schedule activity="parallel"/><components>
        <component name="detector" in="image" out="boxes"/>
      </components></pipeline>
      <gather><component name="tracker" in="boxes"/></gather>
    </farm>

The copies can only be made once every component definition is read (a farm may name components
defined further down or in an include), so a farm is read into a :class:`FarmDraft` and expanded by
:func:`expand_farms` with the whole-application checks.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from ..errors import AttributeValueError, Location
from ..model import ActivitySpec, ComponentSpec, ConnectionSpec, PortRef, ScheduleSpec
from ..policy import BufferPolicy, SyncPolicy
from .draft import Draft, Scheduled
from .pipeline import Pipeline, check_stages, read_stages, stage_activities, stage_connections
from .reader import CONDITIONS, FileReader
from .schedule import ACTIVITY_SCHEDULE_ATTRIBUTES, read_schedule
from .tree import Element
from .values import parse_bool, parse_int

FARM_ATTRIBUTES = ("name", *CONDITIONS)
FARM_CHILDREN = ("gather", "pipeline", "schedule", "source")
FARM_SCHEDULE_ATTRIBUTES = ("discard_old_data", "workers")
MAX_WORKERS = 256
"""More workers than this is a typo: each is a copy of every stage, with a thread each."""


@dataclass
class End:
    """The source's ``<component name= out=>`` or the gather's ``<component name= in=>``."""

    component: str
    port: str
    location: Location


@dataclass
class FarmDraft:
    """A farm as read, and where its activities and connections go in document order."""

    name: str
    workers: int
    source: End | None
    source_schedule: ScheduleSpec
    pipeline: Pipeline
    gather: End | None
    activity_index: int
    connection_index: int


def read_farm(reader: FileReader, element: Element, draft: Draft) -> None:
    """Note a ``<farm>`` whose conditions held in ``draft`` (see :func:`expand_farms`)."""
    values = reader.attributes(element, FARM_ATTRIBUTES)
    draft.farm_count += 1
    name = values.get("name", "").strip() or f"farm{draft.farm_count}"
    children = reader.children(element, FARM_CHILDREN)
    workers = _workers(reader, element, reader.once(element, children, "schedule"))

    source, source_schedule = None, ScheduleSpec(location=element.location)
    source_element = reader.once(element, children, "source")
    if source_element is None:
        reader.error("<farm> needs a <source>: the component that feeds the workers", element)
    else:
        source, source_schedule = _source(reader, source_element)

    pipeline_element = reader.once(element, children, "pipeline")
    if pipeline_element is None:
        reader.error("<farm> needs a <pipeline>: what each worker runs", element)
        pipeline = Pipeline(name, ScheduleSpec(location=element.location), 1, [], element)
    else:
        reader.check_attributes(pipeline_element, ())
        pipeline = read_stages(reader, pipeline_element, name)
        check_stages(reader, pipeline.stages)
        _check_ends(reader, pipeline)

    gather = None
    gather_element = reader.once(element, children, "gather")
    if gather_element is None:
        reader.error("<farm> needs a <gather>: the component that collects the workers' results", element)
    else:
        gather = _end(reader, gather_element, "in")
    draft.farms.append(FarmDraft(
        name, workers, source, source_schedule, pipeline, gather, len(draft.activities), len(draft.connections)
    ))


def expand_farms(draft: Draft) -> None:
    """Turn every farm of ``draft`` into components, activities and connections.

    A worker whose stages are not all defined is not copied: the stages of worker 0 are then
    reported as undefined components, once.
    """
    definitions = {spec.name: spec for spec in draft.components}
    for farm in reversed(draft.farms):  # from the last, so that the recorded positions stay right
        activities: list[ActivitySpec] = []
        connections: list[ConnectionSpec] = []
        if farm.source is not None:
            activities.append(_activity(draft, f"{farm.name}.source", farm.source_schedule, farm.source))
        stages = farm.pipeline.stages
        complete = all(stage.component in definitions for stage in stages)
        for worker in range(farm.workers if complete else 1):
            suffix = f"_{worker}" if worker else ""

            def rename(component: str, suffix: str = suffix) -> str:
                return component + suffix

            if worker:
                draft.components.extend(_copy(definitions[stage.component], suffix) for stage in stages)
            name = f"{farm.name}.worker{worker}" if farm.pipeline.sequential else farm.name
            activities.extend(stage_activities(farm.pipeline, name, rename, draft))
            connections.extend(stage_connections(farm.pipeline, rename))
            if not stages:
                continue
            first, last = stages[0], stages[-1]
            if farm.source is not None and first.input:
                connections.append(_link(farm.source, PortRef(rename(first.component), first.input, first.location),
                                         farm.pipeline.buffer_size, shared=True))
            if farm.gather is not None and last.output:
                source = End(rename(last.component), last.output, last.location)
                connections.append(_link(source, PortRef(farm.gather.component, farm.gather.port,
                                                         farm.gather.location), farm.pipeline.buffer_size))
        if farm.gather is not None:
            gather_schedule = ScheduleSpec(location=farm.gather.location)
            activities.append(_activity(draft, f"{farm.name}.gather", gather_schedule, farm.gather))
        draft.activities[farm.activity_index:farm.activity_index] = activities
        draft.connections[farm.connection_index:farm.connection_index] = connections
    draft.farms.clear()


def _workers(reader: FileReader, farm: Element, schedule: Element | None) -> int:
    if schedule is None:
        reader.error('<farm> needs a <schedule workers="N"/>: how many copies of the pipeline run', farm)
        return 1
    values = reader.attributes(schedule, FARM_SCHEDULE_ATTRIBUTES, required=("workers",))
    reader.empty(schedule)
    if reader.parsed(schedule, values, "discard_old_data", parse_bool):
        reader.warn('<schedule> attribute discard_old_data is ignored (the original CoCo ignores it too): '
                    "a worker reads every value handed to it", schedule)
    return reader.parsed(schedule, values, "workers", _worker_count) or 1


def _worker_count(text: str) -> int:
    expected = f"a number of workers from 1 to {MAX_WORKERS}"
    count = parse_int(text, expected)
    if not 1 <= count <= MAX_WORKERS:
        raise AttributeValueError(expected)
    return count


def _source(reader: FileReader, element: Element) -> tuple[End | None, ScheduleSpec]:
    reader.check_attributes(element, ())
    children = reader.children(element, ("component", "schedule"))
    schedule_element = reader.once(element, children, "schedule")
    schedule = ScheduleSpec(location=element.location)
    if schedule_element is None:
        reader.error("<source> needs a <schedule>: when the source component runs", element)
    else:
        values = reader.attributes(schedule_element, ACTIVITY_SCHEDULE_ATTRIBUTES)
        reader.empty(schedule_element)
        schedule = read_schedule(reader, schedule_element, values)
    return _end(reader, element, "out", children), schedule


def _end(reader: FileReader, element: Element, port: str, children: list[Element] | None = None) -> End | None:
    """The one ``<component name=... in|out=...>`` of a ``<source>`` or ``<gather>``."""
    if children is None:
        reader.check_attributes(element, ())
        children = reader.children(element, ("component",))
    component = reader.once(element, children, "component")
    if component is None:
        reader.error(f'<{element.tag}> needs a <component name="..." {port}="..."/>', element)
        return None
    values = reader.attributes(component, ("name", port), required=("name", port))
    reader.empty(component)
    name, port_name = values.get("name", "").strip(), values.get(port, "").strip()
    return End(name, port_name, component.location) if name and port_name else None


def _check_ends(reader: FileReader, pipeline: Pipeline) -> None:
    """The source feeds the first stage's input, the last stage's output feeds the gather."""
    if not pipeline.stages:
        return
    first, last = pipeline.stages[0], pipeline.stages[-1]
    if not first.input:
        reader.error(f"farm stage {first.component!r} needs in=: the source feeds it", first.element)
    if not last.output:
        reader.error(f"farm stage {last.component!r} needs out=: it feeds the gather", last.element)


def _activity(draft: Draft, name: str, schedule: ScheduleSpec, end: End) -> ActivitySpec:
    draft.scheduled.append(Scheduled(end.component, name, end.location))
    return ActivitySpec(name, schedule, [end.component], end.location)


def _link(source: End, dest: PortRef, buffer_size: int, shared: bool = False) -> ConnectionSpec:
    return ConnectionSpec(
        src=PortRef(source.component, source.port, source.location),
        dest=dest,
        data=BufferPolicy.BUFFER,
        policy=SyncPolicy.LOCKED,
        buffersize=buffer_size,
        event=True,
        location=source.location,
        shared=shared,
    )


def _copy(spec: ComponentSpec, suffix: str) -> ComponentSpec:
    """A worker's copy of a stage: the same definition, named ``name + suffix``, peers too. The
    attributes are the definition's own objects, so that the resolution of ``type="file"`` values,
    which comes later, holds for the copies too."""
    return dataclasses.replace(
        spec,
        name=spec.name + suffix,
        attributes=list(spec.attributes),
        peers=[_copy(peer, suffix) for peer in spec.peers],
    )
