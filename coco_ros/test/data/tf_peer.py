"""A plain rclpy node in its own process, the other side of the TF bridge's interoperability tests.

``talker``: publishes ``world -> camera`` once on /tf_static (latched, as tf2's static broadcaster)
and ``world -> marker`` on /tf at 20 Hz (stamp 1000 + n s + 0.25 s, x = 0.01 n, yaw = 0.1 n), until
interrupted; prints ``static sent`` once the static transform is out.

``listener``: publishes a Baxter JointState (``--joints name=value ...``) at 20 Hz on
/robot/joint_states, receives /tf and /tf_static (transient local: it may join late), and
``--seconds`` after its first /tf_static message writes what it received to ``--output`` (JSON:
the newest /tf transform per child frame, every /tf_static message) and exits.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import rclpy
from geometry_msgs.msg import TransformStamped
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import JointState
from tf2_msgs.msg import TFMessage

STATIC_CAMERA = {"translation": (0.5, -0.2, 1.25), "rotation": (0.0, 0.0, math.sin(0.3), math.cos(0.3))}
"""world -> camera: 0.6 rad about z."""

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
LATCHED_LISTENER = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL)
TF = QoSProfile(depth=100)


def transform(parent: str, child: str, translation, rotation, sec: int = 0, nanosec: int = 0) -> TransformStamped:
    t = TransformStamped()
    t.header.frame_id, t.child_frame_id = parent, child
    t.header.stamp.sec, t.header.stamp.nanosec = sec, nanosec
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = translation
    r = t.transform.rotation
    r.x, r.y, r.z, r.w = rotation
    return t


def as_dict(t: TransformStamped) -> dict:
    tr, r = t.transform.translation, t.transform.rotation
    return {"parent": t.header.frame_id, "child": t.child_frame_id,
            "stamp": [t.header.stamp.sec, t.header.stamp.nanosec],
            "translation": [tr.x, tr.y, tr.z], "rotation": [r.x, r.y, r.z, r.w]}


def talker(node) -> None:
    static = node.create_publisher(TFMessage, "/tf_static", LATCHED)
    static.publish(TFMessage(transforms=[transform("world", "camera", STATIC_CAMERA["translation"],
                                                   STATIC_CAMERA["rotation"])]))
    print("static sent", flush=True)
    moving = node.create_publisher(TFMessage, "/tf", TF)
    n = 0
    while rclpy.ok(context=node.context):
        yaw = 0.1 * n
        moving.publish(TFMessage(transforms=[transform("world", "marker", (0.01 * n, 0.0, 0.5),
                                                       (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)),
                                                       1000 + n, 250_000_000)]))
        n += 1
        time.sleep(0.05)


def listener(node, joints: dict[str, float], seconds: float, output: str) -> None:
    newest: dict[str, dict] = {}
    static: list[list[dict]] = []
    counts = {"tf": 0}

    def on_tf(msg: TFMessage) -> None:
        counts["tf"] += 1
        for t in msg.transforms:
            newest[t.child_frame_id] = as_dict(t)

    node.create_subscription(TFMessage, "/tf", on_tf, TF)
    node.create_subscription(TFMessage, "/tf_static", lambda msg: static.append([as_dict(t) for t in msg.transforms]),
                             LATCHED_LISTENER)
    publisher = node.create_publisher(JointState, "/robot/joint_states", QoSProfile(depth=10))
    state = JointState(name=list(joints), position=list(joints.values()))
    first_static = None
    deadline = time.monotonic() + 25
    while time.monotonic() < deadline:
        state.header.stamp = node.get_clock().now().to_msg()
        publisher.publish(state)
        end = time.monotonic() + 0.05
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.01)
        if static and first_static is None:
            first_static = time.monotonic()
        if first_static is not None and time.monotonic() - first_static >= seconds:
            break
    with open(output, "w") as handle:
        json.dump({"tf": newest, "tf_static": static, "tf_messages": counts["tf"], "wall_time": time.time()}, handle)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mode", choices=("talker", "listener"))
    parser.add_argument("--joints", nargs="*", default=[], help="name=value joint positions (listener)")
    parser.add_argument("--seconds", type=float, default=3.0, help="listen this long after /tf_static arrived")
    parser.add_argument("--output", default="tf_peer.json")
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node(f"tf_peer_{args.mode}")
    try:
        if args.mode == "talker":
            talker(node)
        else:
            joints = {name: float(value) for name, value in (item.split("=") for item in args.joints)}
            listener(node, joints, args.seconds, args.output)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
