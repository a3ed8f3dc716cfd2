"""docs/ros.md's example of a component of your own between two topics (examples/topic_scaler) does
what the docs say: run by the installed ROS launcher with the module on PYTHONPATH, in a namespace,
it publishes gain x every number it receives. This test is the publisher and the subscriber (real
rclpy nodes, DDS domain 45, localhost only)."""

from __future__ import annotations

import os
import subprocess
import time
from pathlib import Path

import pytest

from conftest import ROOT

EXAMPLE = ROOT / "examples" / "topic_scaler"
LAUNCHER = ROOT / "install" / "coco_ros" / "lib" / "coco_ros" / "launcher"
DOMAIN = "45"


def test_numbers_in_one_topic_come_out_scaled_on_the_other(monkeypatch: pytest.MonkeyPatch) -> None:
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import Float64

    monkeypatch.setenv("ROS_DOMAIN_ID", DOMAIN)
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env = {**os.environ, "PYTHONPATH": f"{EXAMPLE}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
           "PYTHONUNBUFFERED": "1"}
    process = subprocess.Popen([str(LAUNCHER), str(EXAMPLE / "scaler.xml"), "gain:=3", "--duration", "60",
                                "--ros-args", "-r", "__ns:=/lab"], env=env, cwd=ROOT,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    context = Context()
    rclpy.init(context=context)
    node = Node("scaler_peer", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    received: list[float] = []
    try:
        publisher = node.create_publisher(Float64, "/lab/value_in", 10)
        node.create_subscription(Float64, "/lab/value_out", lambda message: received.append(message.data), 10)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not (publisher.get_subscription_count()
                                                   and node.count_publishers("/lab/value_out")):
            executor.spin_once(timeout_sec=0.1)
        assert publisher.get_subscription_count(), "the example never subscribed to /lab/value_in"
        # Matched on this side does not mean matched on the launcher's: a probe is sent until its
        # result comes back, then the numbers the test checks.
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and not received:
            publisher.publish(Float64(data=0.0))
            executor.spin_once(timeout_sec=0.1)
        assert received and set(received) == {0.0}, received
        received.clear()
        for value in (1.0, 2.5, -4.0):
            publisher.publish(Float64(data=value))
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and len([v for v in received if v != 0.0]) < 3:
            executor.spin_once(timeout_sec=0.1)
    finally:
        process.terminate()
        out, _ = process.communicate(timeout=20)
        executor.shutdown()
        node.destroy_node()
        context.try_shutdown()
    # Probes still in flight may come back before them; the numbers come out scaled, in order.
    assert [value for value in received if value != 0.0] == [3.0, 7.5, -12.0], out
