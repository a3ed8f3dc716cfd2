"""``coco-replay``: republish a rosbag2 MCAP bag on ROS topics (as ``ros2 bag play``), with rclpy.

The CDR bytes of the bag are published as they are (``publisher.publish(bytes)``), nothing is
deserialized; each topic is offered the QoS its recorded publishers offered, history depth included
(:func:`coco_ros.bag.qos.for_replay`; ``--depth`` overrides the depth). ``--fast`` offers volatile
topics with KEEP_ALL history, so the publisher overwrites nothing before every reliable subscriber
has it, and topics whose messages a reliable subscriber did not acknowledge by the end are reported;
it also names, at the start and in the final report, each matched subscriber whose own history may
be shallower than a topic's count (what it cannot take in time, it overwrites unseen), with what to
do (:mod:`coco_ros.replay.flow`). ``/tf`` and ``/tf_static`` are published like any other
topic (tf2_msgs is built in the workspace, ``vendor/tf2_msgs``). Exit status: 0, or 1 with the
error (file and byte offset) when the bag is damaged, after replaying what was readable; Ctrl-C
stops within a fraction of a second.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence

from coco_core.errors import BagError

from ..bag import BagReader
from ..bag.qos import for_replay
from .flow import ACK_TIMEOUT, SHALLOW_ADVICE, as_fast_as_possible, merged, shallow_subscribers, unacknowledged
from .player import Player, parse_remaps


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="coco-replay", description=__doc__.split("\n\n")[0])
    parser.add_argument("bag", help="bag folder or .mcap file")
    speed = parser.add_mutually_exclusive_group()
    speed.add_argument("--rate", "-r", type=float, default=1.0, help="speed factor (default 1)")
    speed.add_argument("--fast", action="store_true", help="as fast as possible")
    parser.add_argument("--loop", "-l", action="store_true", help="replay again after the end")
    parser.add_argument("--start", "-s", type=float, default=0.0, metavar="S", help="start offset (s)")
    parser.add_argument("--duration", "-d", type=float, default=None, metavar="D", help="seconds per pass")
    parser.add_argument("--topics", nargs="+", default=None, metavar="TOPIC", help="topics to replay")
    parser.add_argument("--remap", nargs="+", default=[], metavar="FROM:=TO", help="topic remappings")
    parser.add_argument("--clock", type=float, default=0.0, metavar="HZ", help="publish /clock at HZ")
    parser.add_argument("--delay", type=float, default=1.0, metavar="S",
                        help="seconds to wait after creating the publishers, for discovery (default 1)")
    parser.add_argument("--wait-subscribers", type=int, default=0, metavar="N",
                        help="wait (up to 10 s) until N subscriptions are matched in total, instead of --delay")
    parser.add_argument("--depth", type=int, default=None,
                        help="publisher history depth (default: the recorded one of each topic)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        reader = BagReader(args.bag)
    except BagError as error:
        print(f"coco-replay: error: {error}", file=sys.stderr)
        return 1
    try:
        player = Player(reader, rate=0.0 if args.fast else args.rate, start_offset=args.start,
                        duration=args.duration, loop=args.loop, topics=args.topics,
                        remap=parse_remaps(args.remap))
    except (BagError, ValueError) as error:
        print(f"coco-replay: error: {error}", file=sys.stderr)
        return 1
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)  # Ctrl-C stays a KeyboardInterrupt
    node = rclpy.create_node("coco_replay")
    try:
        return _replay(args, reader, player, node)
    except KeyboardInterrupt:
        player.stop()
        print("\ncoco-replay: interrupted", file=sys.stderr)
        return 130
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        reader.close()


def _publishers(reader: BagReader, player: Player, node, depth: int | None, fast: bool) -> dict:
    publishers, skipped = {}, []
    for topic in player.topics:
        info = reader.topics[topic]
        try:
            cls = reader.message_class(topic)
        except BagError as error:
            skipped.append(f"{topic} ({error.detail})")
            continue
        offered = for_replay(info.offered_qos_profiles, depth=depth)
        if fast and depth is None:
            offered = as_fast_as_possible(offered)
        publishers[topic] = node.create_publisher(cls, player.out_topic(topic), offered.to_rclpy())
    if skipped:
        print("coco-replay: warning: not replaying " + "; ".join(skipped), file=sys.stderr)
    return publishers


def _replay(args, reader: BagReader, player: Player, node) -> int:
    publishers = _publishers(reader, player, node, args.depth, args.fast)
    if not publishers:
        damage = "; ".join(str(error) for error in reader.errors)
        why = f": the bag is damaged: {damage}" if damage else ""
        print(f"coco-replay: error: {reader.path}: no topic can be published{why}", file=sys.stderr)
        return 1
    _wait_for_discovery(args, publishers)
    counts = {player.out_topic(topic): reader.topics[topic].message_count for topic in publishers}
    shallow = shallow_subscribers(node, counts) if args.fast else []
    if shallow:
        print("coco-replay: warning: --fast sends each topic as fast as possible, faster than a subscriber may "
              "take it, and a subscriber with a KEEP_LAST history keeps only its last messages: "
              f"{'; '.join(s.describe() for s in shallow)}; {SHALLOW_ADVICE}", file=sys.stderr)
    clock_publish = _clock_publisher(node, player, args.clock)
    progress = None
    if not args.no_progress:
        from tqdm import tqdm

        start, end = player.progress()
        progress = tqdm(total=round(end, 3), unit="s", desc=str(reader.path.name), leave=True,
                        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.2f}/{total:.2f} s [{elapsed}]")
    count = 0
    last_bar = 0.0
    for played in player.iterate(idle=clock_publish):
        publisher = publishers.get(played.message.topic)
        if publisher is None:
            continue
        publisher.publish(played.message.data)
        count += 1
        clock_publish()
        if progress is not None and time.monotonic() - last_bar > 0.1:
            last_bar = time.monotonic()
            progress.n = round(player.progress()[0], 3)
            progress.refresh()
    if progress is not None:
        progress.n = round(player.progress()[0], 3)
        progress.close()
    late = unacknowledged(publishers)
    print(f"coco-replay: {count} messages published from {reader.path}", file=sys.stderr)
    if args.fast:  # those seen at the start, and those that joined during the replay
        shallow = merged(shallow, shallow_subscribers(node, counts))
        if shallow:
            print("coco-replay: warning: sent as fast as possible to subscribers whose history may be shallower "
                  f"than what they were sent, so they may have lost messages: "
                  f"{'; '.join(s.describe() for s in shallow)}; {SHALLOW_ADVICE}", file=sys.stderr)
    if late:
        print(f"coco-replay: warning: a reliable subscriber of {', '.join(late)} did not acknowledge every "
              f"message within {ACK_TIMEOUT:g} s after the end (gone or stuck): the last messages may be lost "
              "to it", file=sys.stderr)
    if player.errors:
        for error in player.errors:
            print(f"coco-replay: error: {error}", file=sys.stderr)
        return 1
    return 0


def _wait_for_discovery(args, publishers: dict) -> None:
    if args.wait_subscribers > 0:
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            if sum(p.get_subscription_count() for p in publishers.values()) >= args.wait_subscribers:
                time.sleep(0.1)  # let the subscription side match too
                return
            time.sleep(0.02)
        print(f"coco-replay: warning: fewer than {args.wait_subscribers} subscriptions after 10 s; "
              "replaying anyway", file=sys.stderr)
    elif args.delay > 0:
        time.sleep(args.delay)


def _clock_publisher(node, player: Player, hz: float):
    if hz <= 0:
        return lambda: None
    from rclpy.qos import QoSProfile
    from rosgraph_msgs.msg import Clock

    publisher = node.create_publisher(Clock, "/clock", QoSProfile(depth=1))
    period = 1.0 / hz
    state = {"next": 0.0}

    def publish() -> None:
        now = time.monotonic()
        if now >= state["next"]:
            state["next"] = now + period
            ns = player.clock.now()
            message = Clock()
            message.clock.sec, message.clock.nanosec = divmod(ns, 1_000_000_000)
            publisher.publish(message)

    return publish


if __name__ == "__main__":
    sys.exit(main())
