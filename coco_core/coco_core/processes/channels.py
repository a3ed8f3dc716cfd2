"""Connections between processes: the shared-memory channels of the process level.

The launcher plans one channel per connection that crosses processes (:func:`plan_channels`),
before any child starts: the segment, the policy, whether it carries pooled frames, and whether a
write wakes the reader's activity (whose eventfd the launcher made and every process inherits).
Then each process attaches its own ends (:func:`attach`): the writer's process an
:class:`~coco_core.shm.ShmWriter` on the output port (and, for a pooled output, a pool in shared
memory), the reader's process an :class:`~coco_core.shm.ShmReader` on the input port. Everything
else about the ports stays as it is: read status, round-robin over several connections, counters in
the profile (reported once, by the reader's process).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from .. import registry
from ..errors import ConfigError
from ..model import AppSpec, ComponentSpec
from ..policy import BufferPolicy, ConnectionPolicy
from ..connections import Connection
from ..ports import InputPort, OutputPort, PooledOutputPort
from .placement import Placement

if TYPE_CHECKING:
    from ..application import Application
    from ..shm import Arena


@dataclass
class ChannelPlan:
    """One connection between two processes, as every process needs to know it."""

    src: str
    """``component.port`` of the writer."""
    dest: str
    src_process: str
    dest_process: str
    channel: Any
    """The shared-memory channel's description (:class:`coco_core.shm.ChannelSpec`)."""
    frames: bool
    """Pooled frames (a :class:`PooledOutputPort`'s slots in shared memory) rather than values."""
    event: bool | None
    """The connection's own ``event`` setting; None: the input port decides."""
    wakes: str
    """The reader's activity woken by a write (through its eventfd); empty: none."""


def _declared(spec: ComponentSpec | None, port: str) -> Any:
    """The class-level declaration of ``port`` on the component of ``spec``, if it has one: the
    launcher plans channels without building the children's components."""
    if spec is None:
        return None
    try:
        cls = registry.load(spec.task, spec.library)
    except Exception:  # reported where the component is built
        return None
    return cls._port_decls.get(port)


def plan_channels(arena: Arena, spec: AppSpec, placement: Placement) -> list[ChannelPlan]:
    """One channel for every connection of ``spec`` that crosses processes."""
    components = {component.name: component for component in spec.all_components()}
    activity_of = {name: activity for activity in spec.activities for name in activity.components}
    plans = []
    for connection in placement.crossing(spec):
        out = _declared(components.get(connection.src.component), connection.src.port)
        into = _declared(components.get(connection.dest.component), connection.dest.port)
        frames = isinstance(out, PooledOutputPort) or connection.data is BufferPolicy.POOL
        if frames and connection.data not in (BufferPolicy.DATA, BufferPolicy.POOL):
            raise ConfigError(f"{connection.src} is a pooled output: connect it with data=POOL (latest frame, "
                              f"no copy), not {connection.data.value}", connection.location)
        event = connection.event if connection.event is not None else bool(isinstance(into, InputPort) and into.event)
        activity = activity_of.get(placement.top_of.get(connection.dest.component, connection.dest.component))
        wakes = activity.name if event and activity is not None and activity.schedule.type == "triggered" else ""
        policy = ConnectionPolicy(BufferPolicy.POOL if frames else connection.data, connection.policy,
                                  max(1, connection.buffersize))
        channel = arena.channel(policy, f"{connection.src}->{connection.dest}", frames=frames)
        plans.append(ChannelPlan(str(connection.src), str(connection.dest),
                                 placement.process_of(connection.src.component),
                                 placement.process_of(connection.dest.component), channel, frames,
                                 connection.event, wakes))
    return plans


def attach(app: Application, plans: list[ChannelPlan], wakes: dict[str, int]) -> None:
    """Attach this process's ends of the ``plans`` to ``app``'s ports; ``wakes`` maps each reader
    activity to its eventfd (inherited from the launcher)."""
    if not plans:
        return
    from ..pool import PoolConnection
    from ..shm import ShmFrameNotifier, ShmFramePool, ShmPoolReader, ShmReader, ShmWriter

    process = app.process
    for plan in plans:
        if plan.src_process == process:
            component, _, port_name = plan.src.rpartition(".")
            out = app.component(component).port(port_name)
            if not isinstance(out, OutputPort):
                raise ConfigError(f"{plan.src} is an input port; a connection starts at an output")
            writer: Connection
            if plan.frames:
                if not isinstance(out, PooledOutputPort):
                    raise ConfigError(f"{plan.src} is not a pooled output: a POOL connection needs one")
                if not isinstance(out.pool, ShmFramePool):  # one shared pool for every reader process
                    out.pool = ShmFramePool(plan.channel)  # type: ignore[assignment]  # FramePool's interface, in shared memory
                    for local in out.connections:  # readers in this process read the shared pool too
                        if isinstance(local, PoolConnection):
                            local.pool = out.pool
                writer = ShmFrameNotifier(plan.channel)
            else:
                writer = ShmWriter(plan.channel)
            out.add_connection(writer)
            app.outgoing.append(writer)
            if plan.wakes:
                fd = wakes[plan.wakes]
                writer.trigger = lambda fd=fd: os.eventfd_write(fd, 1)
        if plan.dest_process == process:
            component, _, port_name = plan.dest.rpartition(".")
            into = app.component(component).port(port_name)
            if not isinstance(into, InputPort):
                raise ConfigError(f"{plan.dest} is an output port; a connection ends at an input")
            reader: Connection = ShmPoolReader(plan.channel) if plan.frames else ShmReader(plan.channel)
            into.add_connection(reader, plan.event)
            app.connections.append(reader)


def wake_targets(plans: list[ChannelPlan]) -> set[str]:
    """The activities that a write in another process wakes."""
    return {plan.wakes for plan in plans if plan.wakes}
