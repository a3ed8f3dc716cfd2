"""DDS between the hosts of an application: the ``coco.host_transports`` entry point ``dds``.

coco_core plans the hosts and runs the launch's barriers (:mod:`coco_core.hosts`); this is what it
asks of the network, in each process: the launch's messages (:class:`~.bus.DdsBus`, in a host's
launcher) and the ends of the connections between hosts (:mod:`.channel`, in the process that holds
each end). One :class:`~.bridge.HostBridge` per process carries both, and is closed once neither
uses it any more: its close delivers the last messages and samples (bounded).
"""

from __future__ import annotations

import threading
from typing import Callable

from coco_core import Application
from coco_core.hosts.auth import Refusals
from coco_core.hosts.clock import ClockOffset
from coco_core.hosts.channel import ros_name
from coco_core.hosts.key import AppKey
from coco_core.model import AppSpec
from coco_core.messages import Message

from .bridge import HostBridge
from .bus import DdsBus
from .channel import HostEnds, attach_between_hosts
from .fastdds import use_hosts_profile


class DdsTransport:
    """The network of one process of an application over several hosts."""

    def __init__(self) -> None:
        use_hosts_profile()  # before this process's first participant (the ROS launcher did it before its node)
        self._bridge: HostBridge | None = None
        self._users = 0
        self._lock = threading.Lock()

    def _use(self, spec: AppSpec, process: str) -> HostBridge:
        with self._lock:
            if self._bridge is None:
                self._bridge = HostBridge(ros_name(f"coco_{spec.name}_{spec.part_of}_{process or 'launcher'}")
                                          .replace("/", "_"))
            self._users += 1
            return self._bridge

    def _release(self) -> None:
        with self._lock:
            self._users -= 1
            bridge = self._bridge if self._users == 0 else None
            if bridge is not None:
                self._bridge = None
        if bridge is not None:
            bridge.close()

    def bus(self, spec: AppSpec, receive: Callable[[str, Message], None], key: AppKey,
            refusals: Refusals) -> DdsBus:
        return DdsBus(self._use(spec, ""), spec.name, spec.part_of, [host.name for host in spec.hosts], receive,
                      self._release, key, refusals)

    def attach(self, app: Application, spec: AppSpec, clock: ClockOffset, key: AppKey) -> ProcessEnds:
        bridge = self._use(spec, app.process)
        try:
            ends = attach_between_hosts(app, bridge, spec.between_hosts, spec.part_of, key,
                                        [host.name for host in spec.hosts], clock.to_app, clock.from_app)
        except BaseException:
            self._release()
            raise
        return ProcessEnds(ends, self._release)


class ProcessEnds:
    """This process's ends of the connections between hosts (:class:`coco_core.levels.Ends`)."""

    def __init__(self, ends: HostEnds, release: Callable[[], None]) -> None:
        self.ends = ends
        self._release = release

    def unmatched(self) -> list[str]:
        return self.ends.unmatched()

    def close(self) -> None:
        self._release()
