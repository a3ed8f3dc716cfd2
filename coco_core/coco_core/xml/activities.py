"""``<activity>``: a schedule and the components it runs, in order.

In the later layout an activity's ``<component name="X"/>`` refers to a component defined in
``<package><components>``; in the per-activity layout the activity holds the full definition, which
both defines the component and schedules it here. A ``<component>`` with child elements is a
definition, one without is a reference.
"""

from __future__ import annotations

from ..model import ActivitySpec, ScheduleSpec
from .components import read_component
from .draft import Draft, Scheduled
from .reader import CONDITIONS, FileReader
from .schedule import ACTIVITY_SCHEDULE_ATTRIBUTES, read_schedule
from .tree import Element

ACTIVITY_ATTRIBUTES = ("name", *CONDITIONS)
ACTIVITY_CHILDREN = ("components", "schedule", "schedulepolicy")
REFERENCE_ATTRIBUTES = ("name", *CONDITIONS)


def read_activity(
    reader: FileReader, element: Element, draft: Draft, on_error_default: str
) -> None:
    """Add an ``<activity>`` whose conditions held, and the components it defines, to ``draft``."""
    values = reader.attributes(element, ACTIVITY_ATTRIBUTES)
    draft.activity_count += 1
    name = values.get("name", "").strip() or f"activity{draft.activity_count}"
    children = reader.children(element, ACTIVITY_CHILDREN)

    schedules = [child for child in children if child.tag != "components"]
    for extra in schedules[1:]:
        reader.error(
            f"<activity> has more than one schedule (the first is at line "
            f"{schedules[0].location.line})",
            extra,
        )
    if schedules:
        schedule_values = reader.attributes(schedules[0], ACTIVITY_SCHEDULE_ATTRIBUTES)
        reader.empty(schedules[0])
        schedule = read_schedule(reader, schedules[0], schedule_values)
    else:
        reader.error(
            "<activity> needs a <schedule> (<schedulepolicy> in the per-activity layout)", element
        )
        schedule = ScheduleSpec(location=element.location)

    components: list[str] = []
    components_element = reader.once(element, children, "components")
    if components_element is None:
        reader.error("<activity> needs <components>: the components it runs", element)
    else:
        for child in reader.container(components_element, ("component",)):
            if not reader.kept(child):
                continue
            component = _scheduled_name(reader, child, draft, on_error_default)
            if component:
                components.append(component)
                draft.scheduled.append(Scheduled(component, name, child.location))
    draft.activities.append(ActivitySpec(name, schedule, components, element.location))


def _scheduled_name(
    reader: FileReader, element: Element, draft: Draft, on_error_default: str
) -> str | None:
    """The component an activity's ``<component>`` runs; a definition is also added to ``draft``."""
    if element.children:
        spec = read_component(reader, element, draft, on_error_default)
        if spec is None:
            return None
        draft.components.append(spec)
        return spec.name
    values = reader.attributes(element, REFERENCE_ATTRIBUTES, required=("name",))
    reader.empty(element)
    return values.get("name", "").strip() or None
