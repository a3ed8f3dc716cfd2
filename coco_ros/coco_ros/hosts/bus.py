"""The launch's messages between the hosts of one application, on one DDS topic.

Every host publishes on ``/coco/<application>/hosts`` and listens to it; a message names its
sender and its recipient (empty: every host). Its body is one of the typed messages of the launch
(:mod:`coco_core.hosts.messages`, :mod:`coco_core.processes.messages`), pickled: the hosts of one
application trust each other as the processes of one launch do (use a DDS domain of the
application's own, or SROS 2, where the network is shared with others). A body that does not
unpickle is reported and dropped, never a crash.

Reliable, volatile, keeping the last :data:`DEPTH`: a heartbeat says a host's whole state and comes
again a fifth of a second later, so what a host missed before it listened costs nothing; an
operation's call and result must arrive, which reliability gives while both hosts are there.
"""

from __future__ import annotations

import logging
import pickle
from collections.abc import Callable

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from coco_core.hosts.channel import ros_name
from coco_core.processes.messages import Message
from coco_interfaces.msg import HostMessage

from .bridge import HostBridge

log = logging.getLogger("coco")

DEPTH = 256
QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEPTH, reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.VOLATILE)


def bus_topic(application: str) -> str:
    return f"/coco/{ros_name(application)}/hosts"


class DdsBus:
    """The :class:`coco_core.hosts.session.Bus` of one host, on ``bridge`` (whose thread runs
    ``receive(sender, message)`` for each message to this host). Closing the bridge delivers the
    last messages (it waits, bounded, for the other hosts to acknowledge them)."""

    def __init__(self, bridge: HostBridge, application: str, host: str,
                 receive: Callable[[str, Message], None], release: Callable[[], None]) -> None:
        self.host = host
        self.receive = receive
        self.release = release
        self.damaged = 0
        """Messages whose body did not unpickle (reported, dropped)."""
        topic = bus_topic(application)
        self.publisher = bridge.publisher(HostMessage, topic, QOS)
        self.subscription = bridge.subscribe(HostMessage, topic, self._heard, QOS)

    def send(self, recipient: str, message: Message) -> None:
        out = HostMessage()
        out.sender, out.recipient, out.body = self.host, recipient, pickle.dumps(message)
        self.publisher.publish(out)

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
