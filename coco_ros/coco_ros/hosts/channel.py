"""The two ends of a connection between hosts, over DDS, and how a process attaches its ends.

Each host plans the connections between hosts from the application file alone
(:class:`~coco_core.hosts.channel.HostChannel`: topic, policy, codec), so the writer's end and the
reader's end meet on their topic without asking each other. As between processes
(:mod:`coco_core.processes.channels`), every end is a :class:`~coco_core.connections.Connection` on
a port and nothing else about the ports changes: read status, round-robin over several
connections, message stamps, event ports, filters.

- :class:`DdsWriter`, on the output port: each write is encoded (:mod:`.sample`) and published at
  once, in the writing thread; a publish never blocks (keep-last QoS, :mod:`.qos`). It numbers its
  writes, so that the reader tells a sample lost on the way from one never written.
- :class:`DdsReader`, on the input port: the subscription (served by the bridge's ``coco:dds``
  thread) decodes each sample and stores it in a local connection made with the connection's own
  policy (:func:`~coco_core.connections.make_connection`), so DATA overwrites, a full BUFFER
  refuses, a CIRCULAR pushes out its oldest, and NEW/OLD/NO_DATA read exactly as in one process.
  Decoding there, not in the reader's ``pop``, keeps a damaged sample out of the reader's way and
  lets the decoding (JPEG and Zstandard release the GIL) overlap the reader's own work.
- :class:`DdsFrameReader`, on an input fed by a pooled output: each frame is copied into a slot of a
  local pool of the port's slot count, which the reader takes as from a pooled output of its own
  process (the newest frame, once, a :class:`~coco_core.pool.Slot` to release).

Counters keep the contract of :class:`~coco_core.connections.Connection` on each side:

- the reader's end: ``written`` is the highest write number that arrived (the ``writer_done`` sample
  brings the last), so a sample lost on the network, one the writer's DDS history dropped, one
  written before the reader joined, or a damaged one is ``dropped``, together with what the
  connection's policy discarded; ``read`` and ``pending`` are the local connection's;
- the writer's end (profiled on the writer's host too, which cannot see the reader's):
  ``written`` what its port offered, ``read`` what it published, so its ``dropped`` is what could
  not be published (a value that cannot be encoded, a write after the bridge closed).

Damaged input (a sample that does not decode) is counted (``damaged``), reported to the application
as other damaged input is (:meth:`~coco_core.application.Application.report_damage`: the first
:data:`~coco_core.component.DAMAGE_LISTED` of each connection, as a component reports its refused
samples, so that a flood does not flood the summary), and skipped.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Callable

import numpy as np
from rclpy.exceptions import InvalidHandle

from coco_core.component import DAMAGE_LISTED
from coco_core.connections import Connection, CountedConnection, make_connection
from coco_core.errors import ChannelError, CocoError, ConfigError, PacketError
from coco_core.hosts.auth import Sealer, Verifier
from coco_core.hosts.channel import HostChannel
from coco_core.hosts.key import AppKey
from coco_core.policy import BufferPolicy, SyncPolicy
from coco_core.pool import LocalFramePool, PoolReader, frame_stamp
from coco_core.ports import PooledOutputPort
from coco_core.processes.channels import fed_filter, input_end, output_end
from coco_core.processes.routed import RoutingEnd
from coco_core.stamps import Message, Stamp
from coco_core.wire import conforms
from coco_interfaces.msg import Sample

from .bridge import HostBridge
from .qos import qos_of
from .sample import (STAMP_CODEC, Clock, Frame, SampleDecoder, SampleEncoder, check_numbers, same_clock,
                     sample_parts)
from .seal import seal_of

if TYPE_CHECKING:
    from coco_core.application import Application

log = logging.getLogger("coco.hosts")


class DdsWriter(CountedConnection):
    """The writer's end of a connection between hosts (see the module's docstring): ``read``
    counts the samples published."""

    __slots__ = ("channel", "routed_away", "_encoder", "_publisher", "_unpublished")
    carries_stamps = True

    def __init__(self, bridge: HostBridge, channel: HostChannel, key: AppKey, to_app: Clock = same_clock) -> None:
        super().__init__(channel.policy)
        self.channel = channel
        self.routed_away = 0
        """Messages the connection's Split or Cull routed to other connections here (never
        published): every sample carries the count, for the reader's host's profile."""
        self._encoder = SampleEncoder(STAMP_CODEC if channel.stamps_only else channel.codec,
                                      Sealer(key, channel.topic, channel.src_host), to_app)
        self._publisher = bridge.publisher(Sample, channel.topic, qos_of(channel.policy))
        self._unpublished = False

    def push(self, value: Any) -> None:
        self.written += 1
        try:
            sample = self._encoder.encode(value, self.written, self.routed_away)
        except Exception as error:  # counted: the number is skipped, which the reader's side counts too
            payload = value.value if type(value) is Message else value
            raise ChannelError(f"connection {self.label}: a {type(payload).__name__} value cannot be sent to host "
                               f"{self.channel.dest_host}: {type(error).__name__}: {error}") from None
        if self._publish(sample):
            self.read += 1

    def writer_done(self) -> None:
        """Tell the reader's host that nothing more comes, and how many writes there were."""
        self._publish(self._encoder.done(self.written, self.routed_away))

    def route_away(self) -> None:
        """Count a message the writer's end routed to another connection (it is not published)."""
        self.routed_away += 1

    def _publish(self, sample: Sample) -> bool:
        try:
            self._publisher.publish(sample)
        except InvalidHandle as error:  # the bridge closed under a late writer
            if not self._unpublished:
                log.warning("connection %s: not published (%s): later writes are counted as dropped", self.label,
                            error)
                self._unpublished = True
            return False
        return True

    @property
    def matched(self) -> bool:
        """Whether a reader's end on another host subscribes (discovered it)."""
        try:
            return self._publisher.get_subscription_count() > 0
        except InvalidHandle:  # the bridge closed
            return False

    def pop(self) -> Any:
        raise CocoError(f"connection {self.label}: the writer's end cannot be read")

    @property
    def pending(self) -> int:
        return 0

    @property
    def label(self) -> str:
        return f"{self.channel.src} -> {self.channel.dest}"

    def describe(self) -> str:
        return f"{super().describe()}, DDS to host {self.channel.dest_host}{_codec(self.channel)}"


def _codec(channel: HostChannel) -> str:
    return "" if channel.codec == "plain" or channel.stamps_only else f", {channel.codec} codec"


class Arrivals:
    """The subscription of a reader's end: checks each sample's seal (``verifier``: a sample that
    fails is refused and counted there, never decoded), decodes it, checks its value against the
    input port's declared type (``accepts``) and hands it to ``store``; counts the highest write
    number (the reader's ``written``), the writer's end and damaged samples."""

    __slots__ = ("channel", "number", "routed_away", "finished", "damaged", "_decoder", "_store", "_report",
                 "_verifier", "_accepts", "subscription")

    def __init__(self, bridge: HostBridge, channel: HostChannel, verifier: Verifier, from_app: Clock,
                 store: Callable[[Any], None], report: Callable[[str], None] | None, accepts: Any = object) -> None:
        self.channel = channel
        self.number = 0
        """The highest write number that arrived (every write up to it was made)."""
        self.routed_away = 0
        """The highest count of messages the writer's Split or Cull routed away that arrived."""
        self.finished = False
        """Whether the writer's ``writer_done`` arrived."""
        self.damaged = 0
        """Samples that did not decode (counted as dropped; the first :data:`DAMAGE_LISTED` reported)."""
        self._decoder = SampleDecoder(from_app)
        self._store = store
        self._report = report
        self._verifier = verifier
        self._accepts = accepts
        """The reader's declared type (:attr:`coco_core.ports.Port.type`): a value of another type
        is refused here, not in the component."""
        self.subscription = bridge.subscribe(Sample, channel.topic, self._arrive, qos_of(channel.policy))

    @property
    def matched(self) -> bool:
        """Whether the writer's end on the other host publishes to this end."""
        try:
            return self.subscription.get_publisher_count() > 0
        except InvalidHandle:  # the bridge closed
            return False

    def _arrive(self, sample: Sample) -> None:
        if not self._verifier.accept(seal_of(sample), sample_parts(sample)):
            return
        try:
            if sample.writer_done:
                check_numbers(sample)
                self.routed_away = max(self.routed_away, sample.routed_away)
                self.number = max(self.number, sample.number)
                self.finished = True
                return
            item = self._decoder.decode(sample)
            self.routed_away = max(self.routed_away, sample.routed_away)
            value = item.value if type(item) is Message else item
            if not conforms(value, self._accepts) and not isinstance(value, (Frame, Stamp)):
                raise PacketError("garbage", f"sample {sample.number} holds a {type(value).__name__}, which "
                                             f"{self.channel.dest} does not take")
            number = sample.number
            if number > self.number:  # first: a reader must never see read > written
                self.number = number
            self._store(item)
        except PacketError as error:
            self.damaged += 1
            damaged = self.damaged
            what = f"connection {self.channel.label} from host {self.channel.src_host}: {error}"
            if damaged == 1:
                log.warning("%s", what)
            if self._report is not None and damaged <= DAMAGE_LISTED:  # as a component's refused samples
                more = "; further damaged samples are only counted (dropped)" if damaged == DAMAGE_LISTED else ""
                self._report(what + more)


class FromHost:
    """What the two reader's ends share: ``written``, the writer's end and the damaged samples come
    from their :class:`Arrivals`; the reader's end is never written to."""

    __slots__ = ()

    channel: HostChannel
    arrivals: Arrivals

    @property
    def written(self) -> int:
        return self.arrivals.number

    @property
    def matched(self) -> bool:
        """Whether the writer's end on the other host publishes to this end (discovered it)."""
        return self.arrivals.matched

    @property
    def damaged(self) -> int:
        return self.arrivals.damaged

    @property
    def writer_finished(self) -> bool:
        return self.arrivals.finished

    @property
    def label(self) -> str:
        return f"{self.channel.src} -> {self.channel.dest}"

    @property
    def stamps_only(self) -> bool:
        return self.channel.stamps_only

    @property
    def routed_away(self) -> int:
        """Messages the writer's Split or Cull routed to other connections, as the samples tell."""
        return self.arrivals.routed_away

    def push(self, value: Any) -> None:
        raise CocoError(f"connection {self.label}: the reader's end cannot be written")


class DdsReader(FromHost, Connection):
    """The reader's end of a connection between hosts of values (see the module's docstring).

    ``front`` is the connection the input port holds: this end, or the filter fed from it
    (:class:`~coco_core.processes.filtered.FedFilter`), whose trigger a stored sample calls."""

    __slots__ = ("channel", "store", "front", "arrivals")

    def __init__(self, bridge: HostBridge, channel: HostChannel, verifier: Verifier, from_app: Clock = same_clock,
                 report: Callable[[str], None] | None = None, accepts: Any = object) -> None:
        super().__init__(channel.policy)
        self.channel = channel
        self.store = make_connection(channel.policy)
        """What arrived and was not read yet, kept with the connection's own policy."""
        self.store.trigger = self._wake
        self.front: Connection = self
        self.arrivals = Arrivals(bridge, channel, verifier, from_app, self.store.push, report, accepts)

    def _wake(self) -> None:
        trigger = self.front.trigger
        if trigger is not None:
            trigger()

    def pop(self) -> Any:
        return self.store.pop()

    def pop_newest(self) -> Any:
        return self.store.pop_newest()

    def skip(self, count: int = 1) -> None:
        self.store.skip(count)

    def ready_at(self) -> float | None:
        return self.store.ready_at()

    @property
    def read(self) -> int:
        return self.store.read

    @property
    def pending(self) -> int:
        return self.store.pending

    def describe(self) -> str:
        return f"{super().describe()}, DDS from host {self.channel.src_host}{_codec(self.channel)}"


class DdsFrameReader(FromHost, PoolReader):
    """The reader's end of a connection between hosts from a pooled output: each frame that arrives
    is copied into a slot of a local pool (``channel.policy.size`` slots, the output's), and read as
    from a pooled output in this process. A frame that finds every slot held by the reader is
    dropped (counted), as a local pool refuses its writer."""

    __slots__ = ("read", "channel", "arrivals")

    read: int  # a field here, where PoolReader only asks for a value

    def __init__(self, bridge: HostBridge, channel: HostChannel, verifier: Verifier, from_app: Clock = same_clock,
                 report: Callable[[str], None] | None = None) -> None:
        super().__init__(LocalFramePool(max(2, channel.policy.size)), channel.policy)
        self.read = 0
        self.channel = channel
        self.arrivals = Arrivals(bridge, channel, verifier, from_app, self._store, report)

    def _store(self, item: Any) -> None:
        frame = item.value if type(item) is Message else item
        if not isinstance(frame, Frame):
            raise PacketError("garbage", f"a pooled output's sample holds a {type(frame).__name__}, not a frame")
        pool = self.pool
        slot = pool.acquire(frame.array.shape, frame.array.dtype)
        if slot is None:
            return  # every slot held by the reader: dropped (written - read - pending)
        np.copyto(slot.array, frame.array)
        slot.stamp = frame.stamp
        slot.message = (Message(frame_stamp(frame.stamp), item.time, item.seq, item.source, item.it, item.user)
                        if type(item) is Message else None)
        pool.publish(slot)
        if self.trigger is not None:
            self.trigger()

    def describe(self) -> str:
        return f"{self.policy}, DDS from host {self.channel.src_host}"


@dataclass
class HostEnds:
    """The ends of connections between hosts that one process attached."""

    writers: list[DdsWriter] = field(default_factory=list)
    readers: list[DdsReader | DdsFrameReader] = field(default_factory=list)

    @property
    def matched(self) -> bool:
        """Whether every end found its other end: what the hosts' start barrier waits for. Both
        sides matter: a sample written before the reader's side discovered its writer is resent by
        DDS's reliability only at its next heartbeat (measured here: the first samples came 130 ms
        late), and one written before the writer's side discovered the reader is lost (counted)."""
        return not self.unmatched()

    def unmatched(self) -> list[str]:
        """The ends that have not found their other end yet, each with the host it is on."""
        return ([f"{writer.channel.label} (its reader on host {writer.channel.dest_host})"
                 for writer in self.writers if not writer.matched]
                + [f"{reader.channel.label} (its writer on host {reader.channel.src_host})"
                   for reader in self.readers if not reader.matched])


def attach_between_hosts(app: Application, bridge: HostBridge, channels: list[HostChannel], host: str, key: AppKey,
                         hosts: Sequence[str], to_app: Clock = same_clock, from_app: Clock = same_clock) -> HostEnds:
    """Attach the ends of ``channels`` that run in this process (``host``, ``app.process``) to
    ``app``'s ports, as :func:`coco_core.processes.channels.attach` attaches the ends of channels
    between processes: a :class:`DdsWriter` on each output (in ``app.outgoing``, and in
    ``app.connections`` so that the writer's host profiles it), a :class:`DdsReader` (or
    :class:`DdsFrameReader` for a pooled output's frames, ``policy`` POOL) on each input, behind the
    connection's filter when it has one (made by the builder, ``app.incoming_filters``: the filter
    stays on the reader's side, fed from the network; a Split or Cull decides on the writer's side
    too, ``app.outgoing_routers``, so that a message routed away is never published; both hosts
    profile the routed-away count, which the samples carry, :class:`~coco_core.processes.routed.RoutingEnd`). An activity's ``endit``/``beginit`` is an end
    like a component's port. ``to_app``/``from_app`` convert stamp times to and from the
    application's clock (:mod:`.sample`). Every sample is sealed with ``key`` on the writer's side
    and checked on the reader's (:mod:`coco_core.hosts.auth`: only the connection's writer's host,
    one of ``hosts``, may write on its topic; a refusal is counted in ``app.network_refusals``)."""
    ends = HostEnds()
    process = app.process
    for channel in channels:
        frames = channel.policy.data is BufferPolicy.POOL
        if channel.policy.sync is SyncPolicy.UNSYNC and host in (channel.src_host, channel.dest_host):
            raise ConfigError(f"connection {channel.label} joins hosts {channel.src_host} and {channel.dest_host}: "
                              "UNSYNC is only valid inside one activity (use LOCKED or LOCK_FREE)")
        if frames and channel.stamps_only and host in (channel.src_host, channel.dest_host):
            raise ConfigError(f"connection {channel.label} between hosts: a stamps-only connection carries the "
                              "messages' stamps, not frames: connect it with data=DATA, BUFFER or CIRCULAR, not POOL")
        if channel.src_host == host and channel.src_process == process:
            out = output_end(app, channel.src, channel.src_activity)
            if isinstance(out, PooledOutputPort) != frames and not channel.stamps_only:
                raise ConfigError(f"connection {channel.label} between hosts: {channel.src} is "
                                  f"{'a pooled' if isinstance(out, PooledOutputPort) else 'not a pooled'} output, its "
                                  f"policy {channel.policy}: a pooled output's frames cross with data=POOL only")
            if frames and channel.codec != "plain":
                raise ConfigError(f"connection {channel.label} between hosts: a pooled output's frames are arrays "
                                  f"without an image format; the {channel.codec} codec takes RGBDFrame and Image "
                                  "values (write them on a plain output)")
            writer = DdsWriter(bridge, channel, key, to_app)
            router = app.outgoing_routers.get(channel.label)
            end: Connection = writer if router is None else RoutingEnd(router, writer, writer.route_away)  # decided here
            out.add_connection(end, channel.stamps_only)
            app.outgoing.append(writer)
            app.connections.append(end)
            ends.writers.append(writer)
        if channel.dest_host == host and channel.dest_process == process:
            into = input_end(app, channel.dest, channel.dest_activity, channel.stamps_only)
            reader: DdsReader | DdsFrameReader
            verifier = Verifier(key, channel.topic, [channel.src_host], hosts, app.network_refusals)
            if frames:
                reader = DdsFrameReader(bridge, channel, verifier, from_app, app.report_damage)
                front: Connection = reader
            else:  # a filter may make values of other types of what comes: then its input is not checked
                reader = DdsReader(bridge, channel, verifier, from_app, app.report_damage,
                                   object if channel.filtered else into.type)
                front = reader
                if channel.filtered:  # the filter on this side, fed from the network
                    front = reader.front = fed_filter(app, channel.label, reader, reader)
            into.add_connection(front, channel.event)
            app.connections.append(front)
            ends.readers.append(reader)
            if front.pending and front.trigger is not None:
                front.trigger()  # it holds messages from the start (a PreSignal's tokens): as if written now
    return ends

