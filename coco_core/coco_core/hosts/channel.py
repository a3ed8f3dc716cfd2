"""A connection between two hosts, as both of its hosts need to know it.

The same application file runs on every host (``coco-launch app.xml --host NAME``); each host plans
the connections between hosts from the file alone, so that the writer's host and the reader's host
agree on the topic, the policy and the codec without asking each other. The traffic is DDS, through
rclpy (``coco_ros.hosts``): this module is the part that needs no ROS.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from ..policy import ConnectionPolicy

CODECS = ("plain", "rgbd")
"""How a payload crosses the network: ``plain`` (any value of plain data and registered value types, :mod:`coco_core.wire`; the default), ``rgbd`` (an RGB-D frame
or image through the vision stream codec: JPEG colour, Zstandard depth)."""


@dataclass(frozen=True)
class HostChannel:
    """One connection between two hosts."""

    src: str
    """``component.port`` of the writer (``activity.endit`` when :attr:`src_activity`)."""
    dest: str
    """``component.port`` of the reader (``activity.beginit`` when :attr:`dest_activity`)."""
    src_host: str
    dest_host: str
    src_process: str
    """The writer's process on its host (``""``: that host's launcher)."""
    dest_process: str
    policy: ConnectionPolicy
    """The connection's own policy: the reader's side stores what arrives with it (drop rules, sizes)."""
    event: bool | None
    """The connection's ``event`` setting (:meth:`ConnectionSpec.wakes`); None: the input port decides."""
    codec: str
    """One of :data:`CODECS`."""
    topic: str
    """The DDS topic that carries it (:func:`topic_of`)."""
    stamps_only: bool = False
    """Only the messages' stamps travel (FlowVR's dashed connections)."""
    filtered: bool = False
    """The connection has a filter: it runs on the reader's side, fed from the network."""
    src_activity: bool = False
    dest_activity: bool = False

    @property
    def label(self) -> str:
        return f"{self.src}->{self.dest}"


def ros_name(name: str) -> str:
    """``name`` as a ROS name: every character a ROS name does not allow replaced by ``_``, ``.`` by
    ``/`` (``cam1/mesher.mesh`` keeps its namespace: ``cam1/mesher/mesh``), and a token that starts
    with a digit prefixed by ``_``; every host derives the same name from the same file."""
    parts = [re.sub(r"[^A-Za-z0-9_]", "_", part) or "_" for part in name.replace(".", "/").split("/")]
    return "/".join(f"_{part}" if part[0].isdigit() else part for part in parts)


def topic_of(application: str, src: str, dest: str) -> str:
    """The topic of the connection ``src -> dest`` of ``application``: ``/coco/APP/SRC/to/DEST``."""
    return f"/coco/{ros_name(application)}/{ros_name(src)}/to/{ros_name(dest)}"
