"""coco-replay: republish a bag on DDS (a real rclpy subscriber receives it), damaged bags exit 1."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from tf2_msgs.msg import TFMessage

from coco_ros.bag import BagReader, BagWriter

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


UDP_ONLY = {"FASTDDS_BUILTIN_TRANSPORTS": "UDPv4"}
"""Fast DDS without its shared-memory transport, for the test whose subscriber stops itself (SIGSTOP):
a process stopped at an arbitrary point may hold a lock of a shared-memory port that the replay's
participant then waits on (with the Python lock held, out of reach of pytest's timeout); a stopped
process holds nothing of a UDP socket but its own buffer."""


def cli(*args: str, timeout: float = 20.0, transports: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    env = dict(os.environ, ROS_DOMAIN_ID=DOMAIN, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               PYTHONPATH=os.pathsep.join([str(PACKAGE), str(PACKAGE.parent / "coco_core"),
                                           os.environ.get("PYTHONPATH", "")]), **(transports or {}))
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
        spinner.join(timeout=5)
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        context.destroy()  # its DDS participant ends here, before the stuck-subscriber test
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

    from mcap.reader import make_reader

    folder = tmp_path / "cut"
    shutil.copytree(chatter_bag, folder)
    mcap = folder / "chatter_0.mcap"
    with mcap.open("rb") as stream:
        chunks = sorted(c.chunk_start_offset for c in make_reader(stream).get_summary().chunk_indexes)
    mcap.write_bytes(mcap.read_bytes()[: chunks[len(chunks) // 2]])
    result = cli(str(folder), "--fast", "--delay", "0")
    assert result.returncode == 1, result.stderr
    assert f"{folder / 'metadata.yaml'}: the storage files hold fewer messages" in result.stderr, result.stderr
    assert "are lost" in result.stderr


def test_damaged_bags_that_exited_0_exit_1_naming_file_and_byte(chatter_bag, tmp_path):
    """Issue 23's damage that coco-replay published without a word (or, cut before any topic, refused
    without naming the damage): each exits 1 with the file and the byte, after publishing what is
    readable, and each message at most once."""
    from mcap.reader import make_reader

    mcap = chatter_bag / "chatter_0.mcap"
    data = mcap.read_bytes()
    with mcap.open("rb") as stream:
        chunks = sorted(make_reader(stream).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
    middle = chunks[len(chunks) // 2]
    start, end = middle.chunk_start_offset, middle.chunk_start_offset + middle.chunk_length
    kinds = {  # name: (the .mcap file's bytes, with metadata.yaml, the byte named)
        "cut at a chunk boundary, no metadata.yaml": (data[:start], False, start),
        "a duplicated chunk": (data[:end] + data[start:end] + data[end:], True, end),
        "cut before any topic": (data[:chunks[0].chunk_start_offset + 40], False, chunks[0].chunk_start_offset),
        "an uncompressed chunk cut in the middle": (data[:start + middle.chunk_length // 2], True, None),
    }
    for index, (name, (content, with_metadata, byte)) in enumerate(kinds.items()):
        folder = tmp_path / f"kind{index}"
        folder.mkdir()
        (folder / mcap.name).write_bytes(content)
        if with_metadata:
            (folder / "metadata.yaml").write_text((chatter_bag / "metadata.yaml").read_text())
        result = cli(str(folder), "--fast", "--delay", "0")
        assert result.returncode == 1, (name, result.stderr)
        named = f"{folder / mcap.name} at byte {byte if byte is not None else ''}"
        assert named in result.stderr, (name, result.stderr)
        if name == "cut before any topic":
            assert "no topic can be published: the bag is damaged" in result.stderr, result.stderr
            continue
        published = int(result.stderr.split(" messages published")[0].rsplit(" ", 1)[-1])
        assert 0 < published <= COUNT + 1, (name, result.stderr)
        if name == "a duplicated chunk":
            assert published == COUNT + 1, result.stderr
        if name == "an uncompressed chunk cut in the middle":  # more than the chunks before the cut hold
            with BagReader(chatter_bag) as reader:
                before = sum(1 for m in reader.messages() if m.log_time < middle.message_start_time)
            assert published > before, result.stderr


def test_damage_that_loses_no_message_exits_1_naming_what_is_missing(chatter_bag, tmp_path):
    """Issue 36's silent exits 0: the footer cut (``truncate -s -100``), the file cut right after its
    last chunk, metadata.yaml deleted. Every message is published, then the exit status is 1 and the
    error names the footer, the byte where the data ends, or metadata.yaml."""
    import shutil

    from mcap.reader import make_reader

    mcap = chatter_bag / "chatter_0.mcap"
    data = mcap.read_bytes()
    with mcap.open("rb") as stream:
        last = max(make_reader(stream).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
    after_last = last.chunk_start_offset + last.chunk_length + last.message_index_length
    kinds = {  # name: (the .mcap file's bytes, with metadata.yaml, what the error names)
        "footer cut": (data[:-100], True, f"{mcap.name} at byte {len(data) - 100}: the file has no MCAP footer"),
        "cut right after the last chunk": (data[:after_last], True, f"{mcap.name} at byte {after_last}: the data "
                                           "section ends here without its DataEnd record"),
        "metadata.yaml deleted": (data, False, "metadata.yaml: missing"),
    }
    for index, (name, (content, with_metadata, named)) in enumerate(kinds.items()):
        folder = tmp_path / f"kind{index}"
        shutil.copytree(chatter_bag, folder)
        (folder / mcap.name).write_bytes(content)
        if not with_metadata:
            (folder / "metadata.yaml").unlink()
        result = cli(str(folder), "--fast", "--delay", "0")
        assert result.returncode == 1, (name, result.stderr)
        assert f"{COUNT + 1} messages published" in result.stderr, (name, result.stderr)
        assert named in result.stderr, (name, result.stderr)


SUBSCRIBER = """
import os, signal, sys, time
import rclpy
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile
from nav_msgs.msg import Odometry
from geometry_msgs.msg import PoseWithCovarianceStamped
from tf2_msgs.msg import TFMessage

rclpy.init()
node = rclpy.create_node("counting_subscriber")
counts = {"/tf": 0, "/odom": 0, "/amcl_pose": 0}
def counter(topic):
    def count(message):
        counts[topic] += 1
        if mode == "stuck":  # a subscriber that hangs once the data flows: it acknowledges no more
            os.kill(os.getpid(), signal.SIGSTOP)
    return count
mode = sys.argv[1]
if mode in ("stream", "stuck"):  # subscribers that want every message: reliable, KEEP_ALL
    every = QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=0)
    node.create_subscription(TFMessage, "/tf", counter("/tf"), every)
    node.create_subscription(Odometry, "/odom", counter("/odom"), every)
elif mode == "shallow":  # rclpy's usual subscriber: reliable, KEEP_LAST 10
    node.create_subscription(TFMessage, "/tf", counter("/tf"), QoSProfile(depth=10))
else:  # a late subscriber of a transient-local topic, deeper than the recording's depth 1
    while node.count_publishers("/amcl_pose") == 0:
        rclpy.spin_once(node, timeout_sec=0.05)
    time.sleep(1.0)  # the replay has published every /amcl_pose by now
    node.create_subscription(PoseWithCovarianceStamped, "/amcl_pose", counter("/amcl_pose"),
                             QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL))
print("ready", flush=True)
deadline = time.monotonic() + float(sys.argv[2])
last, seen = time.monotonic(), 0
while time.monotonic() < deadline and not (seen and time.monotonic() - last > 3.0):  # 3 s quiet: done
    rclpy.spin_once(node, timeout_sec=0.05)
    if sum(counts.values()) != seen:
        last, seen = time.monotonic(), sum(counts.values())
print(counts["/tf"], counts["/odom"], counts["/amcl_pose"], flush=True)
"""


def start_subscriber(mode: str, seconds: float, transports: dict[str, str] | None = None) -> subprocess.Popen:
    env = dict(os.environ, ROS_DOMAIN_ID=DOMAIN, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", **(transports or {}))
    return subprocess.Popen([sys.executable, "-c", SUBSCRIBER, mode, str(seconds)], stdout=subprocess.PIPE,
                            text=True, env=env)


@pytest.fixture(scope="module")
def robot_bag(tmp_path_factory) -> Path:
    """/tf (reliable, depth 100), /odom (reliable, depth 10) as fast as a robot records them, and
    /amcl_pose offered transient local with depth 1, as nav2's AMCL does."""
    from geometry_msgs.msg import PoseWithCovarianceStamped, TransformStamped
    from nav_msgs.msg import Odometry
    from std_msgs.msg import String

    from coco_ros.bag import Qos

    folder = tmp_path_factory.mktemp("replay_flow") / "robot"
    with BagWriter(folder) as writer:
        writer.add_topic("/tf", "tf2_msgs/msg/TFMessage", qos=Qos(depth=100))
        writer.add_topic("/amcl_pose", "geometry_msgs/msg/PoseWithCovarianceStamped",
                         qos=Qos(depth=1, durability="transient_local"))
        for i in range(10):
            writer.write("/amcl_pose", PoseWithCovarianceStamped(), T0 + i * MS)
        for i in range(3000):
            transforms = [TransformStamped(child_frame_id=f"link{k}") for k in range(3)]
            writer.write("/tf", TFMessage(transforms=transforms), T0 + 10 * MS + i * MS)
            if i % 2 == 0:
                writer.write("/odom", Odometry(child_frame_id="base_link"), T0 + 10 * MS + i * MS)
        writer.write("/keepalive", String(data="end"), T0 + 8000 * MS)  # keeps a 1x replay alive 8 s
    return folder


def replay_to_subscriber(bag: Path, mode: str) -> tuple[subprocess.CompletedProcess, list[str]]:
    """``coco-replay --fast`` of /tf and /odom to a subscriber process in ``mode``: (result, its counts)."""
    transports = UDP_ONLY if mode == "stuck" else None
    subscriber = start_subscriber(mode, 25.0, transports)
    try:
        assert subscriber.stdout.readline().strip() == "ready"
        result = cli(str(bag), "--fast", "--wait-subscribers", "1" if mode == "shallow" else "2", "--topics", "/tf",
                     "/odom", timeout=60, transports=transports)
        if mode == "stuck":
            return result, []
        return result, subscriber.communicate(timeout=30)[0].split()
    finally:
        if subscriber.poll() is None:
            subscriber.send_signal(signal.SIGCONT)
            subscriber.kill()
            subscriber.wait()


def test_fast_replay_delivers_every_message_to_reliable_subscribers(robot_bag):
    """A separate rclpy process with reliable KEEP_ALL subscriptions receives all of /tf and /odom."""
    result, counts = replay_to_subscriber(robot_bag, "stream")
    assert result.returncode == 0, result.stderr
    assert "acknowledge" not in result.stderr, result.stderr
    assert counts[:2] == ["3000", "1500"], counts


def test_fast_replay_reports_a_stuck_reliable_subscriber(robot_bag):
    """A subscriber that stops acknowledging (its process stops itself at its first message) is
    reported, not ignored."""
    result, _ = replay_to_subscriber(robot_bag, "stuck")
    assert result.returncode == 0, result.stderr
    assert "did not acknowledge every message" in result.stderr and "/tf" in result.stderr, result.stderr


def test_fast_replay_names_subscribers_whose_history_may_be_shallower_than_a_topic(robot_bag):
    """An rclpy subscriber in another process with KEEP_LAST 10 on /tf, which --fast sends 3000 messages
    in a burst: its own history overwrites what it cannot take in time, which no publisher can see
    (issue 23: 166-258 of 5,422 delivered, the replay silent). The replay names it, at the start and in
    its final report, and says what to do. (DDS discovery does not carry the history: rmw_fastrtps
    announces it as unknown, which is named as such.)"""
    result, _ = replay_to_subscriber(robot_bag, "shallow")
    assert result.returncode == 0, result.stderr
    start, _, end = result.stderr.partition(" messages published")
    assert end, result.stderr
    for part in (start, end):
        assert "warning:" in part, result.stderr
        assert re.search(r"/tf \(3000 messages\) to /counting_subscriber \((KEEP_LAST 10|history unknown)", part), \
            result.stderr
        assert "--rate" in part and "deeper history" in part, result.stderr
    assert "/odom" not in result.stderr.replace("--topics", ""), result.stderr  # nobody subscribes to it


def test_replay_offers_the_recorded_depth_to_late_transient_local_subscribers(robot_bag):
    """The recording offered /amcl_pose at depth 1, transient local: a subscriber joining after the
    replay published ten of them gets one, as it would have from the recorded publisher."""
    subscriber = start_subscriber("late", 3.0)
    try:
        result = cli(str(robot_bag), "--delay", "0", "--topics", "/amcl_pose", "/keepalive", timeout=60)
        assert result.returncode == 0, result.stderr
        lines = subscriber.communicate(timeout=30)[0].split("\n")
    finally:
        if subscriber.poll() is None:
            subscriber.kill()
            subscriber.wait()
    assert lines[0] == "ready" and lines[1].split()[2] == "1", lines


def test_a_subscriber_first_seen_without_its_node_is_reported_once_by_name():
    """DDS announces a subscription before its node's name (later still on a loaded machine): the final
    report merges what the start saw with what the end sees, per subscription (its GID), and keeps the
    name (CI once listed the same subscriber twice, as rmw's placeholder and by name)."""
    from coco_ros.replay.flow import ShallowSubscriber, merged

    gid = bytes(range(16))
    unknown = ShallowSubscriber("/tf", "_NODE_NAMESPACE_UNKNOWN_/_NODE_NAME_UNKNOWN_", None, 3000, gid)
    named = ShallowSubscriber("/tf", "/counting_subscriber", None, 3000, gid)
    other = ShallowSubscriber("/tf", "/counting_subscriber", 10, 3000, bytes(16))
    assert merged([unknown], [named, other]) == [named, other]
    assert merged([named], []) == [named]
