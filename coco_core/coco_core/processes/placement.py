"""Which process runs what: the scheduling tree's process level, read from an application model.

Every activity belongs to one process (its ``<process>``, or the launcher's own, named ``""``); a
component belongs to the process of the activity that runs it, a peer to its owner's, and a
component that no activity runs stays in the launcher's process (where it serves operations, like
the TransformationInterface that keeps the transformation graph whole). A connection whose two ends
are in different processes *crosses*: it becomes a shared-memory channel with the same policy (a
connection with a filter: a ring that feeds the filter on the reader's side,
:func:`coco_core.boundary.ring_policy`).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field

from ..errors import ConfigError
from ..files import MiB
from ..boundary import ring_policy
from ..model import AppSpec, ConnectionSpec, PortRef, ProcessSpec
from ..policy import BufferPolicy, SyncPolicy
from ..shm import layout, ring_size
from ..shm.segment import SHM_DIR, free_bytes

LAUNCHER = ""
"""The name of the launcher's own process in a placement."""


@dataclass
class Placement:
    """The process of every activity and component of one application."""

    processes: dict[str, ProcessSpec] = field(default_factory=dict)
    """The child processes, by name, in file order."""
    of_activity: dict[str, str] = field(default_factory=dict)
    of_component: dict[str, str] = field(default_factory=dict)
    """Every component (peers too) -> its process."""
    top_of: dict[str, str] = field(default_factory=dict)
    """Every component (peers too) -> the top-level component that owns it (itself for a top one)."""

    @classmethod
    def of(cls, spec: AppSpec) -> Placement:
        placement = cls({process.name: process for process in spec.processes})
        for activity in spec.activities:
            placement.of_activity[activity.name] = activity.process
        scheduled = {name: activity.process for activity in spec.activities for name in activity.components}
        for top in spec.components:
            process = scheduled.get(top.name, LAUNCHER)
            stack = [top]
            while stack:
                component = stack.pop()
                placement.of_component[component.name] = process
                placement.top_of[component.name] = top.name
                stack.extend(component.peers)
        return placement

    @property
    def several(self) -> bool:
        """Whether the application has child processes at all."""
        return bool(self.processes)

    def process_of(self, component: str) -> str:
        return self.of_component.get(component, LAUNCHER)

    def process_of_ref(self, ref: PortRef) -> str:
        """The process of the component, or activity (``beginit``/``endit``), that ``ref`` names."""
        return self.of_activity.get(ref.component, LAUNCHER) if ref.activity else self.process_of(ref.component)

    def crosses(self, connection: ConnectionSpec) -> bool:
        return self.process_of_ref(connection.src) != self.process_of_ref(connection.dest)

    def crossing(self, spec: AppSpec) -> list[ConnectionSpec]:
        """The connections of ``spec`` that join two processes, in file order."""
        return [connection for connection in spec.connections if self.crosses(connection)]

    def problems(self, spec: AppSpec) -> list[ConfigError]:
        """What cannot run across processes: an UNSYNC connection between two processes, and rings
        (a BUFFER's values, each in a slot) larger than the shared memory left: found by ``--check``
        too, not by the kernel's ENOMEM when the launcher makes them."""
        errors = []
        free, needed = free_bytes(), 0
        for connection in self.crossing(spec):
            if connection.data is not BufferPolicy.POOL:  # a pool's control segment is a few kB
                policy = ring_policy(connection)
                size = ring_size(*layout(policy, None))
                needed += size
                if needed > free:
                    errors.append(ConfigError(
                        f"connection {connection.src} -> {connection.dest} ({policy}) between processes needs "
                        f"{size / MiB:.1f} MiB of shared memory, and the connections between processes up to "
                        f"it {needed / MiB:.1f} MiB; {SHM_DIR} has {free / MiB:.1f} MiB free (a smaller "
                        "buffersize, or both ends in one process)", connection.location))
                    free = sys.maxsize  # one error says it
            if connection.policy is SyncPolicy.UNSYNC:
                src, dest = self.process_of_ref(connection.src), self.process_of_ref(connection.dest)
                errors.append(ConfigError(
                    f"UNSYNC connection {connection.src} -> {connection.dest} joins process "
                    f"{src or 'launcher'!r} and process {dest or 'launcher'!r}; UNSYNC is only valid inside "
                    "one activity (use LOCKED or LOCK_FREE)", connection.location))
        return errors
