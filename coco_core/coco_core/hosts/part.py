"""One host's part of an application: what ``coco-launch app.xml --host NAME`` builds and runs.

Every host reads the same file and cuts its own part out of it (:func:`host_part`): the activities
and processes of its ``<host>``, the components they run, the connections between them, and (on the
first host) every component no activity runs, as the launcher's process holds those on one machine.
The part is an ordinary one-host application (:class:`~coco_core.model.AppSpec`): processes,
shared-memory channels and the deployment plan work on it unchanged. What joins it to the other
hosts travels with it: its connections to other hosts (:attr:`AppSpec.between_hosts`, over DDS),
the file's whole list of connections (a Split numbers its outputs among all of them) and where
every component of another host runs (:attr:`AppSpec.other_hosts`, for its operations, called by
name as across processes).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from ..boundary import declared_port, ring_policy
from ..errors import ConfigError, ConfigErrors, did_you_mean
from ..model import AppSpec, ConnectionSpec, PortRef
from ..policy import BufferPolicy, ConnectionPolicy, SyncPolicy
from ..pool import DEFAULT_SLOTS
from ..ports import PooledOutputPort
from .channel import HostChannel, topic_of

SEPARATOR = "@"
"""Between a process and its host in an address (``view@graphics``; ``@graphics``: that host's
launcher), where a process name alone names a process of this host."""


def address(host: str, process: str) -> str:
    """How this host names ``process`` of another ``host`` (``app.elsewhere``, operation calls)."""
    return f"{process}{SEPARATOR}{host}"


def split_address(name: str) -> tuple[str | None, str]:
    """(host, process) of an address; (None, name) for a process of this host."""
    process, separator, host = name.rpartition(SEPARATOR)
    return (host, process) if separator else (None, name)


@dataclass
class Where:
    """The host and process of every activity and component of an application with hosts."""

    hosts: tuple[str, ...]
    of_activity: dict[str, tuple[str, str]]
    of_component: dict[str, tuple[str, str]]
    """Every component, peers included."""

    def of_ref(self, ref: PortRef) -> tuple[str, str]:
        """(host, process) of the component, or activity (``beginit``/``endit``), ``ref`` names."""
        table = self.of_activity if ref.activity else self.of_component
        return table.get(ref.component, (self.hosts[0], ""))


def host_part(spec: AppSpec, host: str, where: Where) -> AppSpec:
    """``host``'s part of ``spec``, which declares hosts (:attr:`AppSpec.part_of`), whose ``where``
    the deployment plan computed once (:func:`coco_core.deployment.plan_deployment`); a
    :class:`ConfigErrors` for an unknown host or a connection that cannot join two hosts (UNSYNC:
    it is only valid inside one activity)."""
    if host not in where.hosts:
        raise ConfigErrors([ConfigError(f"--host {host}: the application declares no such host; "
                                        f"{did_you_mean(host, where.hosts)}")])
    errors: list[ConfigError] = []
    channels: list[HostChannel] = []
    inside: list[ConnectionSpec] = []
    for connection in spec.connections:
        (src_host, src_process), (dest_host, dest_process) = where.of_ref(connection.src), where.of_ref(connection.dest)
        if src_host == dest_host:
            if src_host == host:
                inside.append(connection)
            continue
        if connection.policy is SyncPolicy.UNSYNC:
            errors.append(ConfigError(f"UNSYNC connection {connection.src} -> {connection.dest} joins host "
                                      f"{src_host!r} and host {dest_host!r}; UNSYNC is only valid inside one "
                                      "activity (use LOCKED or LOCK_FREE)", connection.location))
        if host in (src_host, dest_host):
            channels.append(_channel(spec, connection, src_host, src_process, dest_host, dest_process))
    if errors:
        raise ConfigErrors(errors)
    mine = [top for top in spec.components if where.of_component[top.name][0] == host]
    return dataclasses.replace(
        spec, components=mine, connections=inside,
        activities=[activity for activity in spec.activities if activity.host == host],
        processes=[process for process in spec.processes if process.host == host], part_of=host,
        between_hosts=channels, file_connections=list(spec.connections),
        other_hosts={name: address(*place) for name, place in where.of_component.items() if place[0] != host})


def _channel(spec: AppSpec, connection: ConnectionSpec, src_host: str, src_process: str, dest_host: str,
             dest_process: str) -> HostChannel:
    return HostChannel(
        src=str(connection.src), dest=str(connection.dest), src_host=src_host, dest_host=dest_host,
        src_process=src_process, dest_process=dest_process, policy=_policy(spec, connection),
        event=connection.wakes(), codec=connection.codec,
        topic=topic_of(spec.name, str(connection.src), str(connection.dest)),
        stamps_only=connection.stamps_only, filtered=connection.filter is not None,
        src_activity=connection.src.activity, dest_activity=connection.dest.activity)


def _policy(spec: AppSpec, connection: ConnectionSpec) -> ConnectionPolicy:
    """What the reader's side stores a connection between hosts with, as a ring between processes
    would (:func:`~coco_core.boundary.ring_policy`: a filter's feed), and for a pooled
    output's frames a pool of the slots the output declares."""
    if connection.data is BufferPolicy.POOL:
        components = {component.name: component for component in spec.all_components()}
        out = declared_port(components.get(connection.src.component), connection.src.port)
        return ConnectionPolicy(BufferPolicy.POOL, SyncPolicy.LOCKED,
                                out.slots if isinstance(out, PooledOutputPort) else DEFAULT_SLOTS)
    return ring_policy(connection)
