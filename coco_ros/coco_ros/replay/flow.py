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

What the replay can do is say so, before and after: :func:`shallow_subscribers` lists the matched
subscriptions (``get_subscriptions_info_by_topic``) that may keep fewer messages than a topic sends
in one burst: KEEP_LAST with a depth below the topic's count, and those whose history the middleware
does not announce. DDS discovery carries reliability and durability but not history: rmw_fastrtps
reports a subscriber in another process as history UNKNOWN, depth 0, so such a subscriber is named
too (rclpy's default, KEEP_LAST 10, is the usual case), with what to do about it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
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


@dataclass(frozen=True)
class ShallowSubscriber:
    """A subscription that may keep fewer messages than a topic sends as fast as possible."""

    topic: str
    node: str
    """Its node's fully qualified name."""
    depth: int | None
    """Its KEEP_LAST depth; None when the middleware does not announce its history."""
    count: int
    """Messages the replay sends on the topic (per pass)."""
    gid: bytes = b""
    """The subscription's endpoint GID: the same subscription, whatever its node was called when seen."""

    def describe(self) -> str:
        history = (f"KEEP_LAST {self.depth}" if self.depth is not None
                   else "history unknown: DDS discovery does not announce it; rclpy's default is KEEP_LAST 10")
        return f"{self.topic} ({self.count} messages) to {self.node} ({history})"


UNKNOWN_NODE = "_NODE_NAME_UNKNOWN_"
"""The node name rmw gives a subscription whose node's description has not been discovered yet (it
comes on a topic of its own, after the endpoint, later still on a loaded machine)."""


def shallow_subscribers(node: Any, counts: dict[str, int], resolve_within: float = 1.0) -> list[ShallowSubscriber]:
    """The subscriptions matched on each topic of ``counts`` (topic -> messages sent per pass) whose
    history may be shallower than that count: KEEP_LAST with a smaller depth, or not announced. A
    subscription whose node is not known yet is asked again for ``resolve_within`` seconds at most, so
    that the warning names the node rather than rmw's placeholder."""
    deadline = time.monotonic() + resolve_within
    while True:
        found = _shallow(node, counts)
        if all(UNKNOWN_NODE not in s.node for s in found) or time.monotonic() >= deadline:
            return found
        time.sleep(0.05)


def merged(seen: list[ShallowSubscriber], later: list[ShallowSubscriber]) -> list[ShallowSubscriber]:
    """``seen`` and ``later`` as one list, one entry per subscription (topic and GID): the later entry
    wins, with the name of a node that was not known yet at first."""
    by_endpoint = {(s.topic, s.gid or s.node): s for s in seen}
    by_endpoint.update({(s.topic, s.gid or s.node): s for s in later})
    return list(by_endpoint.values())


def _shallow(node: Any, counts: dict[str, int]) -> list[ShallowSubscriber]:
    from rclpy.qos import HistoryPolicy

    found = []
    for topic, count in counts.items():
        for info in node.get_subscriptions_info_by_topic(topic):
            qos = info.qos_profile
            if qos.history == HistoryPolicy.KEEP_ALL:
                continue
            known = qos.history == HistoryPolicy.KEEP_LAST
            if known and qos.depth >= count:
                continue
            namespace = info.node_namespace.rstrip("/")
            found.append(ShallowSubscriber(topic, f"{namespace}/{info.node_name}", qos.depth if known else None,
                                           count, bytes(info.endpoint_gid)))
    return found


SHALLOW_ADVICE = ("replay at a pace they can follow (--rate, e.g. --rate 1) or give them a deeper history "
                  "(KEEP_ALL, or a KEEP_LAST depth of at least the topic's count)")
"""What to do about shallow subscribers: the same words at the start and in the final report."""
