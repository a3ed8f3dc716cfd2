"""rclpy anchors: a private ROS context and a publish -> spin_once loopback inside one process.

Import this module before anything imports rclpy: it fixes the DDS domain and keeps discovery on
localhost, so benchmarks never talk to other processes on the machine.
"""

from __future__ import annotations

import os
import time
from typing import Any

os.environ["ROS_DOMAIN_ID"] = os.environ.get("COCO_BENCH_DOMAIN_ID", "87")
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"

import rclpy  # noqa: E402  (the environment above must be set first)
from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402


def rmw_name() -> str:
    try:
        return rclpy.get_rmw_implementation_identifier()
    except Exception:  # pragma: no cover - only informative
        return "unknown"


class RosContext:
    """``with RosContext() as ctx:`` an initialised rclpy context, shut down on exit."""

    def __init__(self) -> None:
        self.context = Context()

    def __enter__(self) -> Context:
        rclpy.init(context=self.context)
        return self.context

    def __exit__(self, *exc: object) -> None:
        self.context.try_shutdown()


class Loopback:
    """One publisher node and one subscriber node on a SingleThreadedExecutor, in this process.

    A *round* publishes one message, then calls ``spin_once`` until the subscription's callback has
    fired: the full cost of handing one message from one component to another through rclpy.
    """

    def __init__(self, context: Context, msg_type: type, topic: str, depth: int = 10) -> None:
        self.pub_node = Node(f"bench_pub_{topic}", context=context)
        self.sub_node = Node(f"bench_sub_{topic}", context=context)
        self.publisher = self.pub_node.create_publisher(msg_type, topic, depth)
        self.received = 0
        self.last: Any = None
        self.subscription = self.sub_node.create_subscription(msg_type, topic, self._on_message, depth)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.pub_node)
        self.executor.add_node(self.sub_node)

    def _on_message(self, msg: Any) -> None:
        self.received += 1
        self.last = msg

    def wait_matched(self, msg: Any, timeout_s: float = 10.0) -> None:
        """Publish until the subscription has received one message (discovery done)."""
        deadline = time.monotonic() + timeout_s
        while self.received == 0:
            if time.monotonic() > deadline:
                raise TimeoutError("the rclpy loopback subscription never received a message")
            self.publisher.publish(msg)
            self.executor.spin_once(timeout_sec=0.05)

    def rounds(self, msg: Any, n: int, timeout_s: float = 5.0) -> None:
        """``n`` rounds of publish + spin until the callback has fired."""
        publish, spin_once = self.publisher.publish, self.executor.spin_once
        for _ in range(n):
            target = self.received + 1
            publish(msg)
            deadline = time.monotonic() + timeout_s
            while self.received < target:
                spin_once(timeout_sec=timeout_s)
                if time.monotonic() > deadline:
                    raise TimeoutError(f"message {target} never arrived through the rclpy loopback")

    def destroy(self) -> None:
        self.executor.shutdown()
        self.pub_node.destroy_node()
        self.sub_node.destroy_node()
