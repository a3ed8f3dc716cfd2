"""ROSHapticDevice: a haptic device whose driver is a ROS node, with the ports of SimulatedDevice.

A real device's ROS driver publishes the handle's pose (``geometry_msgs/PoseStamped``), optionally
its twist (``geometry_msgs/TwistStamped``) and buttons (``sensor_msgs/Joy``), and applies the
``geometry_msgs/WrenchStamped`` it receives. This component turns them into
:class:`~coco_mr_haptics.types.HapticDeviceState` on ``state`` and publishes every
:class:`~coco_mr_haptics.types.HapticForce` that arrives on ``force``, so a HapticRenderer renders
for the real device exactly as for the simulated one.

Threads: the subscriptions belong to the callback group of this component's activity (the ROS
launcher's rule), so a callback never runs during a cycle; each cycle sends the newest pose. Without
a twist topic the velocity is the difference of the last two poses over their header stamps.

Attributes::

    <attribute name="pose_topic" value="/haptic/pose"/>
    <attribute name="twist_topic" value=""/>          <!-- "" : velocity from successive poses -->
    <attribute name="buttons_topic" value="/haptic/buttons"/>
    <attribute name="wrench_topic" value="/haptic/wrench"/>
    <attribute name="wrench_frame" value="haptic_workspace"/>
"""

from __future__ import annotations

import logging
import time
from typing import Any

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.policy import NO_DATA
from coco_core.ports import InputPort, OutputPort
from coco_mr_haptics.types import HapticDeviceState, HapticForce

from ..bag.qos import Qos
from ..convert.stamps import seconds_to_time
from ..interface.component import launcher_node

log = logging.getLogger("coco.haptics")

DEVICE_QOS = Qos(depth=1, reliability="best_effort")
"""Pose, twist and wrench: only the newest matters at a haptic rate (sensor-data QoS)."""
BUTTONS_QOS = Qos(depth=10)
"""Buttons: reliable, a press is an event not to lose."""


class ROSHapticDevice(Component):
    """A haptic device driven by its ROS node: pose/twist/buttons in, WrenchStamped out."""

    pose_topic = Attribute(str, "/haptic/pose", "geometry_msgs/PoseStamped of the handle (workspace frame)")
    twist_topic = Attribute(str, "", "geometry_msgs/TwistStamped of the handle; \"\": from successive poses")
    buttons_topic = Attribute(str, "", "sensor_msgs/Joy with the buttons; \"\": none")
    wrench_topic = Attribute(str, "/haptic/wrench", "geometry_msgs/WrenchStamped sent to the device")
    wrench_frame = Attribute(str, "", "frame_id of the wrench; \"\": the pose's frame_id")

    force = InputPort(HapticForce, doc="the force to render (workspace frame)")
    state = OutputPort(HapticDeviceState, doc="the handle: position, velocity, buttons")

    def on_config(self) -> None:
        from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped

        node, group = launcher_node(self)
        self._pose: Any = None
        self._previous: tuple[float, tuple[float, float, float]] | None = None
        self._velocity = (0.0, 0.0, 0.0)
        self._twist: tuple[float, float, float] | None = None
        self._buttons = 0
        self._frame = self.wrench_frame
        self.poses = self.wrenches = 0
        self._message = WrenchStamped
        self._entities = [node.create_subscription(PoseStamped, self.pose_topic, self._on_pose,
                                                   DEVICE_QOS.to_rclpy(), callback_group=group)]
        if self.twist_topic:
            self._entities.append(node.create_subscription(TwistStamped, self.twist_topic, self._on_twist,
                                                           DEVICE_QOS.to_rclpy(), callback_group=group))
        if self.buttons_topic:
            from sensor_msgs.msg import Joy

            self._entities.append(node.create_subscription(Joy, self.buttons_topic, self._on_buttons,
                                                           BUTTONS_QOS.to_rclpy(), callback_group=group))
        self._publisher = node.create_publisher(WrenchStamped, self.wrench_topic, DEVICE_QOS.to_rclpy(),
                                                callback_group=group)
        self._node = node
        log.info("ROSHapticDevice %s: pose %s%s%s, wrench %s", self.name, self.pose_topic,
                 f", twist {self.twist_topic}" if self.twist_topic else "",
                 f", buttons {self.buttons_topic}" if self.buttons_topic else "", self.wrench_topic)

    def _on_pose(self, message: Any) -> None:
        self._pose = message
        self.poses += 1

    def _on_twist(self, message: Any) -> None:
        linear = message.twist.linear
        self._twist = (linear.x, linear.y, linear.z)

    def _on_buttons(self, message: Any) -> None:
        self._buttons = sum(1 << i for i, pressed in enumerate(message.buttons) if pressed)

    def on_update(self) -> None:
        pose, self._pose = self._pose, None
        if pose is not None:
            p = pose.pose.position
            position = (p.x, p.y, p.z)
            stamp = pose.header.stamp.sec + pose.header.stamp.nanosec * 1e-9
            previous = self._previous
            if previous is not None and stamp > previous[0]:
                dt = stamp - previous[0]
                x0, y0, z0 = previous[1]
                self._velocity = ((p.x - x0) / dt, (p.y - y0) / dt, (p.z - z0) / dt)
            self._previous = (stamp, position)
            if not self._frame:
                self._frame = pose.header.frame_id
            velocity = self._twist if self._twist is not None else self._velocity
            self.state.write(HapticDeviceState(position, velocity, self._buttons, time.perf_counter()))
        status, value = self.force.read()
        if status is NO_DATA:
            return
        fx, fy, fz = value.force
        message = self._message()
        message.header.stamp = seconds_to_time(time.time())
        message.header.frame_id = self._frame
        message.wrench.force.x, message.wrench.force.y, message.wrench.force.z = fx, fy, fz
        self._publisher.publish(message)
        self.wrenches += 1

    def on_stop(self) -> None:
        for entity in self._entities:
            self._node.destroy_subscription(entity)
        self._node.destroy_publisher(self._publisher)
        log.info("ROSHapticDevice %s: %d poses received, %d wrenches sent", self.name, self.poses, self.wrenches)
