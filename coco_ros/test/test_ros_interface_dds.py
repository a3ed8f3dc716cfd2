"""ROSInterface end to end over real DDS: an application run by the installed ROS launcher (a
subprocess) bridges /joint_states into a sink component and a source component's arrays to /coco_out,
while this test's own rclpy node publishes the joint states and listens to /coco_out.

The test-local components live in a module written to tmp_path (the launcher imports them by
``module:Class`` with PYTHONPATH set); the sink writes what it gets to a JSON-lines file checked after
the launcher stopped. Domain 98, localhost only.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from coco_core.interrupt import interrupt
from conftest import rclpy_peer

WORKSPACE = Path(__file__).resolve().parents[2]
LAUNCHER = WORKSPACE / "install" / "coco_ros" / "lib" / "coco_ros" / "launcher"
DOMAIN = "98"

HELPERS = '''
import json

import numpy as np
from coco_core import Attribute, Component, InputPort, OutputPort
from coco_core.transforms.samples import JointSample


class JointSink(Component):
    """Writes every JointSample it receives as one JSON line."""

    path = Attribute(str, "", "JSON-lines output")
    joints = InputPort(JointSample, event=True)

    def on_config(self):
        self._file = open(self.path, "w")

    def on_update(self):
        for sample in self.joints.read_all():
            velocities = getattr(sample, "velocities", None)
            self._file.write(json.dumps({
                "type": type(sample).__name__,
                "is_joint_sample": isinstance(sample, JointSample),
                "names": list(sample.names),
                "positions": [float(p) for p in sample.positions],
                "velocities": None if velocities is None else [float(v) for v in velocities],
                "stamp": sample.stamp,
            }) + "\\n")
        self._file.flush()

    def on_stop(self):
        self._file.close()


class ArraySource(Component):
    """Writes [count, 0.5, -1.0] every update."""

    out = OutputPort(np.ndarray)

    def init(self):
        self.count = 0

    def on_update(self):
        self.out.write(np.array([float(self.count), 0.5, -1.0]))
        self.count += 1
'''

APP = """<package name="rosif_dds">
  <arg name="sink_path" default="joints.jsonl"/>
  <components>
    <component><name>bridge</name><task>ROSInterface</task><library>coco_ros</library>
      <attributes>
        <attribute name="subscribe" value="joints=/joint_states:sensor_msgs/msg/JointState;depth=50"/>
        <attribute name="publish" value="out=/coco_out:std_msgs/msg/Float64MultiArray;depth=20;labels=values"/>
      </attributes>
    </component>
    <component><name>sink</name><task>rosif_helpers:JointSink</task>
      <attributes><attribute name="path" value="$(arg sink_path)"/></attributes>
    </component>
    <component><name>source</name><task>rosif_helpers:ArraySource</task></component>
  </components>
  <connections>
    <connection data="BUFFER" policy="LOCKED" buffersize="256">
      <src task="bridge" port="joints"/><dest task="sink" port="joints"/>
    </connection>
    <connection data="BUFFER" policy="LOCKED" buffersize="256">
      <src task="source" port="out"/><dest task="bridge" port="out"/>
    </connection>
  </connections>
  <activities>
    <activity name="bridging"><schedule type="triggered"/>
      <components><component name="bridge"/></components></activity>
    <activity name="sinking"><schedule type="triggered"/>
      <components><component name="sink"/></components></activity>
    <activity name="sourcing"><schedule type="periodic" period="50"/>
      <components><component name="source"/></components></activity>
  </activities>
</package>
"""


@pytest.fixture
def ros(monkeypatch: pytest.MonkeyPatch):
    yield from rclpy_peer(monkeypatch, DOMAIN, "rosif_test_peer")


@pytest.mark.skipif(not LAUNCHER.exists(), reason="workspace not built (source scripts/setup.sh)")
@pytest.mark.parametrize("hosting", [[], ["--all-threads"]], ids=["executor", "threads"])
def test_launcher_bridges_joint_states_in_and_arrays_out(tmp_path: Path, ros, hosting: list[str]) -> None:
    node, executor = ros
    (tmp_path / "rosif_helpers.py").write_text(HELPERS)
    app = tmp_path / "app.xml"
    app.write_text(APP)
    sink_path = tmp_path / "joints.jsonl"

    received: list[Float64MultiArray] = []
    node.create_subscription(Float64MultiArray, "/coco_out", received.append, QoSProfile(depth=50))
    publisher = node.create_publisher(JointState, "/joint_states", QoSProfile(depth=50))

    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(tmp_path), env.get("PYTHONPATH", "")]))
    env["ROS_DOMAIN_ID"] = DOMAIN
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    process = subprocess.Popen([sys.executable, str(LAUNCHER), str(app), f"sink_path:={sink_path}",
                                "--duration", "90", *hosting],
                               cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    sent = 0
    output = ""
    try:
        deadline = time.monotonic() + 60
        lines: list[str] = []
        while time.monotonic() < deadline and process.poll() is None:
            msg = JointState(name=["shoulder", "elbow"], position=[0.1 * sent, -0.2], velocity=[1.0, 2.0])
            msg.header.stamp.sec = 1000 + sent
            msg.header.frame_id = "base"
            publisher.publish(msg)
            if sent % 3 == 0:  # a malformed one: two names, one position; counted and logged, not bridged
                bad = JointState(name=["shoulder", "elbow"], position=[9.0])
                bad.header.stamp.sec = 5000 + sent
                publisher.publish(bad)
            sent += 1
            executor.spin_once(timeout_sec=0.05)
            lines = sink_path.read_text().splitlines() if sink_path.exists() else []
            if len(lines) >= 5 and len(received) >= 5:
                break
    finally:
        code, output = interrupt(process)

    assert code == 0, output
    assert "ROSInterface bridge: subscribed joints=/joint_states" in output, output
    assert "(clean)" in output, output
    assert "cannot convert a message from /joint_states (sensor_msgs/msg/JointState) on port joints" in output, \
        output

    # The sink got JointStateSamples (JointSample subclasses) with what this node published.
    samples = [json.loads(line) for line in sink_path.read_text().splitlines()]
    assert len(samples) >= 5, output
    for sample in samples:
        assert sample["type"] == "JointStateSample" and sample["is_joint_sample"]
        assert sample["names"] == ["shoulder", "elbow"]
        assert sample["velocities"] == [1.0, 2.0]
        index = round(sample["stamp"]) - 1000  # the malformed messages (5000 + n) never arrive
        assert 0 <= index < sent
        assert sample["positions"] == pytest.approx([0.1 * index, -0.2])
    stamps = [sample["stamp"] for sample in samples]
    assert stamps == sorted(stamps)  # reliable, in order

    # This node got the source's arrays, published by the bridge.
    assert len(received) >= 5, output
    for msg in received:
        assert list(msg.data)[1:] == [0.5, -1.0]
        assert [dim.label for dim in msg.layout.dim] == ["values"] and msg.layout.dim[0].size == 3
    counts = [msg.data[0] for msg in received]
    assert counts == sorted(counts)
