"""ROSInterface hosted in-process by ExecutorHost, over real DDS to a peer node of the same context.

The application is the shape a latency-minded user writes: a ROSInterface and the component that
uses its data in **one** triggered activity, the bridge last. A joint state from the peer goes
subscription -> ``relay`` -> the bridge's publish port -> DDS within one executor callback, and what
the relay writes is ``Stamped``: the bridge publishes the value (std_msgs/Float64) and records the
stamp's age. Domain 80, localhost only.
"""

from __future__ import annotations

import time

import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from coco_core import Application, Component, InputPort, OutputPort, TriggeredActivity
from coco_core.stamps import Stamp, Stamped
from coco_core.transforms.samples import JointSample
from coco_ros.interface.component import ROSInterface
from test_launcher_hosting import BUFFERED, Hosting, wait_until

BRIDGE = {"subscribe": ["joints=/hosted/joints:sensor_msgs/msg/JointState;depth=50"],
          "publish": ["first=/hosted/first:std_msgs/msg/Float64;depth=50"]}


class Relay(Component):
    """The first joint position of every sample, stamped when read."""

    joints = InputPort(JointSample, event=True)
    first = OutputPort(Stamped)

    def init(self) -> None:
        self.relayed = 0

    def on_update(self) -> None:
        for sample in self.joints.read_all():
            self.first.write(Stamped(float(sample.positions[0]), Stamp.now()))
            self.relayed += 1


class Feeder(Component):
    """An output the test writes to from its own thread."""

    out = OutputPort(object)


@pytest.fixture
def rig(monkeypatch: pytest.MonkeyPatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", "80")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    hosting = Hosting()
    peer = Node("hosted_peer", context=hosting.context)
    executor = SingleThreadedExecutor(context=hosting.context)
    executor.add_node(peer)
    yield hosting, peer, executor
    executor.shutdown()
    peer.destroy_node()
    hosting.close()


def relay_app() -> tuple[Application, ROSInterface, Relay]:
    app = Application("hosted_bridge")
    activity = TriggeredActivity("pipeline")
    relay = app.add(Relay("relay"), activity)
    bridge = app.add(ROSInterface("bridge", **BRIDGE), activity)
    app.connect("bridge.joints", "relay.joints", BUFFERED)
    app.connect("relay.first", "bridge.first", BUFFERED)
    return app, bridge, relay


def test_one_activity_relays_a_message_to_dds_and_profiles_the_stamp_to_publish_latency(rig) -> None:
    hosting, peer, executor = rig
    app, bridge, relay = relay_app()
    received: list[Float64] = []
    peer.create_subscription(Float64, "/hosted/first", received.append, QoSProfile(depth=50))
    publisher = peer.create_publisher(JointState, "/hosted/joints", QoSProfile(depth=50))
    hosting.start(app)
    sent = 0
    deadline = time.monotonic() + 20
    while len(received) < 20 and time.monotonic() < deadline:
        publisher.publish(JointState(name=["a", "b"], position=[0.25 * sent, -1.0]))
        sent += 1
        executor.spin_once(timeout_sec=0.02)
    assert hosting.stop()

    assert len(received) >= 20, f"{len(received)} of {sent} relayed"
    values = [msg.data for msg in received]
    assert all(value / 0.25 == int(value / 0.25) for value in values) and values == sorted(values)
    published = bridge.call("counts").result(1)["first"]
    assert published >= len(received) and relay.relayed == published
    # Every Stamped value published recorded its age: relay's read -> handed to DDS.
    latency = bridge.stats.latency
    assert latency.count == published and 0 < latency.mean < 1.0


def publish_through_a_bridge(rig, topic: str, values: list, expected: int) -> tuple[ROSInterface, list[Float64]]:
    """Write ``values`` into a hosted ROSInterface publishing std_msgs/Float64 on ``topic`` and wait
    for ``expected`` messages at the test's subscription; the bridge and what arrived."""
    hosting, peer, executor = rig
    app = Application("hosted_values")
    feeder = app.add(Feeder("feeder"))  # in no activity: the test writes for it
    bridge = app.add(ROSInterface("bridge", publish=[f"value={topic}:std_msgs/msg/Float64"]),
                     TriggeredActivity("publishing"))
    app.connect("feeder.out", "bridge.value", BUFFERED)
    received: list[Float64] = []
    peer.create_subscription(Float64, topic, received.append, QoSProfile(depth=50))
    hosting.start(app)
    assert wait_until(lambda: peer.count_publishers(topic) == 1)
    assert wait_until(lambda: peer.count_subscribers(topic) == 1)
    time.sleep(0.2)  # discovery matched: what is written now reaches the subscription
    for value in values:
        feeder.out.write(value)
    deadline = time.monotonic() + 10
    while len(received) < expected and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    assert hosting.stop()
    return bridge, received


def test_a_plain_float_is_published_and_a_wrong_value_is_counted_not_raised(rig) -> None:
    bridge, received = publish_through_a_bridge(rig, "/hosted/value",
                                                [Stamped(1.5, Stamp.now()), "not a number", 2.5, True], 2)
    assert [msg.data for msg in received] == [1.5, 2.5]
    assert bridge.call("errors").result(1)["value"] == 2
    # Both published values are measured: the Stamped one from its own stamp, the plain one from
    # its message stamp (its write on feeder.out).
    assert bridge.stats.latency.count == 2


def test_a_recorded_message_is_published_as_its_bytes_and_a_wrong_type_is_counted(rig) -> None:
    """A BagMessage (BagReplay output=bag) goes to DDS as its recorded CDR, undecoded; one of another
    type than the publication's is refused and counted."""
    from rclpy.serialization import serialize_message

    from coco_ros.bag import BagMessage

    def recorded(type_name: str, message) -> BagMessage:
        def undecodable(_: bytes):
            raise AssertionError("a passed-through message must not be decoded")

        return BagMessage("/recorded", type_name, 0, 0, serialize_message(message), undecodable)

    bridge, received = publish_through_a_bridge(rig, "/hosted/bytes", [
        recorded("std_msgs/msg/Float64", Float64(data=4.25)),
        recorded("sensor_msgs/msg/JointState", JointState(name=["a"], position=[1.0])),
        recorded("std_msgs/Float64", Float64(data=-2.0))], 2)
    assert [msg.data for msg in received] == [4.25, -2.0]
    assert bridge.call("errors").result(1)["value"] == 1
