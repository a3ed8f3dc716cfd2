"""The anchor of ``bench_hosts.py``: a plain rclpy publisher and subscriber, the same two phases and
the same payloads as ``_hosts_components.py``, the way a ROS 2 user would send them.

    python _hosts_rclpy.py pub small|sample|frame LATENCY BURST PERIOD_S
    python _hosts_rclpy.py sub small|sample|frame LATENCY BURST RECORD.json

Small samples: ``sensor_msgs/JointState`` with 19 positions; ``sample``: the same 19 float64 as a CoCo
connection between hosts sends them, a ``coco_interfaces/Sample`` made by CoCo's own encoder and
decoded by its decoder (``coco_ros.hosts.sample``) in the callback, with none of the ports and
threads around them: how much of the connection's cost is its encoding. Frames: two ``sensor_msgs/Image``
(rgb8 colour, 16UC1 depth, raw: what a ROS camera driver publishes), the frame counted when both
halves came. The write time is the header's stamp (the monotonic clock, one clock for the hosts of
one machine), the phase and number its ``frame_id`` (``phase:number``). Reliable, keep last BURST:
the QoS a CoCo BUFFER connection of that size gets between hosts.
"""

from __future__ import annotations

import json
import sys
import time
from typing import Any

import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image, JointState

from coco_core.hosts.key import AppKey

from _hosts_components import BURST, LATENCY, SMALL, redwood_frame

IDLE_TIMEOUT_S = 10.0
"""The subscriber gives up this long after the last message (a lost last sample ends the run)."""


BENCH_KEY = AppKey(bytes(range(32)), "the benchmark's key")
"""The key of the encoded variant's samples, sealed and checked as between CoCo's hosts."""


def stamp(message: Any, now: float, tag: str) -> None:
    message.header.stamp.sec = int(now)
    message.header.stamp.nanosec = int((now - int(now)) * 1e9)
    message.header.frame_id = tag


def publish(node: Any, kind: str, latency: int, burst: int, period: float) -> None:
    qos = QoSProfile(depth=max(burst, 1), reliability=ReliabilityPolicy.RELIABLE)
    if kind == "small":
        publishers = [node.create_publisher(JointState, "bench_small", qos)]
        joints = [f"joint_{i}" for i in range(SMALL)]
    elif kind == "sample":
        from coco_core.hosts.auth import Sealer
        from coco_interfaces.msg import Sample
        from coco_ros.hosts.sample import SampleEncoder

        publishers = [node.create_publisher(Sample, "bench_sample", qos)]
        encoder = SampleEncoder("plain", Sealer(BENCH_KEY, "bench_sample", "robot"))
    else:
        publishers = [node.create_publisher(Image, "bench_color", qos), node.create_publisher(Image, "bench_depth", qos)]
        frame = redwood_frame()
        halves = []
        for image, encoding in ((frame.color, "rgb8"), (frame.depth, "16UC1")):
            message = Image(height=image.height, width=image.width, encoding=encoding,
                            step=image.data.strides[0], data=image.data.tobytes())
            halves.append(message)
    deadline = time.monotonic() + 30
    while any(p.get_subscription_count() == 0 for p in publishers):
        if time.monotonic() > deadline:
            raise SystemExit("no subscriber matched in 30 s")
        time.sleep(0.01)

    def write(number: int, phase: int) -> None:
        now = time.perf_counter()
        tag = f"{phase}:{number}"
        if kind == "small":
            message = JointState(name=joints, position=[now, float(number), float(phase)] + [0.0] * (SMALL - 3))
            stamp(message, now, tag)
            publishers[0].publish(message)
            return
        if kind == "sample":
            value = np.zeros(SMALL)
            value[:3] = now, number, phase
            publishers[0].publish(encoder.encode(value, number + 1))
            return
        for publisher, half in zip(publishers, halves):
            stamp(half, now, tag)
            publisher.publish(half)

    start = time.perf_counter()
    for number in range(latency):
        time.sleep(max(0.0, start + number * period - time.perf_counter()))
        write(number, LATENCY)
    for number in range(latency, latency + burst):
        write(number, BURST)
    for publisher in publishers:
        publisher.wait_for_all_acked(rclpy.duration.Duration(seconds=30))


def subscribe(node: Any, kind: str, latency: int, burst: int, path: str) -> None:
    qos = QoSProfile(depth=max(burst, 1), reliability=ReliabilityPolicy.RELIABLE)
    records: list[tuple[int, int, float, float]] = []
    last = latency + burst - 1
    halves: dict[str, int] = {}
    done = False

    def arrived(message: Any) -> None:
        received = time.perf_counter()
        if kind == "frame":
            np.frombuffer(message.data, np.uint8)  # the pixels as an array, as a user's callback takes them
        tag = message.header.frame_id
        if kind == "frame":
            halves[tag] = halves.get(tag, 0) + 1
            if halves[tag] < 2:
                return
            del halves[tag]
        phase, number = (int(part) for part in tag.split(":"))
        written = message.header.stamp.sec + message.header.stamp.nanosec * 1e-9
        record(number, phase, written, received)

    def decoded(message: Any) -> None:  # as a reader's end takes a sample: its seal checked, then decoded
        if not verifier.accept(seal_of(message), sample_parts(message)):
            raise SystemExit("a sample of the benchmark failed its seal")
        value = decoder.decode(message)
        record(int(value[1]), int(value[2]), float(value[0]), time.perf_counter())  # received: decoded

    def record(number: int, phase: int, written: float, received: float) -> None:
        nonlocal done
        records.append((number, phase, written, received))
        done = number == last

    if kind == "small":
        node.create_subscription(JointState, "bench_small", arrived, qos)
    elif kind == "sample":
        from coco_core.hosts.auth import Refusals, Verifier
        from coco_interfaces.msg import Sample
        from coco_ros.hosts.sample import SampleDecoder, sample_parts
        from coco_ros.hosts.seal import seal_of

        decoder = SampleDecoder()
        verifier = Verifier(BENCH_KEY, "bench_sample", ["robot"], ["robot", "graphics"], Refusals())
        node.create_subscription(Sample, "bench_sample", decoded, qos)
    else:
        node.create_subscription(Image, "bench_color", arrived, qos)
        node.create_subscription(Image, "bench_depth", arrived, qos)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    print("ready", flush=True)
    quiet_since = time.monotonic()
    seen = 0
    while not done and time.monotonic() - quiet_since < IDLE_TIMEOUT_S:
        executor.spin_once(timeout_sec=0.1)
        if len(records) != seen:
            seen, quiet_since = len(records), time.monotonic()
    with open(path, "w") as out:
        json.dump(records, out)


def main() -> None:
    role, kind, latency, burst = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    rclpy.init()
    node = rclpy.create_node(f"bench_hosts_{role}")
    try:
        if role == "pub":
            publish(node, kind, latency, burst, float(sys.argv[5]))
        else:
            subscribe(node, kind, latency, burst, sys.argv[5])
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
