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
- **one thread**, ``coco:dds (wait set)`` (a daemon: it never keeps a stopping process alive), that
  runs every subscription made through :meth:`HostBridge.subscribe`: an
  :class:`~coco_ros.wait_set.ActivityWaitSet` on the bridge's group, which waits on those
  subscriptions only, with a wait set filled again without being reallocated, and runs each callback
  in place. The callbacks are short (decode and store; the activities run elsewhere). rclpy's
  ``SingleThreadedExecutor`` did the same job first: it rebuilds its wait set in Python for every
  sample, and a small sample between hosts took 1.54x the time of a plain rclpy pair's; with the wait
  set, 0.88-1.09x (``bench/bench_hosts.py``, ``docs/benchmarks.md``).

:meth:`HostBridge.close` first lets the publishers made through :meth:`HostBridge.publisher` get
their last samples acknowledged (the ``writer_done`` of each connection, what a BUFFER reader waits
for), for half its timeout at most, then stops the thread and destroys node and context, all within
``timeout`` (a second by default): a host that is gone costs that bound, never a hang.
"""

from __future__ import annotations

import logging
import time
from typing import Any, Callable

import rclpy
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription

from ..wait_set import ActivityWaitSet, WaitSetGroup

log = logging.getLogger("coco.hosts")

THREAD_NAME = "coco:dds (wait set)"


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
        self.group = WaitSetGroup()
        """The callback group of everything that :meth:`subscribe` makes, which the thread runs."""
        self._waits = ActivityWaitSet(self.group, self.context, "dds")
        self._publishers: list[Publisher] = []
        self._closed = False
        self._waits.start()

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
        """Whether the thread still runs (False once closed)."""
        return self._waits.running

    def close(self, timeout: float = 1.0) -> bool:
        """Flush the publishers (half of ``timeout`` at most), stop the thread, destroy node and
        context; whether the thread stopped within ``timeout`` seconds. Closing twice is harmless."""
        if self._closed:
            return not self.running
        self._closed = True
        deadline = time.monotonic() + timeout
        flushed = self._flush(deadline - timeout / 2)
        stopped = self._waits.stop(max(0.0, deadline - time.monotonic()))
        if stopped:  # a callback still running would use what is destroyed here: left to the daemon then
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
