"""The launch's messages between the hosts of one application, on one DDS topic.

Every host publishes on ``/coco/<application>/hosts`` and listens to it; a message names its
sender and its recipient (empty: every host). Its body is one of the typed messages of the launch
(:mod:`coco_core.hosts.messages`, :mod:`coco_core.processes.messages`), pickled: the hosts of one
application trust each other as the processes of one launch do (use a DDS domain of the
application's own, or SROS 2, where the network is shared with others). A body that does not
unpickle is reported and dropped, never a crash.

The heartbeats go on a topic of their own, ``/coco/<application>/hosts/heartbeat``, best effort: a
heartbeat says a host's whole state and comes again a fifth of a second later, so a lost one costs
nothing, where on a reliable topic one lost packet would hold up every later heartbeat until it is
sent again (Fast DDS asks for repairs every 3 s by default: on a lossy link the other hosts saw a
host silent for 3 s, "disappeared", while it was there). The other messages (operation calls and
results, the clock exchange) must arrive: reliable, volatile, keeping the last :data:`DEPTH`.
"""

from __future__ import annotations

import logging
import pickle
from collections.abc import Callable

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from coco_core.hosts.channel import ros_name
from coco_core.hosts.messages import Heartbeat
from coco_core.processes.messages import Message
from coco_interfaces.msg import HostMessage

from .bridge import HostBridge

log = logging.getLogger("coco")

DEPTH = 256
QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEPTH, reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.VOLATILE)
BEATS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=16, reliability=ReliabilityPolicy.BEST_EFFORT,
                   durability=DurabilityPolicy.VOLATILE)


def bus_topic(application: str) -> str:
    return f"/coco/{ros_name(application)}/hosts"


class DdsBus:
    """The :class:`coco_core.hosts.session.Bus` of one host, on ``bridge`` (whose thread runs
    ``receive(sender, message)`` for each message to this host)."""

    def __init__(self, bridge: HostBridge, application: str, host: str,
                 receive: Callable[[str, Message], None], release: Callable[[], None]) -> None:
        self.host = host
        self.receive = receive
        self.release = release
        self.damaged = 0
        """Messages whose body did not unpickle (reported, dropped)."""
        topic = bus_topic(application)
        # Not among the bridge's flushed publishers: at the end the other hosts may be gone already,
        # and a stop was said as soon as it began, then by every heartbeat.
        self.publisher = bridge.node.create_publisher(HostMessage, topic, QOS)
        self.beats = bridge.node.create_publisher(HostMessage, f"{topic}/heartbeat", BEATS)
        self.subscriptions = [bridge.subscribe(HostMessage, topic, self._heard, QOS),
                              bridge.subscribe(HostMessage, f"{topic}/heartbeat", self._heard, BEATS)]

    def send(self, recipient: str, message: Message) -> None:
        out = HostMessage()
        out.sender, out.recipient, out.body = self.host, recipient, pickle.dumps(message)
        (self.beats if isinstance(message, Heartbeat) else self.publisher).publish(out)

    def _heard(self, message: HostMessage) -> None:
        if message.sender == self.host or message.recipient not in ("", self.host):
            return
        try:
            body = pickle.loads(message.body.tobytes())
        except Exception as error:  # damaged on the way, or sent by an incompatible version
            self.damaged += 1
            log.error("host %s: a message from host %s could not be read (%s: %s); dropped", self.host,
                      message.sender, type(error).__name__, error)
            return
        if not isinstance(body, Message):
            self.damaged += 1
            log.error("host %s: host %s sent a %s, not a launch message; dropped", self.host, message.sender,
                      type(body).__name__)
            return
        self.receive(message.sender, body)

    def close(self) -> None:
        """This host is done with the bus (the bridge closes once nothing else of it is used)."""
        self.release()
