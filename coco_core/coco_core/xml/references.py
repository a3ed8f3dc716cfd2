"""Checks that need the whole application: unique names, references that resolve, files that exist.

They run once every file is read, because a file may refer to a component defined further down or
in another file, a ``type="file"`` attribute or a ``<urdf>`` file is searched in every resource path
the application declares, and ``<transforms>`` sections of several files declare one graph. They
also complete what only the whole application tells: the absolute path of each ``type="file"``
attribute and ``<urdf>`` file, and ``event`` on connections that feed a pipeline.
"""

from __future__ import annotations

from ..errors import ConfigError, Location, did_you_mean
from ..model import ActivitySpec, ComponentSpec, HostSpec, ProcessSpec
from .composite import context_of, resolve_exposed, scope_of
from .draft import Draft
from .farm import expand_farms
from .resources import find_resource, not_found_message
from .transforms import check_transforms


def check_draft(draft: Draft) -> list[ConfigError]:
    """Every error of the whole-application checks; completes ``draft`` as a side effect."""
    errors: list[ConfigError] = []
    expand_farms(draft)
    instances, owners = _instances(draft.components, errors)
    resolve_exposed(draft, instances, errors)
    composites = {spec.name: spec for spec in draft.composites}
    unknown_reported: set[tuple[str, Location | None]] = set()

    def known(name: str, location: Location | None, what: str, valid: list[str]) -> bool:
        if name in instances:
            return True
        if (name, location) not in unknown_reported:
            unknown_reported.add((name, location))
            if name in composites:
                message = (f"{what} is a composite instance ({composites[name].file}): its own activities run its "
                           f"components; name one of its exposed ports, or schedule components of the application")
            else:
                scope = scope_of(name, composites)
                valid = [other for other in valid if scope_of(other, composites) == scope]
                message = f"{what} is not a defined component; {did_you_mean(name, valid)}"
            errors.append(ConfigError(message + context_of(name, composites), location))
        return False

    top_level = list(dict.fromkeys(spec.name for spec in draft.components))
    first_scheduled: dict[str, tuple[str, Location]] = {}
    for scheduled in draft.scheduled:
        name, location = scheduled.component, scheduled.location
        if not known(name, location, f'<component name="{name}">', top_level):
            continue
        if name in owners:
            errors.append(ConfigError(
                f"component {name!r} is a peer of {owners[name]!r}: peers are run by their owner "
                "and cannot be scheduled",
                location,
            ))
        elif name in first_scheduled:
            activity, first = first_scheduled[name]
            errors.append(ConfigError(
                f"component {name!r} is already scheduled in activity {activity!r} at {first}; "
                "a component runs in one activity",
                location,
            ))
        else:
            first_scheduled[name] = (scheduled.activity, location)

    every_name = list(instances)
    activities = [activity.name for activity in draft.activities]
    for connection in draft.connections:
        for tag, ref in (("src", connection.src), ("dest", connection.dest)):
            if not ref.activity:
                known(ref.component, ref.location, f'<{tag} task="{ref.component}">', every_name)
            elif ref.component not in activities:
                scope = scope_of(ref.component, composites)
                valid = [activity for activity in activities if scope_of(activity, composites) == scope]
                errors.append(ConfigError(f'<{tag} activity="{ref.component}"> is not a defined activity; '
                                          f"{did_you_mean(ref.component, valid)}{context_of(ref.component, composites)}",
                                          ref.location))

    _check_hosts(draft, errors)
    _check_activities(draft.activities, errors)
    _check_processes(draft.processes, draft.activities, errors)
    _resolve_files(draft, errors)
    if draft.transforms is not None:
        errors.extend(check_transforms(draft.transforms, draft.paths))
    inputs = {(ref.component, ref.port) for ref in draft.pipeline_inputs}
    for connection in draft.connections:
        if connection.event is None and (connection.dest.component, connection.dest.port) in inputs:
            connection.event = True
    return errors


def _instances(
    components: list[ComponentSpec], errors: list[ConfigError]
) -> tuple[dict[str, ComponentSpec], dict[str, str]]:
    """Every component by instance name (reporting duplicates), and the owner of each peer."""
    instances: dict[str, ComponentSpec] = {}
    owners: dict[str, str] = {}
    pending: list[tuple[ComponentSpec, str | None]] = [(c, None) for c in reversed(components)]
    while pending:
        spec, owner = pending.pop()
        if spec.name in instances:
            errors.append(ConfigError(
                f"component name {spec.name!r} is already used at {instances[spec.name].location}; "
                "instance names must be unique (give one of them a <name>)",
                spec.location,
            ))
        else:
            instances[spec.name] = spec
            if owner is not None:
                owners[spec.name] = owner
        pending.extend((peer, spec.name) for peer in reversed(spec.peers))
    return instances, owners


def _check_activities(activities: list[ActivitySpec], errors: list[ConfigError]) -> None:
    """Activity names are unique, and at most one activity of each host takes its main thread."""
    first_named: dict[str, ActivitySpec] = {}
    main: dict[str, ActivitySpec] = {}
    for activity in activities:
        if activity.name in first_named:
            errors.append(ConfigError(
                f"activity name {activity.name!r} is already used at "
                f"{first_named[activity.name].location}",
                activity.location,
            ))
        else:
            first_named[activity.name] = activity
        if activity.schedule.main:
            taken = main.get(activity.host)
            if taken is not None:
                errors.append(ConfigError(
                    f"activity {activity.name!r} asks for the main thread, which activity "
                    f"{taken.name!r} at {taken.schedule.location} already has; only one can"
                    + (f" on host {activity.host!r}" if activity.host else ""),
                    activity.schedule.location,
                ))
            else:
                main[activity.host] = activity


def _check_hosts(draft: Draft, errors: list[ConfigError]) -> None:
    """Host names are unique, and declared in the application's own file (a composite is placed by
    the file that instantiates it); then what is in no ``<host>`` goes to the first one."""
    if not draft.hosts:
        for activity in draft.activities:
            if activity.host:
                errors.append(ConfigError(
                    f"activity {activity.name!r} is in a <host> of a composite; hosts are declared in the "
                    "application's own file, around the activities of the instances", activity.location))
        return
    first_named: dict[str, HostSpec] = {}
    for host in draft.hosts:
        if host.name in first_named:
            errors.append(ConfigError(
                f"host name {host.name!r} is already used at {first_named[host.name].location}; put all of its "
                "processes and activities in one <host>", host.location))
        else:
            first_named[host.name] = host
    for activity in draft.activities:
        if activity.host and activity.host not in first_named:
            errors.append(ConfigError(
                f"activity {activity.name!r} is in a <host> of a composite; hosts are declared in the "
                "application's own file, around the activities of the instances", activity.location))
        activity.host = activity.host or draft.hosts[0].name
    for process in draft.processes:
        process.host = process.host or draft.hosts[0].name


def _check_processes(
    processes: list[ProcessSpec], activities: list[ActivitySpec], errors: list[ConfigError]
) -> None:
    """Process names are unique, and the main thread is the launcher's: a child has none to give."""
    first_named: dict[str, ProcessSpec] = {}
    for process in processes:
        if process.name in first_named:
            errors.append(ConfigError(
                f"process name {process.name!r} is already used at {first_named[process.name].location}; "
                "put all of its activities in one <process>",
                process.location,
            ))
        else:
            first_named[process.name] = process
    for activity in activities:
        if activity.process and activity.schedule.main:
            errors.append(ConfigError(
                f"activity {activity.name!r} asks for the main thread, but it is in process "
                f"{activity.process!r}: the main thread is the launcher's (move the activity out of "
                "the <process>, or drop main=)",
                activity.schedule.location,
            ))


def _resolve_files(draft: Draft, errors: list[ConfigError]) -> None:
    """Turn each ``type="file"`` attribute into the absolute path of an existing file."""
    for pending in draft.file_attributes:
        spec = pending.spec
        found, tried = find_resource(spec.value, pending.directory, draft.paths)
        if found is None:
            errors.append(ConfigError(
                f'<attribute name="{spec.name}" type="file"> {not_found_message(spec.value, tried)}',
                spec.location,
            ))
        else:
            spec.value = found
