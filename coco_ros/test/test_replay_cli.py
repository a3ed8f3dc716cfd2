"""coco-replay: republish a bag on DDS (a real rclpy subscriber receives it), damaged bags exit 1."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from tf2_msgs.msg import TFMessage

from coco_ros.bag import BagWriter

T0 = 1_700_000_000_000_000_000
MS = 1_000_000
COUNT = 50
PACKAGE = Path(__file__).resolve().parents[1]


DOMAIN = "97"
"""This file's own DDS domain, for the replaying subprocess and the subscriber in the test alike."""


@pytest.fixture(autouse=True)
def own_domain(monkeypatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", DOMAIN)  # read by rclpy.init in this process too
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


def cli(*args: str, timeout: float = 20.0) -> subprocess.CompletedProcess:
    env = dict(os.environ, ROS_DOMAIN_ID=DOMAIN, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               PYTHONPATH=os.pathsep.join([str(PACKAGE), str(PACKAGE.parent / "coco_core"),
                                           os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-m", "coco_ros.replay.cli", *args, "--no-progress"],
                          capture_output=True, text=True, timeout=timeout, env=env)


@pytest.fixture(scope="module")
def chatter_bag(tmp_path_factory) -> Path:
    from geometry_msgs.msg import TransformStamped
    from std_msgs.msg import String

    folder = tmp_path_factory.mktemp("replay_cli") / "chatter"
    with BagWriter(folder, chunk_size=1024) as writer:
        writer.write("/tf_static", TFMessage(transforms=[TransformStamped(child_frame_id="tool")]), T0)
        for i in range(COUNT):
            writer.write("/chatter", String(data=f"hello {i}" + " " * 40), T0 + (i + 1) * MS)
    return folder


def test_fast_replay_reaches_a_ros_subscriber(chatter_bag):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile
    from std_msgs.msg import String

    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("replay_test_sub", context=context)
    got: list[str] = []
    node.create_subscription(String, "/replayed", lambda m: got.append(m.data), QoSProfile(depth=1000))
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        result = cli(str(chatter_bag), "--fast", "--remap", "/chatter:=/replayed", "--wait-subscribers", "1",
                     "--clock", "50")
        deadline = time.monotonic() + 5
        while len(got) < COUNT and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    assert result.returncode == 0, result.stderr
    assert "not replaying" not in result.stderr, result.stderr  # /tf_static too: tf2_msgs is built here
    assert [g.strip() for g in got] == [f"hello {i}" for i in range(COUNT)]


def test_truncated_bag_exits_1_naming_file_and_offset(chatter_bag, tmp_path):
    data = (chatter_bag / "chatter_0.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    result = cli(str(cut), "--fast", "--delay", "0", "--topics", "/chatter")
    assert result.returncode == 1
    assert f"{cut} at byte" in result.stderr
    published = int(result.stderr.split(" messages published")[0].rsplit(" ", 1)[-1])
    assert 0 < published < COUNT


def test_not_a_bag_exits_1(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file at all")
    result = cli(str(bad), "--fast", "--delay", "0")
    assert result.returncode == 1 and str(bad) in result.stderr


def test_bag_cut_at_a_record_boundary_exits_1_naming_what_is_lost(chatter_bag, tmp_path):
    """No byte of a record is cut: only metadata.yaml's counts show that the bag lost its end."""
    import shutil
    import struct

    folder = tmp_path / "cut"
    shutil.copytree(chatter_bag, folder)
    mcap = folder / "chatter_0.mcap"
    data = mcap.read_bytes()
    position, chunks = 8, []
    while position < len(data) - 8:
        opcode, length = struct.unpack_from("<BQ", data, position)
        if opcode == 0x06:  # Chunk
            chunks.append(position)
        position += 9 + length
    mcap.write_bytes(data[: chunks[len(chunks) // 2]])
    result = cli(str(folder), "--fast", "--delay", "0")
    assert result.returncode == 1, result.stderr
    assert f"{folder / 'metadata.yaml'}: the storage files hold fewer messages" in result.stderr, result.stderr
    assert "are lost" in result.stderr
