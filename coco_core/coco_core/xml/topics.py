"""``<topics>``: output ports mirrored on ROS topics by the ROS launcher.

::

    <topics if="$(arg ros_topics)">
        <topic task="distance" port="distance"/>                       <!-- ~/distance/distance -->
        <topic task="distance" port="color" name="/bowl_color" type="std_msgs/msg/ColorRGBA"/>
        <topic task="tf" port="gripper" data="BUFFER" buffersize="100"/>
        <topic task="renderer" port="proxy_force" type="geometry_msgs/msg/WrenchStamped" frame="camera" hz="30"/>
    </topics>

Each ``<topic>`` is a connection from the output port to a ROS publisher (``coco_ros.mirror``): its
``data`` / ``buffersize`` are the connection's policy, which the topic's QoS follows. Component
and port names are checked where the ports are known (the ROS launcher, ``--check`` included);
``coco-launch`` reads the element and publishes nothing.
"""

from __future__ import annotations

from ..model import TopicMirrorSpec
from ..policy import BufferPolicy
from .connections import BUFFER_POLICIES, buffer_size
from .draft import Draft
from .reader import CONDITIONS, FileReader
from .tree import Element
from .values import parse_number

TOPIC_ATTRIBUTES = ("buffersize", "data", "frame", "hz", "name", "port", "task", "type", *CONDITIONS)


def read_topics(reader: FileReader, element: Element, draft: Draft) -> None:
    """Append the kept ``<topic>`` children of ``element`` to ``draft.topics``."""
    reader.check_attributes(element, CONDITIONS)
    for child in reader.children(element, ("topic",)):
        if not reader.kept(child):
            continue
        values = reader.attributes(child, TOPIC_ATTRIBUTES, required=("task", "port"))
        reader.empty(child)
        data = BufferPolicy(reader.choice(child, values, "data", BUFFER_POLICIES, "DATA"))
        size = buffer_size(reader, child, values, data)
        hz = reader.parsed(child, values, "hz", parse_number) or 0.0
        if hz < 0:
            reader.error(f'<topic> attribute hz="{values["hz"]}": expected a rate >= 0 (0: every value)', child)
        component, port = values.get("task", "").strip(), values.get("port", "").strip()
        if component and port:
            draft.topics.append(TopicMirrorSpec(component, port, values.get("name", "").strip(),
                                                values.get("type", "").strip(), data, size, child.location,
                                                values.get("frame", "").strip(), max(hz, 0.0)))
