"""What carries an application over several hosts: a plug-in, found by its entry point.

coco_core knows hosts (the file's ``<host>``, each host's part, the launch's barriers and clock) but
not the network: the traffic between hosts is DDS, and DDS comes with ROS 2 (``coco_ros.hosts``,
registered under the entry point group :data:`GROUP`). ``coco-launch`` loads it only when the file
declares hosts, so a one-host application never imports rclpy.
"""

from __future__ import annotations

import functools
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Callable, Protocol

from ..errors import MissingPackageError

if TYPE_CHECKING:
    from ..application import Application
    from ..levels import Ends
    from ..messages import Message
    from ..model import AppSpec
    from .auth import Refusals
    from .clock import ClockOffset
    from .key import AppKey

GROUP = "coco.host_transports"


class Bus(Protocol):
    """How the hosts of one application reach each other (``coco_ros.hosts``: a DDS topic). It calls
    the session's ``receive`` with each message for this host."""

    def send(self, recipient: str, message: Message) -> None:
        """Send ``message`` to host ``recipient`` ("": every other host)."""

    def close(self) -> None:
        """Deliver what was sent (bounded), then release the network resources."""


class HostTransport(Protocol):
    """The network between the hosts of an application."""

    def bus(self, spec: AppSpec, receive: Callable[[str, Message], None], key: AppKey, refusals: Refusals) -> Bus:
        """The launch's messages between the hosts of ``spec`` (one host's part), sealed and checked
        with ``key`` (those that fail are counted in ``refusals``); ``receive(sender, message)`` gets
        those for this host."""

    def attach(self, app: Application, spec: AppSpec, clock: ClockOffset, key: AppKey) -> Ends:
        """Attach this process's ends of ``spec``'s connections between hosts to ``app``'s ports;
        ``clock`` puts the stamps on the application's clock and back, ``key`` seals and checks
        every sample."""


@functools.cache
def host_transport() -> HostTransport:
    """The installed transport, one per process (the launch's messages and this process's ends of
    connections share its DDS participant); a :class:`MissingPackageError` when there is none."""
    found = list(entry_points(group=GROUP))
    if not found:
        raise MissingPackageError("the application runs on several hosts (<host>), whose connections go over DDS: "
                                  "install the coco_ros package, which provides it (its entry point "
                                  f"{GROUP})")
    transport: HostTransport = found[0].load()()
    return transport
