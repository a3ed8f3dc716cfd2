"""``<host>``: the scheduling tree's top level, around processes and activities.

    <activities>
        <host name="robot">
            <activity name="replay"> ... </activity>
        </host>
        <host name="graphics">
            <process name="view"> <activity name="draw"> ... </activity> </process>
        </host>
    </activities>

Every host runs the same file (``coco-launch app.xml --host graphics``) and builds only its own
part; a connection between two hosts travels over DDS (:mod:`coco_core.hosts`). Activities outside
any ``<host>`` run on the first one, which is also the application's clock.
"""

from __future__ import annotations

from collections.abc import Callable

from ..model import HostSpec
from .draft import Draft
from .reader import CONDITIONS, FileReader
from .tree import Element

HOST_ATTRIBUTES = ("name", *CONDITIONS)
HOST_CHILDREN = ("activity", "farm", "pipeline", "process")


def read_host(reader: FileReader, element: Element, draft: Draft, read_child: Callable[[Element], None]) -> None:
    """Add a ``<host>`` whose conditions held, and what it holds, to ``draft``; ``read_child`` reads
    one ``<process>``, ``<activity>``, ``<pipeline>`` or ``<farm>`` as outside a host."""
    values = reader.attributes(element, HOST_ATTRIBUTES, required=("name",))
    name = values.get("name", "").strip()
    first_activity, first_process = len(draft.activities), len(draft.processes)
    for child in reader.children(element, HOST_CHILDREN):
        if reader.kept(child):
            read_child(child)
    for activity in draft.activities[first_activity:]:
        activity.host = name
    for process in draft.processes[first_process:]:
        process.host = name
    if first_activity == len(draft.activities):
        reader.error(f"<host> {name!r} has no activity: give it <process>, <activity>, <pipeline> or <farm> "
                     "elements", element)
    draft.hosts.append(HostSpec(name, element.location))
