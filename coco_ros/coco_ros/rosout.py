"""CoCo's Python log lines on ``/rosout``, as a ROS node's own log lines are.

CoCo logs with Python's ``logging`` (the launchers print it on the console); rcl only publishes
what goes through rcutils, so without this handler rqt_console, ``ros2 topic echo /rosout`` and
recorded bags never saw a CoCo warning. The handler publishes each record as an
``rcl_interfaces/msg/Log`` with rcl's own ``/rosout`` QoS (reliable, transient local, depth 1000,
10 s lifespan) and leaves the console output as it is: routing the records through an rclpy logger
instead would print them twice, in another format. The severities match by number (DEBUG 10,
INFO 20, WARN 30, ERROR 40, FATAL 50 in both); the logger name is the node's logger name followed
by the record's (``baxter_teleop_replay.coco.replay``), so each child process's lines carry its
own node's name.
"""

from __future__ import annotations

import logging
from typing import Any

ROSOUT = "/rosout"
FLUSH_TIMEOUT = 0.3
"""Seconds a process waits at its end for /rosout's subscribers to acknowledge its last lines."""


class RosoutHandler(logging.Handler):
    """Publishes the log records of this process on ``/rosout`` through ``node``."""

    def __init__(self, node: Any) -> None:
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
        from rclpy.duration import Duration
        from rcl_interfaces.msg import Log

        super().__init__()
        self._log_type = Log
        self._logger_name = node.get_logger().name
        self._publisher = node.create_publisher(Log, ROSOUT, QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL, lifespan=Duration(seconds=10)))

    def flush(self) -> None:
        """Wait (briefly) until every subscriber has what was published: the lines logged while the
        application stops would otherwise die with the node's publisher, undelivered."""
        from rclpy.duration import Duration

        try:
            self._publisher.wait_for_all_acked(Duration(seconds=FLUSH_TIMEOUT))
        except Exception:  # the node is already gone
            pass

    def emit(self, record: logging.LogRecord) -> None:
        try:
            message = self._log_type()
            seconds = record.created
            message.stamp.sec = int(seconds)
            message.stamp.nanosec = int((seconds - int(seconds)) * 1e9)
            message.level = min(max(record.levelno // 10 * 10, 10), 50)
            message.name = f"{self._logger_name}.{record.name}"
            message.msg = record.getMessage()
            message.file = record.pathname
            message.function = record.funcName or ""
            message.line = record.lineno
            self._publisher.publish(message)
        except Exception:  # a destroyed publisher at shutdown, a message that cannot be formatted
            self.handleError(record)


class RosoutLogging:
    """``with RosoutLogging(node):`` every Python log record of the block also goes to ``/rosout``."""

    def __init__(self, node: Any) -> None:
        self._handler = RosoutHandler(node)

    def __enter__(self) -> RosoutHandler:
        logging.getLogger().addHandler(self._handler)
        return self._handler

    def __exit__(self, *exc: object) -> None:
        logging.getLogger().removeHandler(self._handler)
        self._handler.flush()
