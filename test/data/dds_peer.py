"""A plain rclpy publisher or subscriber, run inside a simulated host by ``test/test_netns.py``.

    python dds_peer.py pub TOPIC COUNT     # waits for a subscriber, publishes 0..COUNT-1, waits for every ack
    python dds_peer.py sub TOPIC COUNT     # prints one JSON line: the numbers received, in order

Both reliable, keep last COUNT: every number must arrive, however lossy the link. Each side gives up
after TIMEOUT_S (exit status 2) so that a broken link fails the test instead of hanging it.
"""

from __future__ import annotations

import json
import sys
import time

import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import UInt32

TIMEOUT_S = 20.0


def main() -> int:
    role, topic, count = sys.argv[1], sys.argv[2], int(sys.argv[3])
    rclpy.init()
    node = rclpy.create_node(f"netns_{role}")
    qos = QoSProfile(depth=count, reliability=ReliabilityPolicy.RELIABLE)
    deadline = time.monotonic() + TIMEOUT_S
    if role == "pub":
        publisher = node.create_publisher(UInt32, topic, qos)
        while publisher.get_subscription_count() == 0:
            if time.monotonic() > deadline:
                print("no subscriber matched", file=sys.stderr)
                return 2
            rclpy.spin_once(node, timeout_sec=0.05)
        for number in range(count):
            publisher.publish(UInt32(data=number))
            time.sleep(0.002)  # a sensor's rate, not a burst: the lossy link's repair is what is tested
        if not publisher.wait_for_all_acked(rclpy.duration.Duration(seconds=deadline - time.monotonic())):
            print("not every sample was acknowledged", file=sys.stderr)
            return 2
        return 0
    received: list[int] = []

    def arrived(message: UInt32) -> None:
        received.append(message.data)

    node.create_subscription(UInt32, topic, arrived, qos)
    while len(received) < count and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
    print(json.dumps(received), flush=True)
    return 0 if len(received) >= count else 2


if __name__ == "__main__":
    sys.exit(main())
