"""The TFBridge component: its errors (unknown frames, no ROS launcher, bad attributes) and, in one
process over real DDS (domain 62), a node's /tf entering the graph with malformed transforms dropped
one by one, and the graph's static set reaching a late /tf_static subscriber."""

from __future__ import annotations

import logging
import time

import numpy as np
import pytest
from coco_core import Application, AttributeValueError, PeriodicActivity
from coco_core.deployment import of_application
from coco_ros.deployment import RosRules
from coco_core.transforms import se3
from coco_core.transforms.edges import DynamicEdge
from coco_ros.tf.bridge import TFBridge

DOMAIN = "62"


def app_with_graph() -> Application:
    app = Application("tf_units")
    app.transforms.add_static("world", "table", se3.make(None, (1.0, 2.0, 0.5)))
    app.transforms.add_dynamic("table", "cup")
    return app


def test_unknown_frames_disable_the_bridge_naming_the_known_ones(caplog: pytest.LogCaptureFixture) -> None:
    app = app_with_graph()
    bridge = app.add(TFBridge("tf", publish="world:cup, wrold:table"), PeriodicActivity("broadcast", period=0.02))
    with caplog.at_level(logging.ERROR, logger="coco"):
        assert bridge.configure() is False
    assert not bridge.enabled
    assert "TFBridge tf: unknown frame(s) 'wrold' in the transformation graph; did you mean 'world'? " \
           "valid: cup, table, world" in caplog.text


def test_without_the_ros_launcher_the_error_says_which_launcher(caplog: pytest.LogCaptureFixture) -> None:
    app = app_with_graph()
    bridge = app.add(TFBridge("tf", root="world"), PeriodicActivity("broadcast", period=0.02))
    with caplog.at_level(logging.ERROR, logger="coco"):
        assert bridge.configure() is False
    assert "TFBridge tf needs the ROS launcher" in caplog.text and "ros2 run coco_ros launcher" in caplog.text


def test_a_malformed_pair_names_the_component_and_the_syntax() -> None:
    with pytest.raises(AttributeValueError, match=r"tf\.publish .*'base' must look like parent:child"):
        TFBridge("tf", publish="base")


@pytest.fixture
def ros(monkeypatch: pytest.MonkeyPatch):
    """Two rclpy nodes on their own contexts: the launcher's (hosting the application) and a peer's."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    monkeypatch.setenv("ROS_DOMAIN_ID", DOMAIN)
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    contexts, nodes = [], []
    for name in ("tf_units_launcher", "tf_units_peer"):
        context = Context()
        rclpy.init(context=context)
        contexts.append(context)
        nodes.append(rclpy.create_node(name, context=context))
    executors = [SingleThreadedExecutor(context=context) for context in contexts]
    for executor, node in zip(executors, nodes):
        executor.add_node(node)
    yield nodes, executors
    for executor, node, context in zip(executors, nodes, contexts):
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
        context.destroy()


def test_in_one_process_tf_in_and_tf_static_out(ros) -> None:
    from coco_ros.hosting import ExecutorHost
    from geometry_msgs.msg import TransformStamped
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from tf2_msgs.msg import TFMessage

    (launcher_node, peer), executors = ros
    app = app_with_graph()
    bridge = app.add(TFBridge("tf", root="world"), PeriodicActivity("broadcast", period=0.02))
    # The test spins the executor that runs its callbacks: no wait set of its own.
    host = ExecutorHost(launcher_node, app, of_application(app, RosRules(wait_sets=False)))
    try:
        assert bridge.configure()
        bridge.step()  # the first update: the static set goes out (latched)

        def spin(done, timeout: float = 10.0) -> bool:
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline and not done():
                for executor in executors:
                    executor.spin_once(timeout_sec=0.02)
                bridge.step()
            return done()

        static: list = []
        peer.create_subscription(TFMessage, "/tf_static", static.append,
                                 QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        assert spin(lambda: bool(static)), "the late subscriber got no /tf_static"
        assert [(t.header.frame_id, t.child_frame_id) for t in static[0].transforms] == [("world", "table")]
        assert static[0].transforms[0].transform.translation.y == 2.0

        good, zero = TransformStamped(), TransformStamped()
        good.header.frame_id, good.child_frame_id = "table", "fork"
        good.header.stamp.sec = 42
        good.transform.translation.x, good.transform.rotation.w = 0.3, 1.0
        zero.header.frame_id, zero.child_frame_id = "table", "knife"
        zero.transform.rotation.w = 0.0  # a zero quaternion: not a rotation
        publisher = peer.create_publisher(TFMessage, "/tf", QoSProfile(depth=100))
        received = lambda: bridge.counts()["ingested"] >= 1  # noqa: E731
        assert spin(lambda: (publisher.publish(TFMessage(transforms=[zero, good])), received())[1])
        edge = app.transforms.edge("table", "fork")
        assert isinstance(edge, DynamicEdge) and edge.time_range[1] == 42.0
        np.testing.assert_allclose(app.transforms.lookup("world", "fork"), se3.make(None, (1.3, 2.0, 0.5)))
        counts = bridge.counts()
        assert counts["malformed"] >= 1 and counts["rejected"] == 0 and "knife" not in app.transforms.frames
        assert counts["published_tf_static"] == 1
    finally:
        bridge.stop()
        host.close()
