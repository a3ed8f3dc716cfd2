"""``BagReplay``: a CoCo component that replays a rosbag2 bag into output ports (no DDS).

Attributes (all settable from the application XML):

- ``bag``: the bag folder or ``.mcap`` file.
- ``rate``: speed factor (1 = real time, 2 = twice as fast); ``0``: as fast as possible.
- ``start_offset``: seconds after the bag start where each pass begins.
- ``duration``: seconds replayed per pass; ``0``: to the end.
- ``loop``: replay again from ``start_offset`` after the end.
- ``topics``: the bag topics to replay (empty: all).
- ``remap``: ``/from:=/to`` items; the port names follow the remapped topics.
- ``ports``: ``/topic=port`` items naming the port of a (remapped) topic; the others get a name
  derived from the topic, ``/robot/joint_states`` -> ``robot_joint_states``.
- ``options``: ``/topic;key=value[;key=value...]`` items giving the converter of a (remapped) topic
  its options, in the syntax of ROSInterface's topic specs (:mod:`coco_ros.interface.topic`), e.g.
  ``/bowl/pose;child_frame=bowl``: the PoseStamped becomes a FramePose ``base -> bowl`` that a
  TransformationInterface writes into the graph as an edge. Only with ``output`` ``coco``.
- ``output``: what the ports carry. ``coco`` (default): the converter's CoCo value
  (:func:`coco_ros.convert.converter_for`, port type ``converter.coco_type``), and for a type without
  converter the deserialized rclpy message (port type ``object``); ``/tf`` and ``/tf_static``
  become lists of ``TransformSample`` (tf2_msgs' converter), those of ``/tf_static`` (any latched
  TFMessage topic) marked ``static``: a TransformationInterface makes them static edges, as TFBridge
  does, whatever their stamp (0 is usual). ``ros``: always the
  deserialized rclpy message. ``bag``: the :class:`~coco_ros.bag.BagMessage` itself (CDR bytes,
  log time, topic), nothing decoded.
- ``stop_at_end``: request the application stop once the bag is replayed (not with ``loop``) and the
  messages are processed downstream: a stop ends every activity at once, so the request waits until
  the other activities are idle and the application's queued (BUFFER, CIRCULAR) connections empty
  at two updates in a row, or ``DRAIN_TIMEOUT`` seconds: the last joint state still reaches the last
  output.
- ``max_per_update``: messages written per update at most (as fast as possible, a large bag would
  otherwise hold the activity for long); the rest follow at the next updates.
- ``stamped``: write every value as ``Stamped(value, stamp)`` (port type ``Stamped``), the
  :class:`~coco_core.stamps.Stamp` taken when the message is emitted (``seq`` counts the messages
  this component emitted, ``source`` is the topic). Consumers that call ``record_latency`` with it
  (through a ``stamped`` TransformationInterface too) measure the latency from the replay's emission
  to their output, which ``--profile`` reports. Off by default: the ports carry plain values.

Scheduling: each ``on_update`` writes every message that is due and returns at once, so the
component must be updated regularly: put it in a **periodic activity of 1-10 ms** (the period is the
timing resolution of the replay). In a triggered activity it wakes itself when the next message is
due (a timer thread, or at once when replaying as fast as possible), the first time from
``on_config``: nothing else would wake a replay that has no inputs.

Operations: ``pause()``, ``resume()``, ``step(n=1)`` (deliver the next n messages, stay paused),
``seek(t)`` (continue from ``t`` s after the bag start, latched messages first), ``set_rate(r)``,
``progress()`` -> ``(time, end)`` in seconds after the bag start.

An ``clock`` output port carries the replayed (simulated) time in seconds after each update that
delivered messages. A damaged bag (cut, corrupt, without its footer or metadata.yaml, or holding fewer
messages than its metadata.yaml declares: :mod:`coco_ros.bag.reader`) is replayed as far as it is readable, then its error (file and byte offset, or what is
lost) is logged once and reported to the application (:meth:`Application.report_damage`): the
launcher exits with 1 and a summary that reads ``app.damage`` shows it.

A message its converter refuses (a JointState with fewer positions than names, a zero or NaN
quaternion or position, CDR that does not decode) is damaged input too, but it costs only itself: it is counted
in the profile's ``refused`` column (:meth:`~coco_core.component.Component.record_refusal`), the
first ``DAMAGE_LISTED`` (``coco_core.component``) are each reported to the application (topic, bag time and
reason: the launcher exits with 1) and the messages after it are delivered as usual, at every rate.
"""

from __future__ import annotations

import logging
import re
import threading
import time
from pathlib import Path
from typing import Any

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import BagError, CocoError, ReplayError
from coco_core.operations import operation
from coco_core.ports import OutputPort
from coco_core.stamps import Stamp, Stamped

from ..bag import BagMessage, BagReader
from ..bag.message_types import TF_MESSAGE
from ..interface.topic import converter_options, parse_options
from .player import Played, Player, parse_remaps

log = logging.getLogger("coco.replay")

_NOT_NAME = re.compile(r"[^A-Za-z0-9_]+")

DRAIN_TIMEOUT = 2.0
"""Seconds ``stop_at_end`` waits at most for the downstream connections to empty."""
DRAIN_CHECK = 0.01
"""Seconds between two checks of the connections in a triggered activity (a periodic one checks every update)."""


def port_name_for(topic: str) -> str:
    """``/robot/joint_states`` -> ``robot_joint_states`` (a valid port name from a topic)."""
    name = _NOT_NAME.sub("_", topic).strip("_")
    if not name:
        raise ReplayError(f"cannot derive a port name from topic {topic!r}")
    return f"t_{name}" if name[0].isdigit() else name


def _converter(type_name: str, options: dict[str, str]) -> Any | None:
    """The converter of ``type_name`` with its ``options`` (texts), or None when there is none and no
    options were asked for; a wrong option raises ``ValueError`` naming the converter's options."""
    from ..convert import converter_for, supported_types

    if options:
        if type_name not in supported_types():
            raise ReplayError(f"no converter for {type_name}, so no options (types with a converter: "
                              f"{', '.join(supported_types())})")
        return converter_for(type_name, **converter_options(type_name, options))
    try:
        return converter_for(type_name)
    except (ValueError, ImportError):
        return None


class BagReplay(Component):
    """Replays a rosbag2 MCAP bag into one output port per topic; see the module docstring."""

    bag = Attribute(Path, Path(""), "bag folder or .mcap file")
    rate = Attribute(float, 1.0, "speed factor; 0: as fast as possible", min=0.0)
    start_offset = Attribute(float, 0.0, "seconds after the bag start where replay begins", min=0.0)
    duration = Attribute(float, 0.0, "seconds replayed per pass; 0: to the end", min=0.0)
    loop = Attribute(bool, False, "replay again after the end")
    topics: Attribute[list[str]] = Attribute(list[str], [], "bag topics to replay; empty: all")
    remap: Attribute[list[str]] = Attribute(list[str], [], "'/from:=/to' topic remappings")
    ports: Attribute[list[str]] = Attribute(list[str], [], "'/topic=port' port names; others derived from the topic")
    output = Attribute(str, "coco", "port values: coco (converted), ros (rclpy messages), bag (BagMessage)",
                       choices=("coco", "ros", "bag"))
    stop_at_end = Attribute(bool, False, "request the application stop when the bag is replayed and "
                            "processed downstream")
    max_per_update = Attribute(int, 256, "messages written per update at most", min=1)
    options: Attribute[list[str]] = Attribute(list[str], [], "'/topic;key=value[;key=value]' converter options of a topic")
    stamped = Attribute(bool, False, "write Stamped(value, emission stamp) instead of plain values")

    clock = OutputPort(float, "replayed bag time in seconds since the epoch (simulated time)")

    def init(self) -> None:
        if not str(self.bag) or str(self.bag) == ".":
            raise CocoError(f"component {self.name}: attribute 'bag' is required (a bag folder or .mcap file)")
        self._reader = BagReader(self.bag)
        self._remaps = parse_remaps(self.remap)
        names = self._port_names()
        options = self._topic_options()
        selected = list(self.topics) or list(self._reader.topics)
        self._routes: dict[str, tuple[OutputPort, Any]] = {}
        for topic in selected:
            if topic not in self._reader.topics:
                known = ", ".join(self._reader.topics) or "none"
                damage = "; ".join(str(error) for error in self._reader.errors)
                raise BagError(self._reader.path, f"component {self.name}: no topic {topic!r} in the bag "
                                                  f"(topics: {known})" + (f"; the bag is damaged: {damage}" if damage else ""))
            type_name = self._reader.topics[topic].type
            out_topic = self._remaps.get(topic, topic)
            given = options.pop(out_topic, None) or options.pop(topic, {})
            if type_name == TF_MESSAGE and self._reader.topics[topic].latched and "static" not in given:
                given = {**given, "static": "true"}  # /tf_static: static edges, as TFBridge makes them
            try:
                converter = _converter(type_name, given) if self.output == "coco" else None
            except (ValueError, ImportError) as error:
                raise CocoError(f"component {self.name}: options of {out_topic} ({type_name}): {error}") from None
            port_type: Any = Stamped if self.stamped else BagMessage if self.output == "bag" else (
                converter.coco_type if converter is not None else object)
            port = self.add_output(names.get(out_topic) or names.get(topic) or port_name_for(out_topic),
                                   port_type, f"{out_topic} ({type_name}) replayed from {self.bag}")
            self._routes[topic] = (port, converter)
        if options:
            shown = ", ".join(self._remaps.get(t, t) for t in selected)
            raise CocoError(f"component {self.name}: options name topic(s) {', '.join(options)} that are not "
                            f"replayed (replayed: {shown})")
        self._selected = selected
        self._seq = 0
        self.refused_messages = 0
        """Messages whose converter refused them (malformed), over every pass."""
        self._player: Player | None = None
        self._timer: threading.Timer | None = None
        self._ended = False
        self._ended_at = 0.0
        self._idle_checks = 0

    def _port_names(self) -> dict[str, str]:
        names = {}
        for item in self.ports:
            topic, sep, port = item.partition("=")
            if not sep or not topic.strip() or not port.strip():
                raise CocoError(f"component {self.name}: expected ports items like '/topic=port', got {item!r}")
            names[topic.strip()] = port.strip()
        return names

    def _topic_options(self) -> dict[str, dict[str, str]]:
        """``options`` items -> option texts by topic (checked against the converters in ``init``)."""
        found: dict[str, dict[str, str]] = {}
        for item in self.options:
            topic, *items = item.split(";")
            topic = topic.strip()
            where = f"component {self.name}: options item {item!r}"
            if not topic.startswith("/") or not items:
                raise CocoError(f"{where}: expected '/topic;key=value[;key=value]', e.g. /bowl/pose;child_frame=bowl")
            if self.output != "coco":
                raise CocoError(f"{where}: converter options need output=coco (output is {self.output})")
            if topic in found:
                raise CocoError(f"{where}: topic {topic} has options in another item too")
            try:
                found[topic] = parse_options(items)
            except ValueError as error:
                raise CocoError(f"{where}: {error}") from None
        return found

    def on_config(self) -> None:
        if self.output != "bag":
            self._reader.check_types(self._selected)
        self._player = Player(
            self._reader, rate=self.rate, start_offset=self.start_offset,
            duration=self.duration or None, loop=self.loop, topics=self._selected, remap=self._remaps,
            on_error=self._on_bag_error)
        self._wake_in(0.0)  # the first update; each update then asks for the next

    def _on_bag_error(self, error: BagError) -> None:
        log.error("component %s: bag damaged, replayed what was readable: %s", self.name, error)
        if self.app is not None:  # the launcher's exit status and the summaries carry it
            self.app.report_damage(f"{self.name}: {error}")

    def on_update(self) -> None:
        player = self._player
        if player is None:
            return
        played_list = player.poll(self.max_per_update)
        for played in played_list:
            self._deliver(played)
        if played_list:
            self.clock.write(played_list[-1].due_time / 1e9)
        if player.finished:
            if not self._ended:
                self._ended, self._ended_at, self._idle_checks = True, time.monotonic(), 0
                refused = f", {self.refused_messages} refused" if self.refused_messages else ""
                log.info("component %s: bag %s replayed (%d messages%s)", self.name, self.bag, player.delivered,
                         refused)
            if self.stop_at_end and self.app is not None and not self.app.stop_requested:
                if self._drained():
                    self.app.request_stop(f"{self.name}: bag {self.bag} replayed")
                else:
                    self._wake_in(DRAIN_CHECK)
            return
        delay = player.next_delay()
        if delay is not None:
            self._wake_in(delay)

    def _drained(self) -> bool:
        """Whether the messages replayed have been processed downstream: nothing in flight in the
        application (:meth:`~coco_core.application.Application.in_flight`) at two checks in a row
        (a consumer may be between reading and writing on), or ``DRAIN_TIMEOUT`` passed."""
        assert self.app is not None  # replaying: the component is in a running application
        self._idle_checks = 0 if self.app.in_flight(besides=self.activity) else self._idle_checks + 1
        return self._idle_checks >= 2 or time.monotonic() - self._ended_at > DRAIN_TIMEOUT

    def _deliver(self, played: Played) -> None:
        port, converter = self._routes[played.message.topic]
        value: Any
        try:
            if self.output == "bag":
                value = played.message
            elif converter is not None:  # from the CDR bytes: a converter may skip the rclpy message
                value = converter.from_cdr(played.message.data)
            else:
                value = played.message.message
        except Exception as error:  # a malformed message must cost itself only, not the messages after it
            self._refuse(played, error)
            return
        if self.stamped:
            self._seq += 1
            value = Stamped(value, Stamp.now(self._seq, played.topic))
        port.write(value)

    def _refuse(self, played: Played, error: Exception) -> None:
        """Refuse a message that cannot be converted as damaged input (:meth:`Component.refuse_damaged_input`)."""
        message = played.message
        self.refused_messages += 1
        offset = (message.log_time - self._reader.start_time) / 1e9
        self.refuse_damaged_input(self.bag, f"the {message.topic} message {offset:.3f} s into the bag "
                                  f"(log time {message.log_time} ns)", error)

    def _wake_in(self, delay: float) -> None:
        """In a triggered activity, arrange an update in ``delay`` seconds (a periodic one needs nothing)."""
        activity = self.activity
        if activity is None or not activity.wakes_on_data:
            return
        if delay <= 0:
            activity.wake()
        elif self._timer is None or not self._timer.is_alive():
            self._timer = threading.Timer(min(delay, 0.05), activity.wake)
            self._timer.daemon = True
            self._timer.start()

    def on_stop(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
        if self._player is not None:
            self._player.stop()
        self._reader.close()

    # -- operations ------------------------------------------------------------------------------
    def _require_player(self) -> Player:
        if self._player is None:
            raise CocoError(f"component {self.name} is not configured yet")
        return self._player

    @operation
    def pause(self) -> None:
        """Hold the replay (the clock stops)."""
        self._require_player().pause()

    @operation
    def resume(self) -> None:
        self._require_player().resume()

    @operation(name="step")
    def step_messages(self, n: int = 1) -> None:
        """Operation ``step`` (``Component.step`` is the scheduler's): deliver the next ``n`` messages at the next update, then stay paused."""
        self._require_player().step(int(n))
        self._poke()

    @operation
    def seek(self, t: float) -> None:
        """Continue from ``t`` seconds after the bag start (latched messages first)."""
        self._require_player().seek(float(t))
        self._ended = False

    @operation
    def set_rate(self, rate: float) -> None:
        self._require_player().clock.set_rate(rate)
        self._poke()

    @operation
    def progress(self) -> tuple[float, float]:
        """(replayed time, end time) in seconds after the bag start."""
        return self._require_player().progress()

    def _poke(self) -> None:
        activity = self.activity
        if activity is not None and activity.wakes_on_data:
            activity.wake()
