"""Flow control of a replay over DDS: as fast as possible, but nothing dropped unseen by the replay.

A KEEP_LAST publisher keeps its last ``depth`` messages for the reliable subscribers that have not
acknowledged them yet; publishing a bag as fast as possible overwrites the oldest of them before they
were delivered, silently (``coco-replay --fast`` once delivered about half of a real bag's /tf and
/odom at depth 100). So, as fast as possible, a volatile topic is offered with KEEP_ALL history: the
publisher keeps every message until each reliable subscriber has acknowledged it, and DDS's
reliability protocol delivers it even to a subscriber that falls behind for a while. At the end the
replay waits (:data:`ACK_TIMEOUT`) until every reliable subscriber acknowledged everything, and
reports per topic what was not acknowledged (a subscriber gone or stuck): :func:`unacknowledged`.

Measured, not assumed (rmw_fastrtps on loopback): waiting for acknowledgements every few messages
(``wait_for_all_acked``) is no flow control, since a reader acknowledges on the writer's periodic
heartbeat (3 s by default), not at once. What a subscriber's own KEEP_LAST history overwrites because
its callbacks are slower than the replay happens on its side, after the acknowledgement: a replay
cannot see it. Such a subscriber needs a deeper history (or KEEP_ALL), or the replay a ``--rate``.
Transient-local topics keep the recorded depth (what a late subscriber gets), see
:func:`~coco_ros.bag.qos.for_replay`.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from ..bag.qos import Qos

ACK_TIMEOUT = 10.0
"""Seconds the end of a replay waits for the reliable subscribers' acknowledgements (more than
rmw_fastrtps' 3 s heartbeat period, which paces the acknowledgements)."""


def as_fast_as_possible(offered: Qos) -> Qos:
    """The profile to offer when replaying as fast as possible: KEEP_ALL for a volatile topic, so no
    message is overwritten before every reliable subscriber has it; a transient-local topic keeps its
    recorded history (what a late subscriber gets is part of the recording)."""
    if offered.transient_local:
        return offered
    return replace(offered, history="keep_all", depth=0)


def unacknowledged(publishers: dict[str, Any], timeout: float = ACK_TIMEOUT) -> list[str]:
    """Wait until every reliable subscriber acknowledged everything published; return the topics
    where that did not happen within ``timeout`` seconds in total (their last messages may be lost)."""
    import time

    from rclpy.duration import Duration

    deadline = time.monotonic() + timeout
    late = []
    for topic, publisher in publishers.items():
        remaining = max(0.0, deadline - time.monotonic())
        if not publisher.wait_for_all_acked(Duration(seconds=remaining)):
            late.append(topic)
    return late
