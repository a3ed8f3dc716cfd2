"""Which connections between hosts can carry their writer's values, known before anything runs.

Values cross between hosts in the typed encoding of :mod:`coco_core.wire`, which carries plain data
and registered value types only. A writer's port declares its type, so a connection whose values
could never cross is found from the file and the installed components alone: ``--check`` reports
it and a launch refuses to start, naming the connection, instead of the writer failing at its
first write on another machine.
"""

from __future__ import annotations

from .. import registry
from ..model import AppSpec
from ..ports import OutputPort, PooledOutputPort
from ..wire import crossing_problem


def crossing_problems(spec: AppSpec) -> list[str]:
    """The connections between hosts that ``spec`` (one host's part) writes whose values cannot
    cross, from the writer's declared port type (:func:`coco_core.wire.crossing_problem`), each
    with the connection: what ``--check`` reports and a launch refuses, before any value is sent.
    Pooled frames and stamps-only connections always can; a port declared ``object`` is checked as
    its values are sent."""
    components = {component.name: component for component in spec.all_components()}
    problems = []
    for channel in spec.between_hosts:
        if channel.src_host != spec.part_of or channel.stamps_only or channel.src_activity:
            continue
        name, _, port_name = channel.src.rpartition(".")
        component = components.get(name)
        if component is None:
            continue
        port = getattr(registry.load(component.task, component.library), port_name, None)
        if not isinstance(port, OutputPort) or isinstance(port, PooledOutputPort):
            continue
        problem = crossing_problem(port.type)
        if problem:
            problems.append(f"connection {channel.label} between hosts {channel.src_host} and {channel.dest_host}: "
                            f"{problem}")
    return problems
