"""A mirror: a connection from an output port to a ROS publisher, served by the node's executor.

The port's writes go into a connection of the mirror's policy (made by
:func:`coco_core.connections.make_connection`, as any connection's), so they are counted as any
connection's writes are: the profile shows ``component.port -> ROS topic /name`` with what was
written, published (read) and dropped (what the policy discarded, values no converter took, and
values left when the last subscriber went). Its trigger is a guard condition of the node: the
executor takes the values, converts and publishes them, in order, never in the writer's thread.

Nothing is converted while no one subscribes: until the publisher matches a subscription
(rmw's *matched* event), the connection is muted on its port (:meth:`OutputPort.mute
<coco_core.ports.OutputPort.mute>`), which then writes as if the mirror were not there. A port
declared as carrying anything (``Stamped``) has its publisher made once its first value showed the
message type (:mod:`.choice`), looked at by a timer of the executor, never by the writer.

A ``<topic hz=...>`` publishes the newest value at most that often instead: a timer of the executor
takes it, the older ones count as dropped, and the port's writes wake nothing (a 1 kHz haptic loop
seen by a viewer at 30 Hz costs its process 30 conversions a second, not a thousand).

QoS follows the policy: DATA keeps the newest message (depth 1, reliable), BUFFER ``n`` keeps
``n`` (reliable: a subscriber that keeps up gets every value in order), CIRCULAR ``n`` keeps ``n``
best effort (the newest matter, as on the connection).
"""

from __future__ import annotations

import logging
import time
from typing import Any

from coco_core import Application
from coco_core.connections import EMPTY, make_connection
from coco_core.policy import BufferPolicy, ConnectionPolicy, SyncPolicy
from coco_core.pool import Slot
from coco_core.ports import PooledOutputPort
from coco_core.stamps import Message, Stamped

from ..bag.qos import Qos
from .adapt import adapted, slot_value
from .choice import mirror_converter, value_ros_type
from .plan import Mirrored

log = logging.getLogger("coco.mirror")

_FULL_ERRORS = 3
"""Conversion errors logged in full per mirror before switching to one line per second."""
TYPE_POLL_S = 0.2
"""How often the executor looks whether a port typed by its values has written its first one."""


def qos_of(data: BufferPolicy, size: int) -> Qos:
    """The topic's QoS for a mirror connection's policy (see the module docstring)."""
    if data is BufferPolicy.DATA:
        return Qos(depth=1)
    return Qos(depth=size, reliability="best_effort" if data is BufferPolicy.CIRCULAR else "reliable")


class PortMirror:
    """One port mirrored on one topic of ``node``; its ROS entities in ``group``."""

    def __init__(self, node: Any, group: Any, app: Application, mirrored: Mirrored) -> None:
        self.node = node
        self.group = group
        self.app = app
        self.mirrored = mirrored
        self.topic = node.resolve_topic_name(mirrored.topic, only_expand=True)
        port = mirrored.port
        self.connection = port.connection() if isinstance(port, PooledOutputPort) else \
            make_connection(ConnectionPolicy(mirrored.data, SyncPolicy.LOCKED, mirrored.size))
        self.connection.reader = f"ROS topic {self.topic}"
        self.publisher: Any = None
        self.guard: Any = None
        """What drains the connection: a guard condition its writes trigger, or a timer (``hz``)."""
        self.subscribers = 0
        self.errors = 0
        self._last_log = 0.0
        self._encode: Any = None

    @property
    def port(self) -> Any:
        return self.mirrored.port

    def resolve(self) -> bool:
        """Make the publisher once the message type is known; whether the mirror is done waiting
        (attached, or given up on a value no converter knows, logged with the port's name)."""
        ros_type = self.mirrored.ros_type
        if not ros_type:
            last = self.port.last
            if last is None:
                return False
            chosen = value_ros_type(last.value)
            if chosen is None:
                value = last.value.value if isinstance(last.value, Stamped) else last.value
                log.error("port %s is not mirrored on %s: no converter knows its values (%s)",
                          self.port.qualified_name, self.topic, type(value).__name__)
                return True
            ros_type = chosen
        self._attach(ros_type)
        return True

    def _attach(self, ros_type: str) -> None:
        from rclpy.event_handler import PublisherEventCallbacks

        converter = mirror_converter(ros_type, self.mirrored.frame)
        encode = converter.to_cdr if converter.writes_cdr else converter.to_ros
        frame = self.mirrored.frame
        self._encode = lambda value: encode(adapted(value, frame))
        self.port.add_connection(self.connection)  # muted before a subscriber can match
        self.port.mute(self.connection, True)
        self.app.connections.append(self.connection)  # its counters in the profile
        if self.mirrored.hz > 0:
            self.guard = self.node.create_timer(1.0 / self.mirrored.hz, self._publish_newest, callback_group=self.group)
        else:
            self.guard = self.node.create_guard_condition(self._drain, callback_group=self.group)
            self.connection.trigger = self.guard.trigger
        self.publisher = self.node.create_publisher(
            converter.message_type, self.topic, qos_of(self.mirrored.data, self.mirrored.size).to_rclpy(),
            callback_group=self.group, event_callbacks=PublisherEventCallbacks(matched=self._matched))
        self.port.mute(self.connection, self.subscribers == 0)  # a subscription matched while it was made
        log.info("port %s mirrored on %s (%s)", self.port.qualified_name, self.topic, ros_type)

    def _matched(self, status: Any) -> None:
        """rmw's matched event: unmute on the first subscriber, mute (and drop what waits) after the last."""
        self.subscribers = status.current_count
        if self.publisher is None:  # the event came before create_publisher returned: _attach applies it
            return
        self.port.mute(self.connection, self.subscribers == 0)
        if self.subscribers == 0:
            self._drop_pending()

    def _drain(self) -> None:
        """Convert and publish every value waiting, in order (the guard condition's callback)."""
        while (item := self.connection.pop()) is not EMPTY:
            self._publish(item)

    def _publish_newest(self) -> None:
        """The newest value waiting, published (the timer's callback, ``hz``); older ones are dropped."""
        item = self.connection.pop_newest()
        if item is not EMPTY:
            self._publish(item)

    def _publish(self, item: Any) -> None:
        try:
            message = self._message(item)
        except Exception as error:  # a value no converter takes must not stop the others
            self.connection.skip()
            self._failed(error)
            return
        self.publisher.publish(message)

    def _message(self, item: Any) -> Any:
        """The message of what the connection gave: a value, or a pooled frame (held meanwhile)."""
        if type(item) is Slot:
            try:
                return self._encode(slot_value(item))
            finally:
                item.release()
        return self._encode(item.value if type(item) is Message else item)

    def _drop_pending(self) -> None:
        """Take what waits unpublished (counted as dropped): nothing is left in flight."""
        while (item := self.connection.pop()) is not EMPTY:
            self.connection.skip()
            if type(item) is Slot:
                item.release()

    def _failed(self, error: Exception) -> None:
        self.errors += 1
        now = time.monotonic()
        if self.errors <= _FULL_ERRORS or now - self._last_log >= 1.0:
            log.error("port %s mirrored on %s: cannot convert a value: %s (%d refused so far, counted as dropped)",
                      self.port.qualified_name, self.topic, error, self.errors)
            self._last_log = now

    def close(self) -> None:
        """Mute the port, drop what waits, destroy the ROS entities (after the application stopped)."""
        if self.publisher is None:
            return
        self.port.mute(self.connection, True)
        self._drop_pending()
        self.node.destroy_publisher(self.publisher)
        if self.mirrored.hz > 0:
            self.node.destroy_timer(self.guard)
        else:
            self.node.destroy_guard_condition(self.guard)
        self.publisher = self.guard = None
