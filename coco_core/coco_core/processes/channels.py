"""Connections between processes: the shared-memory channels of the process level.

The launcher plans one channel per connection that crosses processes (:func:`plan_channels`),
before any child starts: the segment, the policy, whether it carries pooled frames (one pool in
shared memory per pooled output, with its declared slots, for all its readers), and whether a write
wakes the reader's activity (whose eventfd the launcher made and every process inherits; for an
input made in ``init()``, which the launcher cannot see, the reader's process says so at attach).
Then each process attaches its own ends (:func:`attach`), after building its part and before
starting it: the writer's process an :class:`~coco_core.shm.ShmWriter` on the output port (and, for
a pooled output, the pool in shared memory, given to the port through
:meth:`~coco_core.ports.PooledOutputPort.use_pool`, the port's one way to change its pool), the
reader's process an :class:`~coco_core.shm.ShmReader` on the input port, behind the connection's
filter when it has one (:class:`~coco_core.processes.filtered.FedFilter`: the filter stays on the
reader's side; a Split or Cull also decides on the writer's side, before the ring,
:class:`~coco_core.processes.routed.RoutingEnd`, so that what it routes away never crosses). An activity's ``endit``/``beginit`` is an end like a component's port. Everything
else about the ports stays as it is: read status, round-robin over several connections, message
stamps, counters in the profile (reported by the reader's process; by the launcher, from shared
memory, when that process died).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Callable

from ..boundary import declared_port, ring_policy
from ..errors import ConfigError
from ..model import ActivitySpec, AppSpec, ComponentSpec, ConnectionSpec
from ..policy import BufferPolicy, ConnectionPolicy, SyncPolicy
from ..connections import Connection
from ..filters import Merge, Router
from ..iteration import port_of
from ..ports import InputPort, OutputPort, PooledOutputPort, Port, type_name
from ..pool import DEFAULT_SLOTS
from ..stamps import Stamp
from ..wakeup import Wakeup
from .filtered import FedFilter, FedRouter, RoutedCount
from .placement import Placement
from .routed import RoutingEnd

if TYPE_CHECKING:
    from ..application import Application
    from ..deployment import HostDeployment
    from ..shm import Arena


@dataclass
class ChannelPlan:
    """One connection between two processes, as every process needs to know it."""

    src: str
    """``component.port`` of the writer (``activity.endit`` when :attr:`src_activity`)."""
    dest: str
    src_process: str
    dest_process: str
    channel: Any
    """The shared-memory channel's description (:class:`coco_core.shm.ChannelSpec`); every
    connection of one pooled output has the same pool (its own label and reader number)."""
    frames: bool
    """Pooled frames (a :class:`PooledOutputPort`'s slots in shared memory) rather than values."""
    event: bool | None
    """The connection's own ``event`` setting; None: the input port decides."""
    wakes: str
    """The reader's activity that a write may wake (through its eventfd); empty: none."""
    asks: int = -1
    """Where the reader's process says whether a write wakes it (a word of the launch's flags
    segment), when only the built component knows: an input port made in ``init()`` is not on the
    class the launcher reads; -1: the plan knows (a write wakes ``wakes`` if set)."""
    src_activity: bool = False
    """``src`` is an activity's ``endit`` (``activity.endit``), not a component's port."""
    dest_activity: bool = False
    """``dest`` is an activity's ``beginit``."""
    filtered: bool = False
    """The connection has a filter: the reader's process puts it on its end of the channel (the
    builder made it, :attr:`Application.incoming_filters <coco_core.application.Application.incoming_filters>`)."""
    stamps_only: bool = False
    """The connection carries the messages' stamps only: the writer's process puts each message's
    :class:`~coco_core.stamps.Stamp` into the ring, never its payload."""


@dataclass(frozen=True)
class Crossing:
    """One connection between two processes of a host, as the deployment plan settles it once:
    its ends' processes and the activity a write on it wakes."""

    connection: ConnectionSpec
    src_process: str
    dest_process: str
    wakes: str
    """The reader's triggered activity that a write may wake (through its eventfd); empty: none."""
    event: bool | None
    """Whether the reader's input is an event port: None when the reader's process must say (an
    input made in ``init()``, which the launcher cannot see)."""


def _woken_by(connection: ConnectionSpec, components: dict[str, ComponentSpec],
              activity_of: dict[str, ActivitySpec], placement: Placement,
              activities: dict[str, ActivitySpec]) -> tuple[str, bool | None]:
    """(the activity a write on the crossing ``connection`` wakes, "" for none; whether its input is an
    event port: True, False, or None when the reader's process must say, the port being made in init).
    An activity's ``beginit`` is an event port of the activity itself."""
    wakes = connection.wakes()
    event: bool | None
    if connection.dest.activity:
        event = wakes if wakes is not None else True
        activity = activities.get(connection.dest.component)
    else:
        into = declared_port(components.get(connection.dest.component), connection.dest.port)
        event = wakes if wakes is not None else (into.event if isinstance(into, InputPort) else None)
        activity = activity_of.get(placement.top_of.get(connection.dest.component, connection.dest.component))
    triggered = activity is not None and activity.schedule.type == "triggered"
    return (activity.name if triggered and event is not False and activity is not None else ""), event


def crossings(spec: AppSpec, placement: Placement) -> list[Crossing]:
    """The connections of ``spec`` between two processes, each with the activity a write on it may
    wake: computed once, by the deployment plan (:func:`coco_core.deployment.plan_host`), whose
    ``woken`` sets get eventfd threads and whose channels :func:`plan_channels` makes."""
    components = {component.name: component for component in spec.all_components()}
    activity_of = {name: activity for activity in spec.activities for name in activity.components}
    activities = {activity.name: activity for activity in spec.activities}
    return [Crossing(connection, placement.process_of_ref(connection.src), placement.process_of_ref(connection.dest),
                     *_woken_by(connection, components, activity_of, placement, activities))
            for connection in placement.crossing(spec)]


def plan_channels(arena: Arena, deployment: HostDeployment) -> list[ChannelPlan]:
    """One channel for every connection of the plan's ``crossings``; one frame pool for
    every pooled output read from another process, with the slots the port declares, shared by all
    its readers (as in one process, where they all read the port's one pool); a ring for a
    stamps-only connection from a pooled output (it carries the frames' stamps, never a slot)."""
    components = {component.name: component for component in deployment.spec.all_components()}
    crossing = deployment.crossings
    outputs = {str(c.connection.src): declared_port(components.get(c.connection.src.component), c.connection.src.port)
               for c in crossing}
    # The connections that read frames from a pool: a stamps-only one reads the frames' stamps from a
    # ring of its own and holds no slot.
    pooled = [c for c in crossing if not c.connection.stamps_only
              and (isinstance(outputs[str(c.connection.src)], PooledOutputPort)
                   or c.connection.data is BufferPolicy.POOL)]
    readers = Counter(str(c.connection.src) for c in pooled)
    pools: dict[str, Any] = {}
    taken: Counter[str] = Counter()
    plans = []
    asks = 0
    for crossed in crossing:
        connection = crossed.connection
        label = f"{connection.src}->{connection.dest}"
        frames = crossed in pooled
        ask = -1
        if crossed.wakes and crossed.event is None:  # an input made in init(): the reader's process says
            ask, asks = asks, asks + 1
        if frames:
            if connection.filter is not None:
                raise ConfigError(f"{connection.src} is a pooled output: its frames go to every reader as they are "
                                  f"and cannot pass through a {connection.filter.type} filter", connection.location)
            if connection.data not in (BufferPolicy.DATA, BufferPolicy.POOL):
                raise ConfigError(f"{connection.src} is a pooled output: connect it with data=POOL (latest frame, "
                                  f"no copy), not {connection.data.value}", connection.location)
            source = str(connection.src)
            out = outputs[source]
            number = taken[source]
            taken[source] += 1
            if not number:
                slots = out.slots if isinstance(out, PooledOutputPort) else DEFAULT_SLOTS
                pools[source] = arena.channel(ConnectionPolicy(BufferPolicy.POOL, SyncPolicy.LOCKED, slots), label,
                                              frames=True, readers=readers[source])
            channel = replace(pools[source], label=label, reader=number)
        elif connection.stamps_only and connection.data is BufferPolicy.POOL:
            raise ConfigError(f"a stamps-only connection from {connection.src} carries the messages' stamps, not "
                              "frames: connect it with data=DATA, BUFFER or CIRCULAR, not POOL", connection.location)
        else:
            channel = replace(arena.channel(ring_policy(connection), label), stamps_only=connection.stamps_only)
        plans.append(ChannelPlan(str(connection.src), str(connection.dest), crossed.src_process,
                                 crossed.dest_process, channel, frames,
                                 connection.wakes(), crossed.wakes, ask, connection.src.activity,
                                 connection.dest.activity, connection.filter is not None, connection.stamps_only))
    if asks:
        arena.flags(asks)
    return plans


def attach(app: Application, plans: list[ChannelPlan], wakes: Mapping[str, Wakeup]) -> None:
    """Attach this process's ends of the ``plans`` to ``app``'s ports; ``wakes`` maps each reader
    activity to its eventfd (inherited from the launcher)."""
    if not plans:
        return
    from ..shm import ShmFrameNotifier, ShmFramePool, ShmPoolReader, ShmReader, ShmWriter

    process = app.process
    flags = _flags(app, plans)
    for plan in plans:
        if plan.src_process == process:
            out = output_end(app, plan.src, plan.src_activity)
            writer: Connection
            if plan.frames:
                if not isinstance(out, PooledOutputPort):
                    raise ConfigError(f"{plan.src} is not a pooled output: a POOL connection needs one")
                if not isinstance(out.pool, ShmFramePool):  # one shared pool for every reader process
                    out.use_pool(ShmFramePool(plan.channel))
                writer = ShmFrameNotifier(plan.channel)
            else:
                writer = ShmWriter(plan.channel)
            router = app.outgoing_routers.get(f"{plan.src}->{plan.dest}")
            if router is not None and isinstance(writer, ShmWriter):  # a Split or Cull decides here
                out.add_connection(RoutingEnd(router, writer, writer.route_away), plan.stamps_only)
            else:
                out.add_connection(writer, plan.stamps_only)
            app.outgoing.append(writer)
            if plan.wakes:
                writer.trigger = _waker(wakes[plan.wakes], flags, plan.asks)
        if plan.dest_process == process:
            into = input_end(app, plan.dest, plan.dest_activity, plan.stamps_only)
            reader: Connection
            if plan.frames:
                reader = ShmPoolReader(plan.channel)
            else:
                ring = reader = ShmReader(plan.channel)
                if plan.filtered:  # the filter on this side, fed from the channel
                    reader = fed_filter(app, f"{plan.src}->{plan.dest}", ring, ring)
            into.add_connection(reader, plan.event)
            app.connections.append(reader)
            if reader.pending and reader.trigger is not None:
                reader.trigger()  # it holds messages from the start (a PreSignal's tokens): as if written now
            if plan.asks >= 0 and flags is not None:
                flags[plan.asks] = int(into.event)


def _port(app: Application, name: str, of_activity: bool) -> Port:
    """The port ``name`` (``component.port``, or ``activity.beginit``/``activity.endit``) in this
    process's application."""
    owner, _, port = name.rpartition(".")
    return port_of(app.activity(owner), port) if of_activity else app.component(owner).port(port)


def output_end(app: Application, name: str, of_activity: bool) -> OutputPort:
    """The output port ``name`` of this process where a connection to another process or host
    starts (:func:`_port`); a :class:`ConfigError` for an input."""
    out = _port(app, name, of_activity)
    if not isinstance(out, OutputPort):
        raise ConfigError(f"{name} is an input port; a connection starts at an output")
    return out


def input_end(app: Application, name: str, of_activity: bool, stamps_only: bool) -> InputPort:
    """The input port ``name`` of this process where a connection from another process or host
    ends; a :class:`ConfigError` for an output, or for a stamps-only connection into a port that
    does not take :class:`~coco_core.stamps.Stamp`."""
    from ..application import types_compatible

    into = _port(app, name, of_activity)
    if not isinstance(into, InputPort):
        raise ConfigError(f"{name} is an output port; a connection ends at an input")
    if stamps_only and not types_compatible(Stamp, into.type):
        raise ConfigError(f"a stamps-only connection gives {name} the messages' stamps "
                          f"(coco_core.stamps.Stamp), and that port takes {type_name(into.type)}; "
                          "connect it to a port of type Stamp or object")
    return into


def fed_filter(app: Application, label: str, feed: Connection, routed: RoutedCount) -> FedFilter:
    """The filter the builder made for the connection ``label`` on the reader's side
    (:attr:`Application.incoming_filters`), fed from ``feed`` (a channel from another process or
    host), in its place in a Merge's group. A Split or Cull was decided by the writer's end
    (:mod:`.routed`): ``routed`` carries what it routed away (the channel's reader end,
    :class:`~.filtered.FedRouter`)."""
    made = app.incoming_filters[label]
    if isinstance(made, Router):
        return FedRouter(made, feed, routed)
    fed = FedFilter(made, feed)
    if isinstance(made, Merge):
        made.group.feeds.append(fed.pull)
    return fed


def _flags(app: Application, plans: list[ChannelPlan]) -> memoryview | None:
    """This process's mapping of the launch's flags segment, when a plan asks a reader."""
    if all(plan.asks < 0 for plan in plans):
        return None
    from ..shm import Segment, flags_name

    return Segment(flags_name(plans[0].channel)).view.cast("q")


def _waker(wakeup: Wakeup, flags: memoryview | None, ask: int) -> Callable[[], None]:
    """What a write calls to wake the reader's activity: its eventfd, or, where the reader's
    process decides (``ask``), its eventfd if that process said so."""
    if ask < 0 or flags is None:
        return wakeup.wake

    def wake_if_asked() -> None:
        if flags[ask]:
            wakeup.wake()

    return wake_if_asked


def reader_stats(plans: list[ChannelPlan], process: str) -> list[Connection]:
    """Read-only views of the counters of the connections that ``process`` reads, from shared
    memory: what the launcher reports for a process that can no longer report them itself."""
    from ..shm import ChannelStats, FrameStats

    return [FrameStats(plan.channel) if plan.frames else ChannelStats(plan.channel)
            for plan in plans if plan.dest_process == process]
