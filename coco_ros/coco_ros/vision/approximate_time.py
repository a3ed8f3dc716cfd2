"""Messages of several topics paired by their header stamps, as message_filters'
``ApproximateTimeSynchronizer`` pairs them (its Python implementation in ROS 2 Jazzy).

A camera driver publishes colour and depth on two topics, each message stamped with its
acquisition time; the two streams arrive interleaved, one may lose a message, and their stamps
differ by up to the sensors' offset. Every topic keeps its ``queue_size`` newest messages by stamp;
when a message arrives, the queues of the other topics are searched, nearest stamps first, for one
message each whose stamps all lie within ``slop`` of one another (the new message's included): the
first such set is delivered and removed from the queues. A message pushed out of its full queue was
never paired: it is counted (:attr:`ApproximateTime.unpaired`), as a live camera's lost frame.

A stamp more than :data:`JUMP` older than the newest its topic had is a jump back in time (a
recording played again, a clock reset: tf2's buffer clears itself on one too): every queue is
emptied (counted as unpaired) and pairing starts again, instead of the new messages, older than all
the queued ones, being pushed out of their queue forever.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

JUMP = 1.0
"""Seconds back in time after which the queues start again."""


class ApproximateTime:
    """The pairing of ``topics`` messages (see the module's docstring); not thread-safe: one caller
    at a time (the subscriptions of one callback group)."""

    def __init__(self, topics: int, queue_size: int, slop: float) -> None:
        if topics < 2 or queue_size < 1 or not slop >= 0.0:
            raise ValueError(f"ApproximateTime needs 2 topics or more, a queue of 1 or more and a slop >= 0; got "
                             f"{topics}, {queue_size}, {slop}")
        self.queues: list[dict[int, Any]] = [{} for _ in range(topics)]
        self.queue_size = queue_size
        self.slop_ns = round(slop * 1e9)
        self.unpaired = 0
        """Messages pushed out of a full queue, replaced by one of the same stamp, or dropped at a jump
        back in time, never paired."""
        self.jumps = 0
        """Jumps back in time seen."""
        self.newest = [-(2 ** 63)] * topics
        """The newest stamp each topic had, in nanoseconds."""

    def add(self, topic: int, stamp_ns: int, message: Any) -> Sequence[Any] | None:
        """Add ``message`` of ``topic`` stamped ``stamp_ns``; the set of messages it completes (one
        per topic, in topic order), or None."""
        queue = self.queues[topic]
        if stamp_ns < self.newest[topic] - JUMP * 1e9:
            self.jumps += 1
            self.unpaired += sum(map(len, self.queues))
            for emptied in self.queues:
                emptied.clear()
            self.newest = [-(2 ** 63)] * len(self.queues)
        self.newest[topic] = max(self.newest[topic], stamp_ns)
        if stamp_ns in queue:
            self.unpaired += 1
        queue[stamp_ns] = message
        while len(queue) > self.queue_size:
            del queue[min(queue)]
            self.unpaired += 1
        if stamp_ns not in queue:  # older than every message queued: it was the one pushed out
            return None
        candidates = []
        for index, other in enumerate(self.queues):
            if index == topic:
                continue
            near = sorted((abs(stamp - stamp_ns), stamp) for stamp in other if abs(stamp - stamp_ns) <= self.slop_ns)
            if not near:
                return None
            candidates.append([stamp for _, stamp in near])
        for stamps in itertools.product(*candidates):
            chosen = list(stamps)
            chosen.insert(topic, stamp_ns)
            if max(chosen) - min(chosen) <= self.slop_ns:
                return [queue.pop(stamp) for queue, stamp in zip(self.queues, chosen)]
        return None
