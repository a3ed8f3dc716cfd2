"""``<process>``: the scheduling tree's top level, around activities and pipelines.

    <activities>
        <process name="haptics" affinity="1" nice="-5">
            <activity name="loop"> ... </activity>
        </process>
        <activity name="display"> ... </activity>   <!-- the launcher's own process -->
    </activities>

Activities outside any ``<process>`` run in the launcher's process, as they always did; each
``<process>`` becomes a child process of the launcher that builds only the components of its own
activities. ``affinity`` (cores) and ``nice`` apply to the whole child process; an activity's own
``<schedule>`` settings still apply to its thread inside it. For a real-time loop (a 1 kHz haptic
process): ``lock_memory="true"`` locks the process's memory in RAM (mlockall) and ``gc="between_cycles"``
keeps CPython's garbage collector out of its cycles (:mod:`coco_core.garbage`).
"""

from __future__ import annotations

from collections.abc import Callable

from ..garbage import GC_MODES
from ..model import ProcessSpec
from .draft import Draft
from .reader import CONDITIONS, FileReader
from .tree import Element
from .schedule import parse_nice
from .values import parse_bool, parse_cores

PROCESS_ATTRIBUTES = ("affinity", "gc", "lock_memory", "name", "nice", *CONDITIONS)
PROCESS_CHILDREN = ("activity", "farm", "pipeline")


def read_process(
    reader: FileReader, element: Element, draft: Draft, read_child: Callable[[Element], None]
) -> None:
    """Add a ``<process>`` whose conditions held, and the activities inside it, to ``draft``;
    ``read_child`` reads one ``<activity>``, ``<pipeline>`` or ``<farm>`` as outside a process."""
    values = reader.attributes(element, PROCESS_ATTRIBUTES, required=("name",))
    name = values.get("name", "").strip()
    spec = ProcessSpec(
        name=name,
        affinity=reader.parsed(element, values, "affinity", parse_cores) or [],
        nice=reader.parsed(element, values, "nice", parse_nice),
        lock_memory=bool(reader.parsed(element, values, "lock_memory", parse_bool)),
        gc=reader.choice(element, values, "gc", GC_MODES, "auto"),
        location=element.location,
    )
    first = len(draft.activities)
    for child in reader.children(element, PROCESS_CHILDREN):
        if reader.kept(child):
            read_child(child)
    for activity in draft.activities[first:]:
        activity.process = name
    if first == len(draft.activities):
        reader.error(f"<process> {name!r} has no activity: give it <activity>, <pipeline> or <farm> elements",
                     element)
    draft.processes.append(spec)
