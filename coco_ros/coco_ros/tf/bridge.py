"""``TFBridge``: the application's transformation graph <-> /tf and /tf_static, so that RViz and
every tf2 tool see the graph, and frames broadcast by ROS nodes join it.

Attributes::

    <attribute name="publish" value="base:left_gripper, base:head"/>  <!-- lookups to /tf -->
    <attribute name="root" value="base"/>        <!-- every moving edge reachable from base to /tf -->
    <attribute name="static" value="true"/>      <!-- static edges to /tf_static (default) -->
    <attribute name="ingest" value="true"/>      <!-- /tf and /tf_static into the graph (default) -->
    <attribute name="prefix" value="robot2/"/>   <!-- added to the names of ingested frames -->

Broadcasting (:mod:`.selection`) happens in ``on_update``, at the rate of the bridge's activity
(make it periodic: its period is the /tf rate), and only for what changed; /tf_static gets all
static transforms in one latched message, re-sent when one is added or changes. Ingesting
(:mod:`.ingest`) happens in the subscription callbacks, in the activity's callback group. The bridge
never ingests a frame it broadcasts (the echo rule), so its own messages do not come back.

QoS as tf2's broadcasters and listeners: /tf reliable, volatile, depth 100; /tf_static published
reliable, transient local, depth 1 (a late subscriber gets the whole set) and subscribed transient
local with depth 100 (one latched message per static broadcaster).

Frames named in ``publish`` and ``root`` must be in the graph when the bridge starts (a URDF loaded
by a TransformationInterface, declared edges): an unknown one disables the bridge with an error
listing the known frames. Needs the ROS launcher, like ROSInterface.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import CocoError
from coco_core.operations import operation
from coco_core.transforms.graph import TransformError
from coco_core.transforms.samples import TransformSample

from ..bag.qos import TF_STATIC, Qos
from ..convert import converter_for
from ..convert.geometry import transform_sample
from ..convert.stamps import RosTime
from ..interface.component import launcher_node
from .ingest import TFIngest
from .selection import TFSelection, check_pairs, parse_pair

log = logging.getLogger("coco.tf")

TF_QOS = Qos(depth=100)
"""/tf, both ways: tf2's TransformBroadcaster and TransformListener (reliable, volatile, 100)."""
TF_STATIC_LISTENER_QOS = Qos(depth=100, durability="transient_local")
"""/tf_static subscription: tf2's static listener keeps up to 100 latched messages (one per broadcaster)."""
_SHOWN = 12
"""Broadcast transforms named in the start-up log line (a URDF robot has dozens)."""


class TFBridge(Component):
    """Broadcasts graph frames on /tf and /tf_static and ingests ROS frames into the graph."""

    publish: Attribute[list[str]] = Attribute(list[str], [], "graph lookups broadcast on /tf, each 'parent:child' (T_parent_child)",
                        check=check_pairs)
    root = Attribute(str, "", "broadcast every dynamic, axis and moving URDF edge reachable from this frame on "
                     "/tf (and only the static edges reachable from it on /tf_static); empty: none")
    static = Attribute(bool, True, "broadcast the graph's static edges and fixed URDF joints on /tf_static")
    ingest = Attribute(bool, True, "write the transforms received on /tf and /tf_static into the graph")
    prefix = Attribute(str, "", "prefix added to the names of the frames ingested from ROS")
    tf_topic = Attribute(str, "/tf", "topic of moving transforms")
    tf_static_topic = Attribute(str, "/tf_static", "topic of static transforms")

    def init(self) -> None:
        self._converter = converter_for("tf2_msgs/msg/TFMessage")
        self._selection = TFSelection(self.transform_graph, [parse_pair(text) for text in self.publish],
                                      self.root.strip(), self.static, clock=self._now)
        self._ingest = TFIngest(self.transform_graph, self.prefix, owner=f"TFBridge {self.name}",
                                broadcast=lambda: self._selection.children)
        self._selection.ingested = self._ingest.ingested
        self._node: Any = None
        self._entities: list[tuple[str, Any]] = []
        self._tf: Any = None
        self._tf_static: Any = None
        self._published = {"tf": 0, "tf_static": 0}
        self._malformed = 0

    def _now(self) -> float:
        """The node's ROS time (simulated time under use_sim_time), exact to the nanosecond."""
        nanoseconds = self._node.get_clock().now().nanoseconds
        return RosTime(nanoseconds // 1_000_000_000, nanoseconds % 1_000_000_000)

    def on_config(self) -> None:
        try:
            self._selection.check()
        except TransformError as error:
            raise CocoError(f"TFBridge {self.name}: {error}") from None
        node, group = launcher_node(self)
        self._node = node
        message = self._converter.message_type
        self._tf = node.create_publisher(message, self.tf_topic, TF_QOS.to_rclpy(), callback_group=group)
        self._tf_static = node.create_publisher(message, self.tf_static_topic, TF_STATIC.to_rclpy(),
                                                callback_group=group)
        self._entities = [("publisher", self._tf), ("publisher", self._tf_static)]
        if self.ingest:
            for topic, qos, write in ((self.tf_topic, TF_QOS, self._ingest.dynamic),
                                      (self.tf_static_topic, TF_STATIC_LISTENER_QOS, self._ingest.static)):
                subscription = node.create_subscription(message, topic, self._receiver(write), qos.to_rclpy(),
                                                        callback_group=group)
                self._entities.append(("subscription", subscription))
        broadcast = self._selection.broadcast
        shown = ", ".join(broadcast[:_SHOWN]) + (f" ... ({len(broadcast)} in all)" if len(broadcast) > _SHOWN else "")
        log.info("TFBridge %s: broadcasting %s; %s", self.name, shown or "nothing yet",
                 f"ingesting {self.tf_topic} and {self.tf_static_topic}"
                 + (f" with prefix {self.prefix!r}" if self.prefix else "") if self.ingest else "not ingesting")

    def _receiver(self, write: Callable[[list[TransformSample]], None]) -> Callable[[Any], None]:
        def receive(msg: Any) -> None:
            samples = []
            for transform in msg.transforms:
                try:
                    samples.append(transform_sample(transform))
                except ValueError as error:  # a zero quaternion: drop that transform, keep the others
                    self._malformed += 1
                    if self._malformed == 1:
                        log.error("TFBridge %s: dropping a transform %s -> %s that is not a rigid transform: "
                                  "%s (further ones are counted, not logged)", self.name,
                                  transform.header.frame_id, transform.child_frame_id, error)
            write(samples)

        return receive

    def on_update(self) -> None:
        if self._tf is None:
            return
        moving = self._selection.moving()
        if moving:
            self._tf.publish(self._converter.to_ros(moving))
            self._published["tf"] += len(moving)
        static = self._selection.static()
        if static is not None:
            self._tf_static.publish(self._converter.to_ros(static))
            self._published["tf_static"] += 1

    def on_stop(self) -> None:
        node, self._node = self._node, None
        if node is None:
            return
        counts = self.counts()
        log.info("TFBridge %s: received %d transforms (ingested %d, echoes %d, rejected %d, malformed %d); "
                 "published %d transforms on %s and %d messages on %s", self.name, counts["received"],
                 counts["ingested"], counts["echoes"], counts["rejected"], counts["malformed"],
                 counts["published_tf"], self.tf_topic, counts["published_tf_static"], self.tf_static_topic)
        for kind, entity in self._entities:
            getattr(node, f"destroy_{kind}")(entity)
        self._entities = []
        self._tf = self._tf_static = None

    @operation
    def counts(self) -> dict[str, int]:
        """Transforms received, ingested, dropped as echoes, rejected by the graph and malformed (not
        rigid); transforms published on /tf and messages published on /tf_static."""
        return {**self._ingest.counts, "malformed": self._malformed, "published_tf": self._published["tf"],
                "published_tf_static": self._published["tf_static"]}

    @operation
    def broadcast(self) -> list[str]:
        """``parent:child`` of every transform the bridge broadcasts (on /tf, then /tf_static)."""
        return self._selection.broadcast
