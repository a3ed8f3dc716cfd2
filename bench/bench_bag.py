"""Figure 6: reading and decoding a rosbag2 bag with many topics, CoCo's BagReader against rosbags.

The bag: 20 s of a mobile robot with a camera, six topics, 9,504 messages, 15 MB (zstd chunks):
``/tf`` (100 Hz, 2 transforms), ``/odom`` (50 Hz), ``/imu`` (200 Hz), ``/joint_states`` (100 Hz, 19
joints), ``/scan`` (10 Hz, 360 ranges), ``/camera/image`` (15 Hz, 320x240 rgb8). It is written twice
with the same CDR bytes: by the project's ``BagWriter`` and by ``rosbags``' own MCAP writer
(``rosbags.rosbag2.Writer``), so neither reader reads only its own library's files; and a third time
by rosbags into SQLite storage (one ``.db3``, what Humble and Iron record and librealsense writes).

Variants, each a whole pass over the bag, per message (interleaved rounds, median):

- *anchor*: ``rosbags`` ``Reader.messages()`` + ``typestore.deserialize_cdr`` of every message;
- *CoCo BagReader + message*: ``BagReader.messages()`` + ``BagMessage.message``: the rclpy message
  a node or a converter gets (made by the decoder generated per type, ``coco_ros.bag.cdr_decoder``,
  equal to rclpy's ``deserialize_message``);
- *no decoding*: both readers handing out the CDR bytes only (what a replay to DDS, ``coco-replay``
  and ``BagReplay output=bag``, needs);
- 6c, ``/joint_states`` and ``/tf`` alone into what a consumer uses: rosbags' messages against
  CoCo's ``JointSample`` and ``TransformSample`` values read straight from the CDR bytes
  (``Converter.from_cdr``, what ``BagReplay output=coco`` does) and through rclpy messages.

Goal (issue 12): CoCo reading + decoding at least as fast as rosbags.

    .venv/bin/python bench/bench_bag.py [--rounds 5] [--json PATH] [--no-plot]
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

import _report
from _table import Table, fmt_ratio, fmt_time_ns, verdict

ANCHOR = "rosbags Reader + deserialize_cdr"
COCO = "CoCo BagReader + message (rclpy)"
COCO_RAW = "CoCo BagReader, no decoding"
CONVERTED = {"/joint_states": "sensor_msgs/msg/JointState", "/tf": "tf2_msgs/msg/TFMessage"}
"""The topics of figure 6c and their types: the ones a CoCo application turns into graph input."""
JS_ANCHOR = "rosbags Reader + deserialize_cdr"
JS_CDR = "CoCo BagReader + converter.from_cdr"
JS_RCLPY = "CoCo BagReader + rclpy message + to_coco"
ANCHOR_RAW = "rosbags Reader, no decoding"
SQLITE = "rosbags Writer into SQLite (.db3)"
T0 = 1_700_000_000_000_000_000
SECONDS = 20


def write_bag(folder: Path) -> Path:
    """The robot bag, written with BagWriter (see the module docstring)."""
    import numpy as np
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import TransformStamped
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import Image, Imu, JointState, LaserScan
    from std_msgs.msg import Header
    from tf2_msgs.msg import TFMessage

    from coco_ros.bag import BagWriter

    def header(t: int, frame: str) -> Header:
        return Header(stamp=Time(sec=t // 10**9, nanosec=t % 10**9), frame_id=frame)

    pixels = bytes(np.random.default_rng(0).integers(0, 255, 320 * 240 * 3, dtype=np.uint8))
    names = [f"joint_{k}" for k in range(19)]
    path = folder / "coco_writer"
    with BagWriter(path, compression="zstd") as writer:
        for i in range(SECONDS * 1000):
            t = T0 + i * 1_000_000
            if i % 10 == 0:
                writer.write("/tf", TFMessage(transforms=[
                    TransformStamped(header=header(t, "odom"), child_frame_id="base_link"),
                    TransformStamped(header=header(t, "map"), child_frame_id="odom")]), t)
            if i % 20 == 0:
                writer.write("/odom", Odometry(header=header(t, "odom"), child_frame_id="base_link"), t)
            if i % 5 == 0:
                writer.write("/imu", Imu(header=header(t, "imu_link")), t)
            if i % 10 == 5:
                writer.write("/joint_states", JointState(header=header(t, ""), name=names,
                                                         position=[0.1 * k + i * 1e-4 for k in range(19)]), t)
            if i % 100 == 0:
                writer.write("/scan", LaserScan(header=header(t, "laser"), ranges=[1.0] * 360), t)
            if i % 66 == 0:
                writer.write("/camera/image", Image(header=header(t, "camera"), height=240, width=320,
                                                    encoding="rgb8", step=960, data=pixels), t)
    return path


def copy_with_rosbags(source: Path, folder: Path, storage: str = "MCAP") -> Path:
    """The same messages (CDR bytes, times, QoS-free connections) written by rosbags' writer, in its
    ``storage`` plugin (MCAP or SQLITE3)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    from coco_ros.bag import BagReader

    store = get_typestore(Stores.ROS2_JAZZY)
    path = folder / f"rosbags_writer_{storage.lower()}"
    with BagReader(source) as reader, Writer(path, version=9, storage_plugin=StoragePlugin[storage]) as writer:
        connections = {name: writer.add_connection(name, info.type, typestore=store)
                       for name, info in reader.topics.items()}
        for message in reader.messages():
            writer.write(connections[message.topic], message.log_time, message.data)
    return path


def variants(path: Path) -> dict[str, Callable[[], int]]:
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    from coco_ros.bag import BagReader

    store = get_typestore(Stores.ROS2_JAZZY)

    def anchor() -> int:
        count = 0
        deserialize = store.deserialize_cdr
        with Reader(path) as reader:
            for connection, _, raw in reader.messages():
                deserialize(raw, connection.msgtype)
                count += 1
        return count

    def anchor_raw() -> int:
        count = 0
        with Reader(path) as reader:
            for _ in reader.messages():
                count += 1
        return count

    def coco() -> int:
        count = 0
        with BagReader(path) as reader:
            for message in reader.messages():
                message.message
                count += 1
        return count

    def coco_raw() -> int:
        count = 0
        with BagReader(path) as reader:
            for _ in reader.messages():
                count += 1
        return count

    return {ANCHOR: anchor, COCO: coco, ANCHOR_RAW: anchor_raw, COCO_RAW: coco_raw}


def joint_variants(path: Path) -> dict[str, Callable[[], int]]:
    """/joint_states and /tf alone, into what a consumer uses: rosbags' messages, CoCo's values."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    from coco_ros.bag import BagReader
    from coco_ros.convert import converter_for

    store = get_typestore(Stores.ROS2_JAZZY)
    converters = {topic: converter_for(type_name) for topic, type_name in CONVERTED.items()}

    def anchor() -> int:
        count = 0
        with Reader(path) as reader:
            connections = [c for c in reader.connections if c.topic in CONVERTED]
            for connection, _, raw in reader.messages(connections=connections):
                store.deserialize_cdr(raw, connection.msgtype)
                count += 1
        return count

    def from_cdr() -> int:
        count = 0
        with BagReader(path) as reader:
            for message in reader.messages(list(CONVERTED)):
                converters[message.topic].from_cdr(message.data)
                count += 1
        return count

    def through_rclpy() -> int:
        count = 0
        with BagReader(path) as reader:
            for message in reader.messages(list(CONVERTED)):
                converters[message.topic].to_coco(message.message)
                count += 1
        return count

    return {JS_ANCHOR: anchor, JS_CDR: from_cdr, JS_RCLPY: through_rclpy}


def measure(passes: dict[str, Callable[[], int]], rounds: int) -> dict[str, list[float]]:
    """ns per message of each variant, one value per round, the order rotated per round."""
    names = list(passes)
    counts = {name: passes[name]() for name in names}  # warm-up: imports, type support, page cache
    assert len(set(counts.values())) == 1, f"the readers disagree on the message count: {counts}"
    per_message: dict[str, list[float]] = {name: [] for name in names}
    for round_ in range(rounds):
        shift = round_ % len(names)
        for name in names[shift:] + names[:shift]:
            start = time.perf_counter_ns()
            passes[name]()
            per_message[name].append((time.perf_counter_ns() - start) / counts[name])
    return per_message


def main() -> None:
    parser = _report.parser("bench_bag", __doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_bag_") as tmp:
        ours = write_bag(Path(tmp))
        theirs = copy_with_rosbags(ours, Path(tmp))
        sqlite = copy_with_rosbags(ours, Path(tmp), "SQLITE3")
        size = sum(f.stat().st_size for f in ours.glob("*.mcap"))
        with _report.LoadMeter() as load:
            results = {"BagWriter": measure(variants(ours), args.rounds),
                       "rosbags Writer": measure(variants(theirs), args.rounds),
                       SQLITE: measure(variants(sqlite), args.rounds)}
            joints = measure(joint_variants(ours), args.rounds)
    others = "n/a" if load.others is None else f"{load.others:.0%}"
    tables, document = [], {}
    for writer, samples in results.items():
        table = Table(f"Figure 6 - bag written by {writer}: read + decode, per message (median of "
                      f"{args.rounds} rounds)",
                      ["variant", "time/message", "messages/s", "vs rosbags (x faster)", "goal >= rosbags"])
        document[writer] = {}
        for name, values in samples.items():
            median = statistics.median(values)
            anchor = ANCHOR if "decod" not in name else ANCHOR_RAW
            ratio = statistics.median(a / v for a, v in zip(samples[anchor], values))
            ok = ratio >= 1.0 if name == COCO else None
            table.add(name, fmt_time_ns(median), f"{1e9 / median:,.0f}", fmt_ratio(ratio), verdict(ok))
            document[writer][name] = {"median_ns": median, "per_message_ns": values,
                                      "x_faster_than_rosbags": ratio, "goal_met": ok}
        chunks = {"BagWriter": "zstd chunks", SQLITE: "SQLite storage, one .db3 file"}.get(
            writer, "uncompressed chunks, rosbags' default")
        checks = ("both read the messages table in timestamp order through SQLite" if writer == SQLITE else
                  "BagReader checks every chunk's CRC (about 4.6 us per message of the uncompressed file), "
                  "rosbags does not")
        table.notes.append(f"9,504 messages on 6 topics ({chunks}; {size / 1e6:.0f} MB with zstd); no-decoding "
                           f"rows compare with rosbags' no-decoding row; {checks}; other "
                           f"processes used {others} of the {_report.machine()['cpus']} cores meanwhile.")
        tables.append(table)
    table = Table(f"Figure 6c - /joint_states and /tf alone (4,000 messages, BagWriter bag) into what a "
                  f"consumer uses, per message (median of {args.rounds} rounds)",
                  ["variant", "time/message", "messages/s", "vs rosbags (x faster)", "goal >= rosbags"])
    document["joint_states"] = {}
    for name, values in joints.items():
        median = statistics.median(values)
        ratio = statistics.median(a / v for a, v in zip(joints[JS_ANCHOR], values))
        ok = ratio >= 1.0 if name == JS_CDR else None
        table.add(name, fmt_time_ns(median), f"{1e9 / median:,.0f}", fmt_ratio(ratio), verdict(ok))
        document["joint_states"][name] = {"median_ns": median, "per_message_ns": values,
                                          "x_faster_than_rosbags": ratio, "goal_met": ok}
    table.notes.append("from_cdr reads the CDR bytes into a JointStateSample (its arrays views of the bytes) and "
                       "TransformSamples (4x4 matrices), what BagReplay output=coco delivers; rosbags gives its "
                       "JointState and TFMessage dataclasses; the chunks also hold the other topics' messages, "
                       "which both readers must decompress.")
    tables.append(table)
    _report.emit("bench_bag", args, tables, {"per_writer": document, "others_cpu": load.others})
    _report.save_plot(args, lambda plt: draw(plt, results))


def draw(plt: Any, results: dict[str, dict[str, list[float]]]) -> Any:
    fig, axes = plt.subplots(1, len(results), figsize=(15, 3.6), sharey=True)
    for ax, (writer, samples) in zip(axes, results.items()):
        names = list(samples)
        values = [statistics.median(samples[n]) / 1e3 for n in names]
        colors = ["tab:red" if n.startswith("rosbags") else "tab:blue" for n in names]
        ax.barh(names, values, color=colors)
        ax.invert_yaxis()
        for y, v in enumerate(values):
            ax.text(v, y, f" {v:.1f} us", va="center", fontsize=8)
        ax.set_title(f"bag written by {writer}", fontsize=10)
        ax.set_xlabel("time per message (us)")
        ax.set_xlim(0, max(values) * 1.35)
        ax.tick_params(axis="y", labelsize=8)
    fig.suptitle("Reading + decoding a 6-topic bag (MCAP, SQLite): CoCo BagReader vs rosbags (one process)")
    fig.tight_layout()
    return fig


if __name__ == "__main__":
    main()
