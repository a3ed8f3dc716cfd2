"""ROSInterface without DDS: topic spec parsing and QoS, ports from the specs, attribute errors, and
the error under plain ``coco-launch`` (no ROS node)."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy

from coco_core import Application, AttributeValueError, CocoError, TriggeredActivity
from coco_core.errors import SpecError
from coco_core.stamps import Stamped
from coco_core.transforms.samples import FramePose, JointSample
from coco_ros.bag import BagMessage
from coco_ros.interface.component import ROSInterface
from coco_ros.interface.topic import SYNTAX, available_types, parse_spec, parse_specs

WORKSPACE = Path(__file__).resolve().parents[2]
COCO_LAUNCH = WORKSPACE / "install" / "coco_core" / "lib" / "coco_core" / "coco-launch"


@pytest.fixture(autouse=True)
def ros_domain(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", "98")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


def test_spec_with_defaults() -> None:
    spec = parse_spec("joints=/joint_states:sensor_msgs/JointState")
    assert (spec.port, spec.topic, spec.type_name) == ("joints", "/joint_states", "sensor_msgs/msg/JointState")
    assert (spec.qos.depth, spec.qos.reliability, spec.qos.durability) == (10, "reliable", "volatile")
    assert spec.options == {}
    profile = spec.qos_profile()
    assert profile.history == HistoryPolicy.KEEP_LAST and profile.depth == 10
    assert profile.reliability == ReliabilityPolicy.RELIABLE
    assert profile.durability == DurabilityPolicy.VOLATILE


def test_spec_with_qos_and_converter_options() -> None:
    spec = parse_spec("pose=/robot/tool_pose:geometry_msgs/msg/PoseStamped;depth=3;reliability=best_effort;"
                      "durability=transient_local;child_frame=tool")
    assert spec.topic == "/robot/tool_pose" and spec.options == {"child_frame": "tool"}
    profile = spec.qos_profile()
    assert profile.depth == 3
    assert profile.reliability == ReliabilityPolicy.BEST_EFFORT
    assert profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert spec.converter().child_frame == "tool"
    # typed converter options: booleans and '|'-separated lists
    assert parse_spec("img=camera/image:sensor_msgs/Image;copy=true").options == {"copy": True}
    assert parse_spec("a=/a:std_msgs/Float64MultiArray;labels=x|y").converter().labels == ("x", "y")


@pytest.mark.parametrize("text, problem", [
    ("joints", "no '=' between the port name"),
    ("joints=/joint_states", "no ':package/msg/Type'"),
    ("2joints=/joint_states:sensor_msgs/JointState", "not an identifier"),
    ("joints=/joint//states:sensor_msgs/JointState", "not a valid topic name"),
    ("joints=/joint_states:sensor_msgs/Imu", "no converter for message type 'sensor_msgs/Imu'; supported: "),
    ("joints=/joint_states:sensor_msgs/JointState;depth=0", "depth must be an integer >= 1"),
    ("joints=/joint_states:sensor_msgs/JointState;reliability=sometimes", "reliability must be reliable or best_effort"),
    ("joints=/joint_states:sensor_msgs/JointState;durability=forever", "durability must be volatile or transient_local"),
    ("joints=/joint_states:sensor_msgs/JointState;gain=2", "has no option(s) gain"),
    ("joints=/joint_states:sensor_msgs/JointState;depth", "not key=value"),
    ("img=/image:sensor_msgs/Image;copy=maybe", "option copy expects true or false"),
])
def test_bad_specs_name_the_spec_and_the_syntax(text: str, problem: str) -> None:
    with pytest.raises(SpecError) as caught:
        parse_spec(text)
    message = str(caught.value)
    assert repr(text) in message and problem in message and SYNTAX in message


def test_unknown_type_lists_supported_types() -> None:
    with pytest.raises(SpecError) as caught:
        parse_spec("x=/x:foo_msgs/msg/Bar")
    for name in ("sensor_msgs/msg/JointState", "sensor_msgs/msg/Image", "sensor_msgs/msg/CameraInfo",
                 "sensor_msgs/msg/PointCloud2", "geometry_msgs/msg/PoseStamped",
                 "geometry_msgs/msg/TransformStamped", "std_msgs/msg/Float64MultiArray"):
        assert name in str(caught.value)


def test_tf_message_can_be_bridged() -> None:
    """tf2_msgs is built in the workspace (vendor/tf2_msgs), so /tf is a topic like any other."""
    spec = parse_spec("tf=/tf_static:tf2_msgs/msg/TFMessage;depth=1;durability=transient_local")
    assert spec.type_name == "tf2_msgs/msg/TFMessage" and spec.qos.transient_local
    assert "tf2_msgs/msg/TFMessage" in available_types()


def test_a_port_named_twice_is_refused() -> None:
    with pytest.raises(SpecError, match="port 'a' is named by another spec"):
        parse_specs(["a=/a:sensor_msgs/JointState", "a=/b:sensor_msgs/JointState"])


def test_ports_follow_the_specs() -> None:
    bridge = ROSInterface("bridge",
                          subscribe="joints=/joint_states:sensor_msgs/JointState, pose=/pose:geometry_msgs/PoseStamped",
                          publish=["cmd=/cmd:std_msgs/msg/Float64MultiArray"])
    bridge.init()
    assert set(bridge.outputs) == {"joints", "pose"} and set(bridge.inputs) == {"cmd"}
    assert bridge.outputs["joints"].type is JointSample and bridge.outputs["pose"].type is FramePose
    # A publish port takes the converter's type or a Stamped one (published unwrapped, its age profiled).
    assert bridge.inputs["cmd"].type == np.ndarray | Stamped | BagMessage and bridge.inputs["cmd"].event


def test_attribute_error_names_component_and_spec() -> None:
    with pytest.raises(AttributeValueError) as caught:
        ROSInterface("bridge", subscribe="joints=/joint_states:sensor_msgs/Imu")
    assert "bridge.subscribe" in str(caught.value) and "joints=/joint_states:sensor_msgs/Imu" in str(caught.value)


def test_same_port_in_subscribe_and_publish_is_refused() -> None:
    bridge = ROSInterface("bridge", subscribe="x=/a:sensor_msgs/JointState", publish="x=/b:sensor_msgs/JointState")
    with pytest.raises(CocoError, match="named in both subscribe and publish"):
        bridge.init()


def test_without_the_ros_launcher_on_config_fails_clearly(caplog: pytest.LogCaptureFixture) -> None:
    app = Application("plain")
    bridge = app.add(ROSInterface("bridge", subscribe="joints=/joint_states:sensor_msgs/JointState"),
                     TriggeredActivity("bridging"))
    with caplog.at_level(logging.ERROR, logger="coco"):
        assert bridge.configure() is False
    assert not bridge.enabled
    assert "ROSInterface bridge needs the ROS launcher" in caplog.text


APP = """<package name="rosif_plain">
  <components>
    <component><name>bridge</name><task>ROSInterface</task><library>coco_ros</library>
      <attributes>
        <attribute name="subscribe" value="joints=/joint_states:sensor_msgs/msg/JointState"/>
      </attributes>
    </component>
  </components>
  <activities>
    <activity name="bridging"><schedule type="triggered"/>
      <components><component name="bridge"/></components></activity>
  </activities>
</package>
"""


@pytest.mark.skipif(not COCO_LAUNCH.exists(), reason="workspace not built (source scripts/setup.sh)")
def test_plain_coco_launch_reports_that_the_ros_launcher_is_needed(tmp_path: Path) -> None:
    app = tmp_path / "app.xml"
    app.write_text(APP)
    result = subprocess.run([sys.executable, str(COCO_LAUNCH), str(app), "--duration", "0.5"],
                            capture_output=True, text=True, timeout=60, env=dict(os.environ))
    output = result.stdout + result.stderr
    assert "ROSInterface bridge needs the ROS launcher" in output, output
    assert "component bridge is stopped after its error in on_config" in output, output


def test_bad_spec_in_a_file_is_reported_before_anything_starts(tmp_path: Path) -> None:
    from coco_core.builder import build_application
    from coco_core.xml import load_application

    app = tmp_path / "app.xml"
    app.write_text(APP.replace("sensor_msgs/msg/JointState", "sensor_msgs/msg/Imu"))
    with pytest.raises(CocoError) as caught:
        build_application(load_application(app))
    assert "sensor_msgs/msg/Imu" in str(caught.value) and "supported" in str(caught.value)
