"""The scheduling tree as ``--check`` prints it: :meth:`coco_core.deployment.Deployment.render`.

One text for the whole plan, host by host: each host's processes with their settings (the launch
host's, such as an executor's threads, included), each activity with the driver the plan gives it
and why, the components each runs (their classes, from the built parts: building every part is what
checks it), the connections inside each process, between processes (shared memory) and between
hosts (DDS). Every process of a run logs the same activity lines (:func:`coco_core.deployment.deployed`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Mapping, Sequence

from .policy import ConnectionPolicy
from .processes.placement import LAUNCHER

if TYPE_CHECKING:
    from .application import Application
    from .connections import Connection
    from .deployment import Deployment, HostDeployment
    from .model import AppSpec


def render(deployment: Deployment, parts: Mapping[str, Mapping[str, Application]],
           notes: Mapping[str, Sequence[str]]) -> str:
    """Every host of ``deployment`` in turn; ``parts``: each host's built processes (by host, then
    process); ``notes``: what the launch host adds under a host's tree (lines)."""
    return "\n".join("\n".join([_host(host, parts.get(name, {})), *notes.get(name, ())])
                     for name, host in deployment.hosts.items())


def _host(deployment: HostDeployment, parts: Mapping[str, Application]) -> str:
    spec = deployment.spec
    lines = [f"application {spec.name}" + _host_words(spec), f"  deployment: {deployment.rules}",
             *_composite_lines(spec)]
    launcher = deployment.processes[LAUNCHER]
    if len(deployment.processes) == 1 and launcher.asks_nothing:
        lines += _activity_lines(deployment, parts.get(LAUNCHER), LAUNCHER, "  ")
        return "\n".join(lines + _between_hosts_lines(spec))
    for name, process in deployment.processes.items():
        details = process.describe()
        lines.append(f"  process {name or 'launcher'}" + (f" ({details})" if details else ""))
        lines += _activity_lines(deployment, parts.get(name), name, "    ")
    crossing = deployment.crossings
    if crossing:
        lines.append("  between processes (shared memory):")
        for crossed in crossing:
            connection = crossed.connection
            policy = ConnectionPolicy(connection.data, connection.policy, max(1, connection.buffersize))
            lines.append(f"    {connection.src} -> {connection.dest}  {policy}  "
                         f"({crossed.src_process or 'launcher'} -> {crossed.dest_process or 'launcher'})")
    return "\n".join(lines + _between_hosts_lines(spec))


def _activity_lines(deployment: HostDeployment, part: Application | None, process: str, indent: str) -> list[str]:
    """The process's activities, each with its plan's line and (from its built ``part``) the
    components it runs, then the part's connections; without a part, the plan's lines only."""
    if part is None:
        return [f"{indent}{placed.line()}" for placed in deployment.of_process(process)]
    lines = []
    for activity, components in part.schedule_tree():
        if activity is not None and activity.process != part.process:
            continue  # the launcher's stand-in of a child's activity: the child's part shows it
        lines.append(f"{indent}{deployment.activities[activity.name].line()}" if activity else f"{indent}(no activity)")
        for top in components:
            for component in top.walk():
                depth = 0
                owner = component.owner
                while owner is not None:
                    depth, owner = depth + 1, owner.owner
                lines.append(f"{indent}  {'  ' * depth}{component.name} ({type(component).__name__})")
    return lines + [_connection_line(connection, indent) for connection in part.connections]


def _connection_line(connection: Connection, indent: str) -> str:
    return f"{indent}{connection.source.qualified_name} -> {connection.sink.qualified_name}  {connection.describe()}"  # type: ignore[union-attr]


def _composite_lines(spec: AppSpec) -> list[str]:
    """The composite instances (FlowVR's hierarchy): each with its file, where it is made, its args,
    exposed ports and own parts, indented under the instance it is in."""
    if not spec.composites:
        return []
    lines = ["  composites:"]
    for composite in spec.composites:
        indent = "    " + "  " * composite.name.count("/")
        args = ", ".join(f"{name}={value}" for name, value in composite.args.items())
        lines.append(f"{indent}{composite.name}: {composite.file} (at {composite.location})")
        if args:
            lines.append(f"{indent}  args: {args}")
        for name, target in composite.ports.items():
            lines.append(f"{indent}  port {name} -> {target}" + (" (activity)" if target.activity else ""))
        if composite.components:
            lines.append(f"{indent}  components: {', '.join(composite.components)}")
        if composite.activities:
            lines.append(f"{indent}  activities: {', '.join(composite.activities)}")
    return lines


def _host_words(spec: AppSpec) -> str:
    """``, host H of A, B`` for one host's part (the first host's clock is the application's)."""
    if not spec.part_of:
        return ""
    first = spec.hosts[0].name
    clock = " (the application's clock)" if spec.part_of == first else f" (on {first}'s clock)"
    return f", host {spec.part_of} of {', '.join(h.name for h in spec.hosts)}{clock}"


def _between_hosts_lines(spec: AppSpec) -> list[str]:
    """The connections between this host and the others, with their DDS topics."""
    if not spec.between_hosts:
        return []
    lines = ["  between hosts (DDS):"]
    for channel in spec.between_hosts:
        ends = (f"{channel.src_host}/{channel.src_process or 'launcher'} -> "
                f"{channel.dest_host}/{channel.dest_process or 'launcher'}")
        extra = ", stamps only" if channel.stamps_only else f", {channel.codec}"
        lines.append(f"    {channel.src} -> {channel.dest}  {channel.policy}{extra}  ({ends}, topic {channel.topic})")
    return lines
