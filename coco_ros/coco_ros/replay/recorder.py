"""``BagRecorder``: a CoCo component writing its input ports into a rosbag2 bag (MCAP + metadata.yaml).

Attributes:

- ``folder``: the new bag folder (must not exist, or be empty); the file is ``<folder>_0.mcap``.
- ``topics``: ``port=/topic:pkg/msg/Type`` items, one input port per item, e.g.
  ``joints=/joint_states:sensor_msgs/msg/JointState``.
- ``time``: the log time of each message: ``receive`` (default: when this component read it, as
  rosbag2 does), ``stamp`` (the value's ``stamp`` in seconds when it has one, else receive),
  ``bag`` (for :class:`~coco_ros.bag.BagMessage` values: their original log time).
- ``compression``: ``none``, ``zstd`` or ``lz4``.

What a port accepts: a CoCo value of the type's converter (``converter.to_ros`` makes the message),
an rclpy message of the type, raw CDR ``bytes``, or a ``BagMessage`` (its CDR bytes are written as they
are). Connect the ports with BUFFER (or CIRCULAR) connections large enough for one update period:
a DATA connection keeps only the latest value. Put the recorder in a periodic activity (10-100 ms),
or a triggered one with event ports.

Nothing is lost on a clean stop (Ctrl-C in the launcher, ``--duration``, ``stop_at_end``): ``on_stop``
drains the ports and closes the bag. The writer flushes every second, so a killed process loses at
most the last second.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import CocoError, ReplayError
from coco_core.ports import InputPort
from coco_core.stamps import unstamped

from ..bag import BagMessage, BagWriter
from ..bag.message_types import normalize_type

log = logging.getLogger("coco.replay")


def parse_topic_spec(item: str) -> tuple[str, str, str]:
    """``port=/topic:pkg/msg/Type`` -> (port, topic, type)."""
    port, sep, rest = item.partition("=")
    topic, sep2, type_name = rest.rpartition(":")
    if not sep or not sep2 or not port.strip() or not topic.strip().startswith("/") or not type_name.strip():
        raise ReplayError(f"expected 'port=/topic:pkg/msg/Type', got {item!r}")
    return port.strip(), topic.strip(), normalize_type(type_name.strip())


class BagRecorder(Component):
    """Records its input ports into a rosbag2 bag; see the module docstring."""

    folder = Attribute(Path, Path(""), "new bag folder")
    topics: Attribute[list[str]] = Attribute(list[str], [], "'port=/topic:pkg/msg/Type' items, one input port each")
    time = Attribute(str, "receive", "log time: receive, stamp or bag", choices=("receive", "stamp", "bag"))
    compression = Attribute(str, "none", "chunk compression", choices=("none", "zstd", "lz4"))

    def init(self) -> None:
        if not str(self.folder) or str(self.folder) == ".":
            raise CocoError(f"component {self.name}: attribute 'folder' is required (the new bag folder)")
        if not self.topics:
            raise CocoError(f"component {self.name}: attribute 'topics' lists no 'port=/topic:pkg/msg/Type'")
        from ..convert import converter_for

        self._routes: list[tuple[InputPort, str, str, Any]] = []
        for item in self.topics:
            try:
                port_name, topic, type_name = parse_topic_spec(item)
            except ValueError as error:
                raise CocoError(f"component {self.name}: attribute topics: {error}") from None
            try:
                converter = converter_for(type_name)
                port_type = object  # CoCo values, rclpy messages, bytes or BagMessages are all accepted
            except (ValueError, ImportError):
                converter = None
                port_type = object
            port = self.add_input(port_name, port_type, doc=f"recorded as {topic} ({type_name})")
            self._routes.append((port, topic, type_name, converter))
        self._writer: BagWriter | None = None

    def on_config(self) -> None:
        self._writer = BagWriter(self.folder, compression=self.compression)
        for _, topic, type_name, _ in self._routes:
            if topic not in self._writer.topic_counts():
                self._writer.add_topic(topic, type_name)
        log.info("component %s: recording %d topics into %s", self.name, len(self._routes), self.folder)

    def on_update(self) -> None:
        writer = self._writer
        if writer is None:
            return
        for port, topic, type_name, converter in self._routes:
            for value in port.read_all():
                self._write(writer, topic, type_name, converter, value)

    def _write(self, writer: BagWriter, topic: str, type_name: str, converter: Any, value: Any) -> None:
        now = time.time_ns()
        value, _ = unstamped(value)  # a Stamped value is recorded as its value (the stamp is the latency's)
        if isinstance(value, BagMessage):
            log_time = value.log_time if self.time == "bag" else now
            writer.write(topic, value.data, log_time, type_name)
            return
        log_time = now
        if self.time == "stamp":
            stamp = getattr(value, "stamp", None)
            exact = getattr(stamp, "nanoseconds", None)  # a RosTime keeps the message's exact stamp
            if isinstance(exact, int) and exact > 0:
                log_time = exact
            elif isinstance(stamp, (int, float)) and stamp > 0:
                log_time = int(round(float(stamp) * 1e9))
        if isinstance(value, (bytes, bytearray, memoryview)):
            writer.write(topic, bytes(value), log_time, type_name)
        elif hasattr(type(value), "get_fields_and_field_types") or hasattr(value, "transforms"):
            writer.write(topic, value, log_time, type_name)
        elif converter is not None:
            writer.write(topic, converter.to_ros(value), log_time, type_name)
        else:
            raise CocoError(f"component {self.name}: {topic} ({type_name}) has no converter; send rclpy "
                            f"messages, CDR bytes or BagMessages, got {type(value).__name__}")

    def on_stop(self) -> None:
        if self._writer is None:
            return
        try:
            self.on_update()  # what arrived since the last update
        finally:
            folder = self._writer.close()
            log.info("component %s: bag %s closed (%d messages)", self.name, folder, self._writer.message_count)
