"""The launch's messages between the hosts of one application, on one DDS topic.

Every host publishes on ``/coco/<application>/hosts`` and listens to it; a message names its
sender and its recipient (empty: every host). Its body is one of the typed messages of the launch
(:mod:`coco_core.hosts.messages`, :mod:`coco_core.messages`) in the typed encoding of
:mod:`coco_core.wire` (never a pickle: any participant of the DDS domain may publish here). Every
message is sealed with the application's key (:mod:`coco_core.hosts.auth`); one whose seal fails
(no key, another application's, a replay, a host the file does not declare) is refused and counted
in the profile before its body is read, so that no packet from outside stops or calls anything. A
body that does not decode, or is not a launch message, is reported and dropped, never a crash.

The heartbeats go on a topic of their own, ``/coco/<application>/hosts/heartbeat``, best effort: a
heartbeat says a host's whole state and comes again a fifth of a second later, so a lost one costs
nothing, where on a reliable topic one lost packet would hold up every later heartbeat until it is
sent again (Fast DDS asks for repairs every 3 s by default: on a lossy link the other hosts saw a
host silent for 3 s, "disappeared", while it was there). The other messages (operation calls and
results, the clock exchange) must arrive: reliable, volatile, keeping the last :data:`DEPTH`.

A heartbeat that says its host stops goes on the reliable topic as well, and a host that stopped
waits a moment (:data:`STOP_FLUSH`) at the end for the other hosts to acknowledge it: a host says
its stop as it begins and then with each beat, but a stop of a few milliseconds sends two beats
before its host closes the bus, and with both lost (a loaded machine, a lossy link) the other
hosts never heard it. They counted the silent host as disappeared and, unless ``on_error`` is
``stop_app``, went on without it, alone, until killed (a CI run's demo over two hosts).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator

from rclpy.duration import Duration
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from coco_core.errors import PacketError
from coco_core.hosts.auth import Refusals, Sealer, Verifier
from coco_core.hosts.channel import ros_name
from coco_core.hosts.key import AppKey
from coco_core.hosts.messages import Heartbeat, Stage
from coco_core.messages import Message
from coco_core.wire import Decoder, Encoder
from coco_interfaces.msg import HostMessage

from .bridge import HostBridge
from .seal import seal_of, sealed

log = logging.getLogger("coco")

DEPTH = 256
QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEPTH, reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.VOLATILE)
BEATS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=16, reliability=ReliabilityPolicy.BEST_EFFORT,
                   durability=DurabilityPolicy.VOLATILE)
STOP_FLUSH = 0.5
"""Seconds a host that said it stops waits at most, as it closes the bus, for the other hosts to
acknowledge that on the reliable topic (a host gone already acknowledges nothing: the bound)."""


def bus_topic(application: str) -> str:
    return f"/coco/{ros_name(application)}/hosts"


def message_parts(message: HostMessage) -> Iterator[object]:
    """What a HostMessage's seal covers besides the topic and the seal's own fields."""
    yield message.recipient
    yield message.body


class DdsBus:
    """The :class:`coco_core.hosts.session.Bus` of one host, on ``bridge`` (whose thread runs
    ``receive(sender, message)`` for each authentic message to this host from another host of
    ``hosts``)."""

    def __init__(self, bridge: HostBridge, application: str, host: str, hosts: list[str],
                 receive: Callable[[str, Message], None], release: Callable[[], None], key: AppKey,
                 refusals: Refusals) -> None:
        self.host = host
        self.receive = receive
        self.release = release
        self.damaged = 0
        """Authentic messages whose body did not decode (reported, dropped)."""
        topic = bus_topic(application)
        others = [name for name in hosts if name != host]
        self._encoder = Encoder()
        self._decoder = Decoder()
        # Not among the bridge's flushed publishers: at the end the other hosts may be gone already;
        # only a stop is waited for, and only so long (close).
        self.publisher = bridge.node.create_publisher(HostMessage, topic, QOS)
        self.beats = bridge.node.create_publisher(HostMessage, f"{topic}/heartbeat", BEATS)
        self._sealers = {self.publisher: Sealer(key, topic, host), self.beats: Sealer(key, f"{topic}/heartbeat", host)}
        checks = {name: Verifier(key, name, others, hosts, refusals, own=host) for name in (topic, f"{topic}/heartbeat")}
        self._own = {sealer.session for sealer in self._sealers.values()}
        self._stop_said = False
        """Whether this host said it stops on the reliable topic (:meth:`close` waits for it)."""
        self.subscriptions = [bridge.subscribe(HostMessage, topic, lambda message: self._heard(message, checks[topic]),
                                               QOS),
                              bridge.subscribe(HostMessage, f"{topic}/heartbeat",
                                               lambda message: self._heard(message, checks[f"{topic}/heartbeat"]),
                                               BEATS)]

    def send(self, recipient: str, message: Message) -> None:
        out = HostMessage()
        out.sender, out.recipient, out.body = self.host, recipient, self._encoder.encode(message)
        if not isinstance(message, Heartbeat):
            self._publish(self.publisher, out)
            return
        self._publish(self.beats, out)
        if message.stage is Stage.STOPPING:  # the one beat that must arrive (see the module)
            self._stop_said = True
            self._publish(self.publisher, out)

    def _publish(self, publisher: Publisher, out: HostMessage) -> None:
        publisher.publish(sealed(out, self._sealers[publisher], message_parts(out)))

    def _heard(self, message: HostMessage, verifier: Verifier) -> None:
        if message.recipient not in ("", self.host):
            return
        if message.sender == self.host and message.session in self._own:
            return  # its own, heard back
        if not verifier.accept(seal_of(message), message_parts(message)):
            return
        try:
            body = self._decoder.decode(message.body)
        except PacketError as error:  # a bug of a host with the key, or another version of CoCo
            self.damaged += 1
            log.error("host %s: a message from host %s could not be read (%s); dropped", self.host, message.sender,
                      error)
            return
        if not isinstance(body, Message):
            self.damaged += 1
            log.error("host %s: host %s sent a %s, not a launch message; dropped", self.host, message.sender,
                      type(body).__name__)
            return
        self.receive(message.sender, body)

    def close(self) -> None:
        """This host is done with the bus (the bridge closes once nothing else of it is used); one
        that said it stops first waits, :data:`STOP_FLUSH` at most, until the other hosts
        acknowledged that."""
        if self._stop_said and not self.publisher.wait_for_all_acked(Duration(nanoseconds=int(STOP_FLUSH * 1e9))):
            log.info("host %s: not every other host acknowledged its stop within %.1f s (gone already, or slow)",
                     self.host, STOP_FLUSH)
        self.release()
