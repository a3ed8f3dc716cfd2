"""``RobotDescription``: the application's URDF on ``/robot_description``, as robot_state_publisher
offers it, so that RViz's RobotModel and Foxglove's 3D panel draw the robot the graph moves.

Attributes::

    <attribute name="urdf" value="package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"/>
    <attribute name="topic" value="robot_description"/>    <!-- the default, relative to the namespace -->

The file (a path, a ``package://`` or ``file://`` URL, as a TransformationInterface reads it) is
read and published once, when the component configures, as a ``std_msgs/String``: reliable,
transient local, depth 1, so a viewer that starts later still gets it. Its frames move on /tf from
the graph through a TFBridge. Needs the ROS launcher, like the TFBridge: an application keeps both
to ``if="$(arg ros_launcher)"``.
"""

from __future__ import annotations

import logging
from typing import Any

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import CocoError, ResourceNotFoundError, UrdfError
from coco_core.files import URDF_LIMIT, FileReadError, read_regular_file
from coco_core.transforms.resources import resolve

from ..bag.qos import Qos
from ..interface.component import launcher_node

log = logging.getLogger("coco.tf")

DESCRIPTION_QOS = Qos(depth=1, durability="transient_local")
"""What robot_state_publisher offers on /robot_description: the newest one, latched."""


def urdf_text(source: str) -> str:
    """The text of the URDF ``source`` names (a path or URL), or an error naming it."""
    try:
        return read_regular_file(resolve(source), URDF_LIMIT, "URDF").decode("utf-8")
    except (FileReadError, ResourceNotFoundError, UnicodeDecodeError) as error:
        raise UrdfError(f"cannot read the URDF {source}: {error}") from None


class RobotDescription(Component):
    """Publishes a URDF once on /robot_description (latched)."""

    urdf = Attribute(str, "", "the URDF: a path, a package:// or file:// URL")
    topic = Attribute(str, "robot_description", "the topic (relative names follow the node's namespace)")

    def init(self) -> None:
        self._node: Any = None
        self._publisher: Any = None

    def on_config(self) -> None:
        from std_msgs.msg import String

        if not self.urdf.strip():
            raise CocoError(f"RobotDescription {self.name}: no urdf given")
        text = urdf_text(self.urdf)
        node, group = launcher_node(self)
        self._node = node
        self._publisher = node.create_publisher(String, self.topic, DESCRIPTION_QOS.to_rclpy(), callback_group=group)
        self._publisher.publish(String(data=text))
        log.info("RobotDescription %s: %s (%d characters) on %s", self.name, self.urdf, len(text),
                 self._publisher.topic_name)

    def on_stop(self) -> None:
        node, self._node = self._node, None
        if node is not None:
            node.destroy_publisher(self._publisher)
            self._publisher = None
