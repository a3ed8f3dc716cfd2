"""Output ports mirrored on ROS topics (coco_ros.mirror): ``<topics>`` and ``--expose``.

In-process, with real rclpy nodes on this test's own DDS domain: the application is built from its
XML and its port written by the test, the mirror served by an executor, the other side a real
subscription. A BUFFER mirror delivers every value in order; nothing is pushed into the mirror
while no one subscribes; ``--check`` names the ports no converter knows.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator

import pytest
from coco_core.builder import build_application
from coco_core.errors import ConfigErrors
from coco_core.xml import load_application
from coco_ros import launcher
from coco_ros.mirror import PortMirrors, plan_mirrors

from conftest import spinning_peer, wait_for

DOMAIN = "81"
APP = """<package name="mirror_app">
  <components>
    <component><name>producer</name><task>CostlyProducer</task><library>coco_core</library></component>
    <component><name>gen</name><task>SignalGenerator</task><library>coco_core</library></component>
    <component><name>tree</name><task>KDTreeBuilder</task><library>coco_mr_haptics</library></component>
    <component><name>consumer</name><task>CostlyConsumer</task><library>coco_core</library></component>
  </components>
  <connections>
    <connection data="BUFFER" buffersize="200">
      <src task="producer" port="out"/><dest task="consumer" port="item"/></connection>
  </connections>
  <topics>
    <topic task="gen" port="sample" name="/mirror_test/sample"/>
  </topics>
  <activities>
    <activity name="a"><schedule type="periodic" period="10"/>
      <components><component name="producer"/><component name="gen"/><component name="tree"/>
        <component name="consumer"/></components>
    </activity>
  </activities>
</package>
"""


@pytest.fixture
def app_file(tmp_path: Path) -> Path:
    path = tmp_path / "mirror_app.xml"
    path.write_text(APP)
    return path


@pytest.fixture
def ros(monkeypatch: pytest.MonkeyPatch) -> Iterator[Any]:
    """An rclpy node (the launcher's stand-in, and the subscriber) spinning on this test's domain."""
    yield from spinning_peer(monkeypatch, DOMAIN, "mirror_app")


def built(app_file: Path) -> tuple[Any, Any]:
    spec = load_application(str(app_file), {})
    return spec, build_application(spec)


def test_expose_of_a_buffered_port_publishes_every_value_in_order_and_only_to_subscribers(app_file: Path,
                                                                                          ros) -> None:
    """``--expose producer.out``: the port's BUFFER connection gives its mirror a BUFFER of its own."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64

    node = ros
    spec, app = built(app_file)
    port = app.component("producer").outputs["out"]
    with PortMirrors(node, app, spec, ["producer.out"]) as mirrors:
        mirror = next(m for m in mirrors.mirrors if m.port is port)
        assert mirror.topic == "/mirror_app/producer/out" and str(mirror.connection.policy) == "BUFFER/LOCKED[200]"
        for value in range(5):  # no subscriber: the port writes as if the mirror were not there
            port.write(value)
        assert mirror.connection.written == 0
        received: list[float] = []
        subscription = node.create_subscription(
            Float64, mirror.topic, lambda msg: received.append(msg.data),
            QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE))
        wait_for(lambda: mirror.subscribers == 1, "the mirror to match the subscription")
        for value in range(100):
            port.write(value)
        wait_for(lambda: len(received) >= 100, "100 mirrored values")
        assert received == [float(v) for v in range(100)]
        assert mirror.connection.counters() == {"written": 100, "read": 100, "dropped": 0, "pending": 0}
        assert any(c.label == "producer.out -> ROS topic /mirror_app/producer/out" for c in app.connections)
        node.destroy_subscription(subscription)
        wait_for(lambda: mirror.subscribers == 0, "the mirror to see the subscriber go")
        port.write(1000)
        assert mirror.connection.written == 100


def test_a_stamped_port_is_mirrored_once_its_first_value_shows_the_type(app_file: Path, ros) -> None:
    from coco_core.stamps import Stamped
    from std_msgs.msg import Float64

    node = ros
    spec, app = built(app_file)
    port = app.component("gen").outputs["sample"]
    with PortMirrors(node, app, spec) as mirrors:
        mirror = next(m for m in mirrors.mirrors if m.port is port)
        assert mirror.publisher is None  # Stamped: no type before a value
        port.write(Stamped(0.25))
        wait_for(lambda: mirror.publisher is not None, "the publisher of the first value's type")
        received: list[float] = []
        node.create_subscription(Float64, "/mirror_test/sample", lambda msg: received.append(msg.data), 10)
        wait_for(lambda: mirror.subscribers == 1, "the mirror to match the subscription")
        port.write(Stamped(0.5))
        wait_for(lambda: received, "the mirrored sample")
        assert received == [0.5]


def test_expose_patterns_choose_ports_and_name_what_cannot_be_mirrored(app_file: Path) -> None:
    spec, app = built(app_file)
    plan = plan_mirrors(spec, app, ["producer.*", "all"])
    names = [m.port.qualified_name for m in plan.mirrored]
    assert names.count("producer.out") == 1 and "gen.sample" in names
    assert any(text.startswith("tree.structure: no converter knows") for text in plan.skipped)
    with pytest.raises(ConfigErrors, match="tree.structure"):
        plan_mirrors(spec, app, ["tree.structure"])
    with pytest.raises(ConfigErrors, match="matches no output port"):
        plan_mirrors(spec, app, ["nothing.*"])


def test_check_names_a_port_no_converter_knows(app_file: Path, capsys) -> None:
    assert launcher.main([str(app_file), "--check", "--expose", "producer.out"]) == 0
    out = capsys.readouterr().out
    assert "producer.out -> ~/producer/out (std_msgs/msg/Float64, BUFFER 200)" in out
    assert launcher.main([str(app_file), "--check", "--expose", "tree.structure"]) == 1
    assert "tree.structure" in capsys.readouterr().err


def test_a_topic_of_an_input_port_or_an_unknown_type_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "bad.xml"
    path.write_text(APP.replace('<topic task="gen" port="sample" name="/mirror_test/sample"/>',
                                '<topic task="producer" port="out" type="std_msgs/msg/Bool"/>'))
    spec, app = built(path)
    with pytest.raises(ConfigErrors, match="no converter for ROS type 'std_msgs/msg/Bool'"):
        plan_mirrors(spec, app)


def test_a_pooled_mesh_is_mirrored_as_its_points_and_a_handle_as_a_pose(ros) -> None:
    """The palpation app's remote scene (a MeshReconstructor's slots) as a PointCloud2 in the mesh's
    camera frame, the slot given back; a device's handle as a PoseStamped in the topic's frame."""
    import numpy as np
    from coco_core.application import Application
    from coco_core.component import Component
    from coco_core.model import AppSpec, TopicMirrorSpec
    from coco_core.ports import OutputPort, PooledOutputPort
    from coco_mr_haptics.types import HapticDeviceState
    from coco_mr_vision.mesh import MeshInfo, MeshLayout, TriangleMesh
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import PointCloud2

    class Scene(Component):
        mesh = PooledOutputPort(slots=2)
        state = OutputPort(HapticDeviceState)

    node = ros
    app = Application("mirror_app")
    scene = app.add(Scene("scene"))
    spec = AppSpec(name="mirror_app", topics=[
        TopicMirrorSpec("scene", "mesh", "cloud", "sensor_msgs/msg/PointCloud2"),
        TopicMirrorSpec("scene", "state", "handle", frame="hand_tracker")])
    clouds: list[Any] = []
    poses: list[Any] = []
    node.create_subscription(PointCloud2, "/cloud", clouds.append, 1)
    node.create_subscription(PoseStamped, "/handle", poses.append, 1)
    with PortMirrors(node, app, spec) as mirrors:
        wait_for(lambda: all(m.subscribers for m in mirrors.mirrors), "both mirrors to match")
        layout = MeshLayout(2, 2)
        slot = scene.mesh.acquire((layout.offsets[-1],), np.uint8)
        vertices, _, colors, _ = TriangleMesh.writable(slot.array, layout)
        vertices[:] = [[0, 0, 1], [0.1, 0, 1], [0, 0.1, 1], [0.1, 0.1, 1.2]]
        colors[:] = 200
        slot.stamp = MeshInfo(layout, 3, 0, None, 12.5, "camera")
        scene.mesh.write(slot)
        scene.state.write(HapticDeviceState((0.1, 0.2, 0.3)))
        wait_for(lambda: clouds and poses, "the cloud and the pose")
        cloud, pose = clouds[0], poses[0]
        assert (cloud.header.frame_id, cloud.width, cloud.height) == ("camera", 3, 1)
        assert cloud.header.stamp.sec == 12
        assert pose.header.frame_id == "hand_tracker"
        assert (pose.pose.position.x, pose.pose.position.y, pose.pose.position.z) == (0.1, 0.2, 0.3)
        wait_for(lambda: slot.readers == 0, "the mirror to give the slot back")


def test_a_force_goes_out_as_a_wrench_and_an_arrow_in_the_topics_frame(ros) -> None:
    from coco_core.application import Application
    from coco_core.component import Component
    from coco_core.model import AppSpec, TopicMirrorSpec
    from coco_core.ports import OutputPort
    from coco_mr_haptics.types import HapticSample
    from geometry_msgs.msg import WrenchStamped
    from visualization_msgs.msg import Marker

    class Renderer(Component):
        sample = OutputPort(HapticSample)
        proxy_force = OutputPort(tuple)

    node = ros
    app = Application("mirror_app")
    renderer = app.add(Renderer("renderer"))
    spec = AppSpec(name="mirror_app", topics=[
        TopicMirrorSpec("renderer", "proxy_force", "force", "geometry_msgs/msg/WrenchStamped", frame="camera"),
        TopicMirrorSpec("renderer", "sample", "arrow", "visualization_msgs/msg/Marker", frame="camera")])
    wrenches: list[Any] = []
    arrows: list[Any] = []
    node.create_subscription(WrenchStamped, "/force", wrenches.append, 1)
    node.create_subscription(Marker, "/arrow", arrows.append, 1)
    with PortMirrors(node, app, spec) as mirrors:
        wait_for(lambda: all(m.subscribers for m in mirrors.mirrors), "both mirrors to match")
        renderer.proxy_force.write((0.0, 0.0, 5.0))
        renderer.sample.write(HapticSample(1.0, (0.0, 0.0, 1.0), (0.0, 0.0, 0.99), (0.0, 0.0, 5.0), True, "cloud",
                                           0.01))
        wait_for(lambda: wrenches and arrows, "the wrench and the arrow")
    assert wrenches[0].header.frame_id == "camera" and wrenches[0].wrench.force.z == 5.0
    arrow = arrows[0]
    assert arrow.header.frame_id == "camera" and arrow.type == Marker.ARROW
    assert [(p.x, p.y, p.z) for p in arrow.points] == [(0.0, 0.0, 0.99), (0.0, 0.0, pytest.approx(1.09))]


def test_a_mirror_with_a_rate_publishes_the_newest_value_and_counts_the_rest_dropped(app_file: Path, ros) -> None:
    from coco_core.model import TopicMirrorSpec
    from std_msgs.msg import Float64

    node = ros
    spec, app = built(app_file)
    spec.topics[:] = [TopicMirrorSpec("producer", "out", "limited", hz=20)]
    port = app.component("producer").outputs["out"]
    received: list[float] = []
    node.create_subscription(Float64, "/limited", lambda msg: received.append(msg.data), 10)
    with PortMirrors(node, app, spec) as mirrors:
        mirror = mirrors.mirrors[0]
        wait_for(lambda: mirror.subscribers == 1, "the mirror to match the subscription")
        for value in range(50):
            port.write(value)
        wait_for(lambda: received and received[-1] == 49.0, "the newest value")
        counters = mirror.connection.counters()
    assert len(received) < 10 and counters["written"] == 50
    assert counters["read"] == len(received) and counters["dropped"] == 50 - len(received)


def test_check_names_a_port_of_a_child_process_no_converter_knows(tmp_path: Path, capsys) -> None:
    """The ports of a ``<process>``'s components are that child's to mirror: ``--check`` builds its
    part to see them."""
    path = tmp_path / "in_a_child.xml"
    path.write_text(APP.replace('<activity name="a">', '<process name="worker"><activity name="a">')
                    .replace("</activity>\n  </activities>", "</activity></process>\n  </activities>"))
    assert launcher.main([str(path), "--check", "--expose", "producer.out"]) == 0
    assert "producer.out -> ~/producer/out (std_msgs/msg/Float64, BUFFER 200)" in capsys.readouterr().out
    assert launcher.main([str(path), "--check", "--expose", "tree.structure"]) == 1
    assert "tree.structure" in capsys.readouterr().err


def test_a_frame_pose_goes_to_a_pose_topic_and_to_tf(ros) -> None:
    """A FramePose port is a PoseStamped by default, and a /tf transform with ``type=TFMessage``."""
    import numpy as np
    from coco_core.application import Application
    from coco_core.component import Component
    from coco_core.model import AppSpec, TopicMirrorSpec
    from coco_core.ports import OutputPort
    from coco_core.transforms.samples import FramePose
    from geometry_msgs.msg import PoseStamped
    from tf2_msgs.msg import TFMessage

    class Tracker(Component):
        tool = OutputPort(FramePose)

    node = ros
    app = Application("mirror_app")
    tracker = app.add(Tracker("tracker"))
    spec = AppSpec(name="mirror_app", topics=[TopicMirrorSpec("tracker", "tool", "tool_pose"),
                                              TopicMirrorSpec("tracker", "tool", "/tf", "tf2_msgs/msg/TFMessage")])
    poses: list[Any] = []
    tf: list[Any] = []
    node.create_subscription(PoseStamped, "/tool_pose", poses.append, 1)
    node.create_subscription(TFMessage, "/tf", tf.append, 1)
    with PortMirrors(node, app, spec) as mirrors:
        wait_for(lambda: all(m.subscribers for m in mirrors.mirrors), "both mirrors to match")
        transform = np.eye(4)
        transform[:3, 3] = (0.5, 0.0, 0.25)
        tracker.tool.write(FramePose("world", "tool", transform, 3.0))
        wait_for(lambda: poses and tf, "the pose and the transform")
    assert poses[0].header.frame_id == "world" and poses[0].pose.position.x == 0.5
    sent = tf[0].transforms[0]
    assert (sent.header.frame_id, sent.child_frame_id, sent.transform.translation.z) == ("world", "tool", 0.25)
