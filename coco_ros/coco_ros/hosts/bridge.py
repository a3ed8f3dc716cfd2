"""HostBridge: the DDS side of one process of an application spread over several hosts.

A process that holds ends of connections between hosts (:mod:`.channel`), or speaks the control
protocol between hosts, needs a DDS participant, a node and a thread that takes what arrives. It
gets them here, apart from anything else ROS in the same process:

- its **own rclpy context**: the ROS launcher's node, executor and wait sets live in the default
  context of the same process; a context of its own means the bridge never adds entities to their
  wait sets, never shares their executor's thread, and is shut down without shutting ROS down for
  the activities (and the other way round). Signal handlers are left alone: Ctrl-C stays the
  launcher's (``coco_ros.launcher``);
- **one node** (named by the caller, e.g. ``coco_<app>_<host>_<process>``, so that ``ros2 node
  list`` tells the hosts' processes apart);
- **one executor thread**, ``coco:dds`` (a daemon: it never keeps a stopping process alive), that
  runs every subscription made through :meth:`HostBridge.subscribe`. A ``SingleThreadedExecutor``:
  it waits with no timeout and wakes on each sample, and the callbacks here are short (decode and
  store; the activities run elsewhere). rclpy 7's multi-threaded executor can miss a wake-up
  (``coco_ros.hosting``), which a data path cannot afford.

:meth:`HostBridge.close` first lets the publishers made through :meth:`HostBridge.publisher` get
their last samples acknowledged (the ``writer_done`` of each connection, what a BUFFER reader waits
for), for half its timeout at most, then stops the thread and destroys node and context, all within
``timeout`` (a second by default): a host that is gone costs that bound, never a hang.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable

import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription
from rclpy.task import Future

log = logging.getLogger("coco.hosts")

THREAD_NAME = "coco:dds"


class HostBridge:
    """One DDS participant, node and executor thread of a process (see the module's docstring).
    Use it as a context manager, or call :meth:`close`."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.context = Context()
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        try:
            self.node = Node(name, context=self.context, start_parameter_services=False)
        except BaseException:
            self.context.try_shutdown()
            raise
        self.group = MutuallyExclusiveCallbackGroup()
        """The callback group of everything that :meth:`subscribe` makes, which the thread runs."""
        self._executor = SingleThreadedExecutor(context=self.context)
        self._executor.add_node(self.node)
        self._publishers: list[Publisher] = []
        self._closing = Future()
        self._thread = threading.Thread(target=self._spin, name=THREAD_NAME, daemon=True)
        self._thread.start()

    def subscribe(self, message_type: Any, topic: str, callback: Callable[[Any], None],
                  qos: QoSProfile) -> Subscription:
        """A subscription whose ``callback`` runs in the ``coco:dds`` thread."""
        return self.node.create_subscription(message_type, topic, callback, qos, callback_group=self.group)

    def publisher(self, message_type: Any, topic: str, qos: QoSProfile) -> Publisher:
        """A publisher whose last samples :meth:`close` waits to see acknowledged (bounded)."""
        publisher = self.node.create_publisher(message_type, topic, qos)
        self._publishers.append(publisher)
        return publisher

    @property
    def running(self) -> bool:
        """Whether the executor thread still runs (False once closed)."""
        return self._thread.is_alive()

    def _spin(self) -> None:
        executor, closing = self._executor, self._closing
        while not closing.done() and self.context.ok():
            try:
                executor.spin_once_until_future_complete(closing)
            except ExternalShutdownException:
                return
            except Exception:  # a callback's own failure: the others go on being served
                log.exception("a DDS callback of %s failed", self.name)

    def close(self, timeout: float = 1.0) -> bool:
        """Flush the publishers (half of ``timeout`` at most), stop the thread, destroy node and
        context; whether the thread stopped within ``timeout`` seconds. Closing twice is harmless."""
        if self._closing.done():
            return not self._thread.is_alive()
        deadline = time.monotonic() + timeout
        flushed = self._flush(deadline - timeout / 2)
        self._closing.set_result(None)
        self._executor.wake()
        self._thread.join(max(0.0, deadline - time.monotonic()))
        stopped = not self._thread.is_alive()
        if stopped:  # a callback still running would use what is destroyed here: left to the daemon then
            self._executor.shutdown(0)
            self.node.destroy_node()
        else:
            log.warning("the DDS thread of %s did not stop within %.1f s", self.name, timeout)
        if not flushed:
            log.warning("%s closed with samples that no reader acknowledged (its readers' hosts are gone or "
                        "slow): the readers count them as dropped", self.name)
        self.context.try_shutdown()
        if stopped:
            self.context.destroy()  # its DDS participant ends now, not when the collector gets to it
        return stopped

    def _flush(self, until: float) -> bool:
        """Wait until every sample of the publishers is acknowledged by their matched readers, or
        ``until`` (``time.monotonic``) passed; whether all were."""
        for publisher in self._publishers:
            left = until - time.monotonic()
            if left <= 0 or not publisher.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))):
                return False
        return True

    def __enter__(self) -> HostBridge:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<HostBridge {self.name} {'running' if self.running else 'closed'}>"
