"""ROSHapticDevice over real DDS: the installed ROS launcher (a subprocess) runs a HapticRenderer on a
plane for a ROSHapticDevice, while this test's own rclpy node acts as the device's driver: it
publishes the handle's pose pressing into the plane and reads the WrenchStamped that comes back.
Domain 71, localhost only."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy

from coco_core.interrupt import interrupt
from conftest import rclpy_peer

WORKSPACE = Path(__file__).resolve().parents[2]
LAUNCHER = WORKSPACE / "install" / "coco_ros" / "lib" / "coco_ros" / "launcher"
DOMAIN = "76"  # its own: the workspace tests (test/test_interop.py: 71) run at the same time
STIFFNESS = 600.0

APP = f"""<package name="ros_haptic_device">
  <components>
    <component><name>device</name><task>ROSHapticDevice</task><library>coco_ros</library>
      <attributes>
        <attribute name="pose_topic" value="/haptic/pose"/>
        <attribute name="wrench_topic" value="/haptic/wrench"/>
      </attributes>
    </component>
    <component><name>renderer</name><task>HapticRenderer</task><library>coco_mr_haptics</library>
      <components>
        <component><name>floor</name><task>HapticImplicitSurf</task><library>coco_mr_haptics</library>
          <attributes>
            <attribute name="surface" value="plane()"/>
            <attribute name="stiffness" value="{STIFFNESS}"/>
            <attribute name="damping" value="0"/>
          </attributes>
        </component>
      </components>
    </component>
  </components>
  <connections>
    <connection data="DATA" policy="LOCKED"><src task="device" port="state"/><dest task="renderer" port="device"/></connection>
    <connection data="DATA" policy="LOCKED"><src task="renderer" port="force"/><dest task="device" port="force"/></connection>
  </connections>
  <activities>
    <activity name="haptics"><schedule type="periodic" period="2"/>
      <components><component name="device"/><component name="renderer"/></components></activity>
  </activities>
</package>
"""


@pytest.fixture
def ros(monkeypatch: pytest.MonkeyPatch):
    yield from rclpy_peer(monkeypatch, DOMAIN, "haptic_device_driver")


@pytest.mark.skipif(not LAUNCHER.exists(), reason="workspace not built (source scripts/setup.sh)")
def test_a_ros_driver_feels_the_plane(tmp_path: Path, ros) -> None:
    node, executor = ros
    app = tmp_path / "app.xml"
    app.write_text(APP)
    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    wrenches: list[WrenchStamped] = []
    node.create_subscription(WrenchStamped, "/haptic/wrench", wrenches.append, qos)
    publisher = node.create_publisher(PoseStamped, "/haptic/pose", qos)
    env = dict(os.environ, ROS_DOMAIN_ID=DOMAIN, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
    process = subprocess.Popen([sys.executable, str(LAUNCHER), str(app), "--duration", "90"], cwd=tmp_path,
                               env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)

    def send(z: float) -> None:
        message = PoseStamped()
        now = time.time()
        message.header.stamp.sec, message.header.stamp.nanosec = int(now), int((now % 1) * 1e9)
        message.header.frame_id = "haptic_workspace"
        message.pose.position.x, message.pose.position.y, message.pose.position.z = 0.01, -0.02, z
        message.pose.orientation.w = 1.0
        publisher.publish(message)

    def hold(z: float, seconds: float) -> list[WrenchStamped]:
        """Publish the handle at height z for a while; the wrenches received meanwhile."""
        start = len(wrenches)
        end = time.monotonic() + seconds
        while time.monotonic() < end and process.poll() is None:
            send(z)
            executor.spin_once(timeout_sec=0.005)
        return wrenches[start:]

    try:
        deadline = time.monotonic() + 60
        while not wrenches and time.monotonic() < deadline and process.poll() is None:
            hold(0.02, 0.2)  # above the plane: discovery, then zero wrenches
        assert wrenches, "no wrench came back"
        above = hold(0.02, 0.5)
        path = [0.02 - 0.0005 * i for i in range(50)]  # down to 4.5 mm below, 0.5 mm per message
        for z in path:
            hold(z, 0.01)
        pressed = hold(-0.005, 1.0)
    finally:
        code, output = interrupt(process)
    assert code == 0, output
    assert "ROSHapticDevice device: pose /haptic/pose" in output, output
    assert above and all(w.wrench.force.z == 0.0 for w in above)
    # Held 5 mm inside the plane: the wrench is stiffness x 5 mm, up, in the pose's frame.
    late = pressed[len(pressed) // 2:]
    assert late, output
    for wrench in late:
        assert wrench.wrench.force.z == pytest.approx(STIFFNESS * 0.005, rel=1e-6)
        assert wrench.wrench.force.x == 0.0 and wrench.wrench.force.y == 0.0
        assert wrench.header.frame_id == "haptic_workspace"
    assert "poses received" in output and "wrenches sent" in output
