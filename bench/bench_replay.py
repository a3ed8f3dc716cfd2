"""Figure 5: bag replay throughput, as fast as possible, into CoCo ports and onto DDS topics.

The bag is a generated Baxter teleoperation session (``coco_ros.baxter.session.generate_session``);
two of its topics are replayed, ``/robot/joint_states`` (100 Hz, 21 joints) and ``/bowl/pose``
(30 Hz): joint states are 77 % of the messages. Every variant replays in a loop for as long as it is
measured; the figure is the steady-state rate over ``--window`` seconds, once the first message has
arrived and ``--warmup`` seconds have passed (so start-up and DDS discovery are not counted).

In one process:

- *floor*: the ``mcap`` library's reader + ``rclpy.serialization.deserialize_message`` of every
  message, nothing delivered: the least a replay that hands out messages must do;
- *CoCo BagReplay -> ports*: ``BagReplay`` (rate 0, loop) in a 1 ms periodic activity writes into a
  consumer component's BUFFER input that counts what it reads; ``output=coco`` (the converted
  ``JointStateSample`` / ``FramePose``, what the teleop app uses) and ``output=bag`` (the CDR bytes).

Over DDS, each publisher in its own process, received here (raw subscriptions, reliable, depth 100):

- *anchor*: a plain rclpy node as a user writes it by hand (this script with ``--plain-publisher``):
  ``mcap`` reader + ``deserialize_message`` + ``publish``;
- ``coco-replay --fast --loop`` (publishes the bag's CDR bytes, nothing deserialised);
- the ROS launcher running ``test/data/interop_replay.xml`` (BagReplay rate 0, loop ->
  ROSInterface publications): with ``output=coco`` every message is decoded, converted to a CoCo
  value and back to a message; with ``output=bag`` the recorded CDR passes through untouched.

Each DDS row also gives the publisher's CPU use (from /proc) and the receiver's: one rclpy
subscriber in Python receives at most some thousand messages per second, and when it is saturated
the publishers' messages per CPU-second are the figure that still compares them.

    .venv/bin/python bench/bench_replay.py [--rounds 3] [--window 3] [--json PATH] [--no-plot]
"""

from __future__ import annotations

import argparse
import signal
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import _report
from _ros import RosContext  # sets ROS_DOMAIN_ID before rclpy is imported
from _table import Table, fmt_ratio
from _timing import Samples

from coco_core.cpu import process_cpu

if str(_report.REPO / "coco_ros") not in sys.path:
    sys.path.insert(0, str(_report.REPO / "coco_ros"))

TOPICS = ("/robot/joint_states", "/bowl/pose")
DEPTH = 100
STAMP = struct.Struct("<iI")
REPLAY_PERIOD = 0.001
"""In-process BagReplay runs in a 1 ms periodic activity, as its docstring advises (up to
``max_per_update`` = 256 messages per update); a triggered one is never woken for its first update."""
INSTALLED = _report.REPO / "install" / "coco_ros" / "lib" / "coco_ros"
REPLAY_APP = _report.REPO / "test" / "data" / "interop_replay.xml"
FLOOR = "mcap + deserialize_message (floor, no delivery)"
ANCHOR = "plain rclpy node: mcap + deserialize + publish"
PORT_ROWS = ("CoCo BagReplay -> ports, output=coco", "CoCo BagReplay -> ports, output=bag")
DDS_ROWS = ("coco-replay --fast --loop", "ROS launcher: BagReplay -> ROSInterface",
            "ROS launcher: BagReplay output=bag -> ROSInterface (CDR passed through)")


# --- the anchor publisher, run as its own process -------------------------------------------------

def plain_publisher(mcap_path: str) -> int:
    """What a user writes by hand: read the MCAP, deserialise, publish, again and again until Ctrl-C."""
    import importlib

    import rclpy
    from mcap.reader import make_reader
    from rclpy.qos import QoSProfile
    from rclpy.serialization import deserialize_message
    from rclpy.signals import SignalHandlerOptions

    stopping: list[int] = []
    signal.signal(signal.SIGINT, lambda number, frame: stopping.append(number))  # checked per message
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("plain_replay")
    publishers: dict[str, Any] = {}
    classes: dict[str, type] = {}
    try:
        with open(mcap_path, "rb") as stream:
            reader = make_reader(stream)
            while not stopping:
                for schema, channel, message in reader.iter_messages(topics=list(TOPICS)):
                    if stopping:
                        break
                    topic = channel.topic
                    if topic not in publishers:
                        package, _, name = schema.name.partition("/msg/")
                        classes[topic] = getattr(importlib.import_module(f"{package}.msg"), name)
                        publishers[topic] = node.create_publisher(classes[topic], topic, QoSProfile(depth=DEPTH))
                    publishers[topic].publish(deserialize_message(message.data, classes[topic]))
        return 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


# --- in-process variants ------------------------------------------------------------------------

def floor_rate(mcap_path: Path, seconds: float) -> float:
    """Messages/s of mcap reading + deserialize_message, looping over the bag for ``seconds``."""
    from mcap.reader import make_reader
    from rclpy.serialization import deserialize_message
    from coco_ros.convert.base import message_class

    count = 0
    with open(mcap_path, "rb") as stream:
        reader = make_reader(stream)
        classes: dict[str, type] = {}
        start = time.perf_counter()
        deadline = start + seconds
        while time.perf_counter() < deadline:
            for schema, channel, message in reader.iter_messages(topics=list(TOPICS)):
                cls = classes.get(channel.topic) or classes.setdefault(channel.topic, message_class(schema.name))
                deserialize_message(message.data, cls)
                count += 1
        return count / (time.perf_counter() - start)


def ports_rate(bag: Path, output: str, warmup: float, window: float) -> float:
    """Messages/s that a consumer component reads from BagReplay (rate 0, loop) in steady state."""
    from coco_core.activity import PeriodicActivity, TriggeredActivity
    from coco_core.application import Application
    from coco_core.component import Component
    from coco_core.policy import BufferPolicy, ConnectionPolicy
    from coco_core.ports import InputPort
    from coco_ros.replay.component import BagReplay, port_name_for

    class Consumer(Component):
        """Counts every value it reads (and keeps the last one, to check what arrived)."""

        joints = InputPort(object, event=True)
        bowl = InputPort(object, event=True)

        def init(self) -> None:
            self.count = 0
            self.last: Any = None

        def on_update(self) -> None:
            for port in (self.joints, self.bowl):
                values = port.read_all()
                if values:
                    self.count += len(values)
                    self.last = values[-1]

    app = Application(f"bench_replay_{output}")
    app.add(BagReplay("replay", bag=bag, rate=0.0, loop=True, topics=list(TOPICS), output=output),
            PeriodicActivity("replaying", REPLAY_PERIOD))
    consumer = app.add(Consumer("consumer"), TriggeredActivity("consuming"))
    policy = ConnectionPolicy(BufferPolicy.BUFFER, size=4096)
    app.connect(f"replay.{port_name_for(TOPICS[0])}", "consumer.joints", policy)
    app.connect(f"replay.{port_name_for(TOPICS[1])}", "consumer.bowl", policy)
    app.start()
    try:
        time.sleep(warmup)
        first, start = consumer.count, time.perf_counter()
        time.sleep(window)
        rate = (consumer.count - first) / (time.perf_counter() - start)
    finally:
        app.stop()
    expected = "BagMessage" if output == "bag" else ("JointStateSample", "FramePose")
    if type(consumer.last).__name__ not in expected:
        raise AssertionError(f"output={output}: the consumer read {type(consumer.last).__name__} values")
    return rate


# --- DDS variants ---------------------------------------------------------------------------------

def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far (coco_core.cpu, from /proc), 0 once it is gone."""
    use = process_cpu(pid)
    return use.seconds if use is not None else 0.0


def stamp_ns(cdr: bytes) -> int:
    """Header stamp of a serialised message that starts with a std_msgs/Header (after the 4-byte CDR
    encapsulation: int32 sec, uint32 nanosec, little-endian as rosbag2 and Fast DDS write them)."""
    sec, nanosec = STAMP.unpack_from(cdr, 4)
    return sec * 1_000_000_000 + nanosec


def pass_positions(bag: Path) -> tuple[dict[int, int], int]:
    """Position in the replayed order (both topics) of every joint state, by its stamp; messages per pass."""
    from coco_ros.bag import BagReader

    positions: dict[int, int] = {}
    count = 0
    with BagReader(bag) as reader:
        for message in reader.messages(list(TOPICS)):
            if message.topic == TOPICS[0]:
                positions[stamp_ns(message.data)] = count
            count += 1
    return positions, count


@dataclass
class DdsRun:
    """One measured window of a publisher process."""

    rate: float
    """Messages/s the publisher put on DDS: its progress through the looping bag, read from the stamps
    of the joint states received (so messages the receiver lost still count)."""
    received_rate: float
    publisher_cpu: float
    """Cores the publisher used in the window (1.0 = one core busy)."""
    receiver_cpu: float
    received: dict[str, int] = field(default_factory=dict)


class Receiver:
    """Raw subscriptions to the replayed topics in this process.

    It counts what arrives, and follows the publisher through the looping bag: each joint state's
    stamp gives its position in a pass, a position lower than the previous one a new pass. When the
    Python receiver cannot keep up, DDS drops messages (keep-last) but the progress stays exact.
    """

    def __init__(self, context: Any, positions: dict[int, int], per_pass: int) -> None:
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from rclpy.qos import QoSProfile
        from geometry_msgs.msg import PoseStamped
        from sensor_msgs.msg import JointState

        self.node = Node("bench_replay_receiver", context=context)
        self.counts = dict.fromkeys(TOPICS, 0)
        self.positions, self.per_pass = positions, per_pass
        self.passes, self.last_position, self.progress, self.progress_time = 0, -1, 0, 0.0
        qos = QoSProfile(depth=DEPTH)
        self.node.create_subscription(JointState, TOPICS[0], self._on_joints, qos, raw=True)
        self.node.create_subscription(PoseStamped, TOPICS[1], self._on_bowl, qos, raw=True)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)

    def _on_joints(self, data: bytes) -> None:
        self.counts[TOPICS[0]] += 1
        position = self.positions[stamp_ns(data)]
        if position < self.last_position:
            self.passes += 1
        self.last_position = position
        self.progress = self.passes * self.per_pass + position
        self.progress_time = time.perf_counter()

    def _on_bowl(self, _: bytes) -> None:
        self.counts[TOPICS[1]] += 1

    def total(self) -> int:
        return sum(self.counts.values())

    def spin_for(self, seconds: float, until: Callable[[], bool] | None = None) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline and not (until and until()):
            self.executor.spin_once(timeout_sec=0.05)

    def measure(self, process: subprocess.Popen, warmup: float, window: float) -> DdsRun:
        """Wait for the first joint state (30 s at most), then ``warmup``, then measure during ``window``."""
        self.passes, self.last_position, self.progress, self.progress_time = 0, -1, 0, 0.0
        self.spin_for(30.0, until=lambda: self.progress_time > 0 or process.poll() is not None)
        if self.progress_time == 0:
            raise RuntimeError(f"no joint state from {process.args!r} (exit {process.poll()})")
        self.spin_for(warmup)
        before = dict(self.counts)
        progress0, time0 = self.progress, self.progress_time
        own0, pub0, start = time.process_time(), cpu_seconds(process.pid), time.perf_counter()
        self.spin_for(window)
        elapsed = time.perf_counter() - start
        received = {t: self.counts[t] - before[t] for t in TOPICS}
        if self.progress_time == time0:
            raise RuntimeError(f"no joint state from {process.args[1]} in the {window} s window "
                               f"(received {received}, exit {process.poll()})")
        return DdsRun((self.progress - progress0) / (self.progress_time - time0), sum(received.values()) / elapsed,
                      (cpu_seconds(process.pid) - pub0) / elapsed, (time.process_time() - own0) / elapsed, received)

    def drain(self) -> None:
        """Let what is still in flight arrive, so it is not counted in the next variant's window."""
        self.spin_for(0.5)

    def destroy(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()


def dds_commands(bag: Path, mcap_path: Path) -> dict[str, list[str]]:
    python = sys.executable
    return {
        ANCHOR: [python, str(Path(__file__).resolve()), "--plain-publisher", str(mcap_path)],
        DDS_ROWS[0]: [python, str(INSTALLED / "coco-replay"), str(bag), "--fast", "--loop", "--topics", *TOPICS,
                      "--delay", "0", "--depth", str(DEPTH), "--no-progress"],
        **{row: [python, str(INSTALLED / "launcher"), str(REPLAY_APP), f"bag:={bag}", "rate:=0", "loop:=true",
                 f"output:={output}", f"depth:={DEPTH}", "--duration", "120", "--log-level", "WARNING"]
           for row, output in ((DDS_ROWS[1], "coco"), (DDS_ROWS[2], "bag"))},
    }


def run_dds(receiver: Receiver, command: list[str], warmup: float, window: float) -> DdsRun:
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                               cwd=_report.REPO)
    try:
        return receiver.measure(process, warmup, window)
    finally:
        process.send_signal(signal.SIGINT)
        try:
            _, err = process.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()
            _, err = process.communicate()
        receiver.drain()
        if process.returncode not in (0, 130, -signal.SIGINT):
            print(f"warning: {command[1]} exited {process.returncode}: {err[-2000:]}", file=sys.stderr)


# --- report ---------------------------------------------------------------------------------------

def samples_of(name: str, rates: list[float]) -> Samples:
    """Rates as :class:`Samples` (ns per message), so paired ratios come from ``Samples.ratio_to``."""
    return Samples(name, [1e9 / r if r > 0 else float("inf") for r in rates], 0)


def median(values: list[float]) -> float:
    return statistics.median(values) if values else float("nan")


def table(rates: dict[str, list[float]], runs: dict[str, list[DdsRun]], args: Any, bag_info: str) -> Table:
    samples = {name: samples_of(name, values) for name, values in rates.items()}
    anchor, floor = samples[ANCHOR], samples[FLOOR]
    t = Table("Figure 5 - bag replay throughput, as fast as possible (messages/s, median of rounds)",
              ["variant", "messages/s", "vs plain rclpy node", "vs floor", "received/s", "publisher CPU",
               "msgs per pub CPU-s", "receiver CPU"])
    for name, s in samples.items():
        rate = 1e9 / s.median
        dds = runs.get(name, [])
        pub_cpu = median([r.publisher_cpu for r in dds])
        t.add(name, f"{rate:,.0f}", fmt_ratio(s.ratio_to(anchor)), fmt_ratio(s.ratio_to(floor)),
              f"{median([r.received_rate for r in dds]):,.0f}" if dds else "-",
              f"{pub_cpu:.0%}" if dds else "-", f"{rate / pub_cpu:,.0f}" if dds and pub_cpu > 0 else "-",
              f"{median([r.receiver_cpu for r in dds]):.0%}" if dds else "-")
    t.notes += [f"bag: {bag_info}; topics {', '.join(TOPICS)}; {args.rounds} rounds, variants interleaved, "
                f"{args.window:g} s window after {args.warmup:g} s warm-up; ratios are medians of per-round ratios "
                "(> 1: more messages/s than the reference).",
                "The first three rows run in this process (BagReplay in a 1 ms periodic activity). DDS rows: the "
                "publisher runs in its own process; 'messages/s' is its progress through the looping bag, read "
                "from the stamps of the joint states received here by one rclpy node (raw subscriptions, "
                f"reliable, keep-last {DEPTH}); 'received/s' is what that Python receiver took, less when it is "
                "saturated (receiver CPU near 100%: DDS drops the oldest). CPU figures: cores used in the window."]
    return t


def draw(rates: dict[str, list[float]]) -> Callable[[Any], Any]:
    def figure(plt: Any) -> Any:
        names = list(rates)
        values = [sorted(v)[len(v) // 2] for v in rates.values()]
        colors = ["tab:red" if n == ANCHOR else "tab:gray" if n == FLOOR else "tab:blue" for n in names]
        fig, ax = plt.subplots(figsize=(8, 3.8))
        ax.barh(names, values, color=colors)
        ax.invert_yaxis()
        for y, v in enumerate(values):
            ax.text(v * 1.01, y, f"{v:,.0f}", va="center", fontsize=8)
        ax.set_xlabel("messages per second (steady state, median of rounds)")
        ax.set_title("Bag replay as fast as possible: Baxter session (joint states + bowl pose)")
        ax.set_xlim(0, max(values) * 1.2)
        return fig

    return figure


def main() -> None:
    p = _report.parser("bench_replay", __doc__.splitlines()[0])
    p.add_argument("--rounds", type=int, default=3, help="measurements per variant (interleaved), default 3")
    p.add_argument("--window", type=float, default=3.0, help="seconds counted per measurement (default 3)")
    p.add_argument("--warmup", type=float, default=1.0, help="seconds skipped after the first message (default 1)")
    p.add_argument("--session", type=float, default=12.0, help="seconds of generated session (default 12)")
    p.add_argument("--plain-publisher", metavar="MCAP", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.plain_publisher:
        sys.exit(plain_publisher(args.plain_publisher))

    from coco_ros.baxter.session import generate_session

    with tempfile.TemporaryDirectory(prefix="bench_replay_") as tmp:
        bag = Path(tmp) / "session"
        info = generate_session(bag, duration=args.session)
        mcap_path = next(bag.glob("*.mcap"))
        per_pass = sum(info.counts.get(t, 0) for t in TOPICS)
        bag_info = (f"{args.session:g} s session, {per_pass} messages per pass "
                    f"({info.counts.get(TOPICS[0], 0)} joint states)")
        rates: dict[str, list[float]] = {FLOOR: [], **{n: [] for n in PORT_ROWS}, ANCHOR: [],
                                         **{n: [] for n in DDS_ROWS}}
        runs: dict[str, list[DdsRun]] = {ANCHOR: [], **{n: [] for n in DDS_ROWS}}
        commands = dds_commands(bag, mcap_path)
        with RosContext() as context:
            receiver = Receiver(context, *pass_positions(bag))
            try:
                for round_ in range(args.rounds):
                    rates[FLOOR].append(floor_rate(mcap_path, args.window))
                    for name, output in zip(PORT_ROWS, ("coco", "bag")):
                        rates[name].append(ports_rate(bag, output, args.warmup, args.window))
                    names = [ANCHOR, *DDS_ROWS]
                    for name in names[round_ % 3:] + names[:round_ % 3]:
                        run = run_dds(receiver, commands[name], args.warmup, args.window)
                        rates[name].append(run.rate)
                        runs[name].append(run)
                    print(f"round {round_ + 1}/{args.rounds}: " + ", ".join(f"{n}: {v[-1]:,.0f}/s"
                                                                           for n, v in rates.items()), flush=True)
            finally:
                receiver.destroy()
    t = table(rates, runs, args, bag_info)
    results = {name: {"messages_per_s": values,
                      "dds": [vars(r) for r in runs.get(name, [])]} for name, values in rates.items()}
    _report.emit("bench_replay", args, [t], results)
    _report.save_plot(args, draw(rates))


if __name__ == "__main__":
    main()
