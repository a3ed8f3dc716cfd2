"""The DDS quality of service of a connection between hosts, from the connection's own policy.

A connection between hosts keeps its policy where it matters, on the reader's side: the reader's end
stores what arrives in a local connection of that policy (:mod:`.channel`), so DATA overwrites,
a full BUFFER refuses, a CIRCULAR pushes out its oldest exactly as in one process. The DDS link only
has to bring the samples there without ever blocking the writer, which decides the profile:

- always **reliable**: a sample the network lost is sent again while the writer's history still
  holds it, so a loss is the exception the reader counts (a gap in the samples' numbers), not the
  rule, as best effort would make it on a loaded link;
- always **keep last**, never keep all: a keep-all writer blocks (or fails) once its history is full
  of samples a slow or absent reader has not acknowledged, and a write must never block. With keep
  last the writer's history drops its oldest unacknowledged sample instead, and the reader sees the
  gap in the numbers;
- a **depth** of what the reader's side keeps, plus one: DATA 1 (only the newest matters), BUFFER and
  CIRCULAR their ``buffersize`` (what the reader's side can hold is what is worth resending), a
  pooled output's frames (POOL) 1 (a reader takes the newest frame only, and resending older frames
  of megabytes would only delay the one that counts); the one more is for the ``writer_done`` sample
  that follows the last value: with a depth of exactly 1 it could push the last value of a DATA
  connection out of the reader's history before the reader's callback took it;
- **volatile**: a reader that joins late gets what is written from then on, as a connection that
  is made while its writer runs. What it missed is counted (its first number tells), and the hosts'
  start barrier (``docs/hosts.md``) makes every reader join before any writer starts.
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from coco_core.policy import BufferPolicy, ConnectionPolicy


def depth_of(policy: ConnectionPolicy) -> int:
    """The samples the DDS histories keep (see the module's docstring)."""
    if policy.data in (BufferPolicy.BUFFER, BufferPolicy.CIRCULAR):
        return max(1, policy.size) + 1
    return 2


def qos_of(policy: ConnectionPolicy) -> QoSProfile:
    """The QoS of both ends of a connection of ``policy`` between hosts: reliable, keep last
    :func:`depth_of` samples, volatile."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth_of(policy),
                      reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
