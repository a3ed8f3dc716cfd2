"""``ROSInterface``: bridges ROS topics and CoCo ports, configured in the application XML.

Attributes (lists of topic specs, syntax in :mod:`coco_ros.interface.topic`)::

    <attribute name="subscribe" value="joints=/joint_states:sensor_msgs/msg/JointState;depth=50"/>
    <attribute name="publish" value="pose=/tool_pose:geometry_msgs/msg/PoseStamped;reliability=best_effort"/>

- ``subscribe``: each spec gives an **output** port: every message received on the topic is
  converted and written to it, from the subscription callback, which runs in the component's
  activity's callback group (never during the activity's own cycle). When the
  executor hosts that activity and it is triggered, the cycle the message woke runs right after, in
  the same callback (:func:`coco_ros.hosting.activity_callback`): components scheduled after the
  bridge in that activity see the message without another executor hop. The subscription takes the
  message's CDR bytes (``raw``) and the converter reads them (``converter.from_cdr``): directly for
  the converters that know their type's layout (a JointState's positions become an array without a
  list of floats), through the generated decoders of :mod:`coco_ros.bag.cdr_decoder` for the others,
  which build the rclpy message 3-8x faster than rclpy does when it takes a message.
- ``publish``: each spec gives an **event input** port: the values written to it are converted
  and published in ``on_update``, all of them, in order: as CDR bytes when the converter packs them
  itself (``writes_cdr``: PoseStamped, Float64), else as the message ``converter.to_ros`` builds.
  Put the component in a triggered activity to publish as soon as values arrive (or in a periodic
  one to publish at its rate).
  A ``Stamped(value, stamp)`` is accepted on every publish port (its type is the converter's
  ``coco_type`` or ``Stamped``): the converter gets ``value``, and once the message is published the
  component records the stamp's age (``record_latency``), so ``--profile`` shows the latency from
  the stamp's origin to the message handed to DDS. A plain value is measured from its message stamp
  (its write on the port that fed this one, in this process or another: :attr:`InputPort.origin
  <coco_core.ports.InputPort.origin>`). A :class:`~coco_ros.bag.BagMessage` of the port's
  type (a ``BagReplay`` with ``output=bag``) is published as its recorded CDR bytes, nothing decoded
  or converted: replaying a bag onto DDS through an application then costs what ``coco-replay`` does.

Port types are the converters' ``coco_type`` (``JointSample``, ``Image``, ``FramePose``...); publish
ports take ``Stamped`` values too.
A message or value that cannot be converted is counted (``errors()`` operation, per port) and logged
(the first three in full, then at most once per second per port), naming the topic and the type; the
bridge goes on.

The component needs the ROS launcher (``ros2 run coco_ros launcher app.xml``): under ``coco-launch``
there is no node, so ``on_config`` fails with an error saying so, and the component is disabled.
"""

from __future__ import annotations

import logging
import time
from typing import Any, Union

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import CocoError, WrongTypeError
from coco_core.operations import operation
from coco_core.stamps import Stamped, unstamped

from ..bag import BagMessage
from ..bag.message_types import normalize_type
from ..convert.base import Converter
from .topic import SYNTAX, TopicSpec, check_specs, parse_specs

log = logging.getLogger("coco.ros_interface")

_FULL_ERRORS = 3
"""Conversion errors logged in full per port before switching to one line per second."""


def launcher_node(component: Component) -> tuple[Any, Any]:
    """The launcher's rclpy node and the callback group of ``component``'s activity, where the ROS
    entities of a bridge belong (so that their callbacks never overlap the activity's cycle).

    Under ``coco-launch`` there is no node: the error says which launcher to use instead.
    """
    from ..hosting import callback_group, ros_node

    try:
        node = ros_node(component)
    except CocoError as error:
        raise CocoError(f"{type(component).__name__} {component.name} needs the ROS launcher to reach ROS "
                        f"(install/coco_ros/lib/coco_ros/launcher app.xml or ros2 run coco_ros launcher "
                        f"app.xml): {error}") from None
    return node, callback_group(component)


class _Route:
    """One bridged topic: its spec, converter, port, ROS entity and counters."""

    def __init__(self, spec: TopicSpec, converter: Converter, port: Any) -> None:
        self.spec = spec
        self.converter = converter
        self.port = port
        self.entity: Any = None
        self.encode = converter.to_cdr if converter.writes_cdr else converter.to_ros
        """What a published value becomes: the message's CDR bytes when the converter packs them
        itself (no rclpy message built), else the rclpy message."""
        self.count = 0
        self.errors = 0
        self.last_log = 0.0

    def failed(self, owner: str, direction: str, error: Exception) -> None:
        self.errors += 1
        now = time.monotonic()
        if self.errors <= _FULL_ERRORS:
            log.error("ROSInterface %s: cannot convert %s %s (%s) on port %s: %s (error %d)", owner, direction,
                      self.spec.topic, self.spec.type_name, self.spec.port, error, self.errors)
            self.last_log = now
        elif now - self.last_log >= 1.0:
            log.error("ROSInterface %s: %d conversion errors so far on %s (%s), last: %s", owner, self.errors,
                      self.spec.topic, self.spec.type_name, error)
            self.last_log = now


class ROSInterface(Component):
    """Subscribes ROS topics into output ports and publishes input ports to ROS topics."""

    dynamic_ports = ("one output per subscribe spec, one event input per publish spec, named by the spec, of the "
                     "converter's CoCo type: JointState -> JointSample, Image -> Image, CameraInfo -> CameraIntrinsics, "
                     "PoseStamped -> FramePose, TransformStamped -> TransformSample, PointCloud2 -> PointCloud, "
                     "Float64 -> float, *MultiArray -> numpy array, TFMessage -> list of TransformSample")

    subscribe: Attribute[list[str]] = Attribute(list[str], [], f"topics received into output ports: {SYNTAX}", check=check_specs)
    publish: Attribute[list[str]] = Attribute(list[str], [], f"input (event) ports published to topics: {SYNTAX}", check=check_specs)

    def init(self) -> None:
        subscribed, published = parse_specs(self.subscribe), parse_specs(self.publish)
        both = sorted({s.port for s in subscribed} & {s.port for s in published})
        if both:
            raise CocoError(f"ROSInterface {self.name}: port(s) {', '.join(both)} named in both subscribe "
                            "and publish; every port needs its own name")
        self._subscriptions: list[_Route] = []
        self._publications: list[_Route] = []
        for spec in subscribed:
            converter = spec.converter()
            output = self.add_output(spec.port, converter.coco_type, doc=f"from {spec.topic} ({spec.type_name})")
            self._subscriptions.append(_Route(spec, converter, output))
        for spec in published:
            converter = spec.converter()
            accepted = converter.coco_type if isinstance(converter.coco_type, tuple) else (converter.coco_type,)
            port = self.add_input(spec.port, Union[(*accepted, Stamped, BagMessage)], event=True,
                                  doc=f"published to {spec.topic} ({spec.type_name})")
            self._publications.append(_Route(spec, converter, port))
        self._node: Any = None

    def on_config(self) -> None:
        from ..hosting import activity_callback

        node, group = launcher_node(self)
        self._node = node
        for route in self._subscriptions:
            spec = route.spec
            route.entity = node.create_subscription(route.converter.message_type, spec.topic,
                                                    activity_callback(self, self._receiver(route)),
                                                    spec.qos_profile(), callback_group=group, raw=True,
                                                    qos_overriding_options=self._qos_overrides(node, spec.topic,
                                                                                               "subscription"))
        for route in self._publications:
            spec = route.spec
            route.entity = node.create_publisher(route.converter.message_type, spec.topic, spec.qos_profile(),
                                                 callback_group=group,
                                                 qos_overriding_options=self._qos_overrides(node, spec.topic,
                                                                                            "publisher"))
        log.info("ROSInterface %s: subscribed %s; publishing %s", self.name,
                 ", ".join(r.spec.describe() for r in self._subscriptions) or "nothing",
                 ", ".join(r.spec.describe() for r in self._publications) or "nothing")

    def _qos_overrides(self, node: Any, topic: str, kind: str) -> Any:
        """rclpy's QoS overrides for one entity: ``-p qos_overrides./topic.publisher.reliability:=...``
        (and ``.history``, ``.depth``: rclpy's default policies) replace what the XML's
        ``;reliability=`` gave, as for any rclpy node. A topic that another entity of this kind in the
        same node has already takes this component's name as its entity id
        (``qos_overrides./topic.publisher_NAME.depth``): one parameter cannot configure two entities."""
        from rclpy.qos_overriding_options import QoSOverridingOptions

        resolved = node.resolve_topic_name(topic)
        entities = node.publishers if kind == "publisher" else node.subscriptions
        taken = any(entity.topic_name == resolved for entity in entities)
        return QoSOverridingOptions.with_default_policies(entity_id=self.name if taken else None)

    def _receiver(self, route: _Route):
        converter, port = route.converter, route.port

        def receive(data: bytes) -> None:
            try:
                value = converter.from_cdr(data)
            except Exception as error:  # a malformed message must not stop the bridge
                route.failed(self.name, "a message from", error)
                return
            route.count += 1
            port.write(value)

        return receive

    def on_update(self) -> None:
        for route in self._publications:
            entity = route.entity
            for value, stamp in route.port.read_all_origins():
                value = unstamped(value)[0]
                try:
                    msg = self._passed_through(route, value) if isinstance(value, BagMessage) else \
                        route.encode(value)
                except Exception as error:
                    route.failed(self.name, "a value for", error)
                    continue
                if entity is not None:
                    entity.publish(msg)
                    route.count += 1
                    if stamp is not None:
                        self.record_latency(stamp)

    @staticmethod
    def _passed_through(route: _Route, message: BagMessage) -> bytes:
        """The CDR bytes of a recorded message, published as they are (rclpy publishes bytes raw)."""
        if normalize_type(message.type) != normalize_type(route.spec.type_name):
            raise WrongTypeError(f"a recorded {message.type} message from {message.topic} cannot go to "
                                 f"{route.spec.topic}, which publishes {route.spec.type_name}")
        return message.data

    def on_stop(self) -> None:
        node, self._node = self._node, None
        if node is None:
            return
        for route in self._subscriptions:
            if route.entity is not None:
                node.destroy_subscription(route.entity)
                route.entity = None
        for route in self._publications:
            if route.entity is not None:
                node.destroy_publisher(route.entity)
                route.entity = None

    @operation
    def counts(self) -> dict[str, int]:
        """Messages received (subscribe ports) or published (publish ports) so far, by port."""
        return {route.spec.port: route.count for route in self._subscriptions + self._publications}

    @operation
    def errors(self) -> dict[str, int]:
        """Conversion errors so far, by port."""
        return {route.spec.port: route.errors for route in self._subscriptions + self._publications}
