"""StreamingServer and StreamingReceiver: images and depth over TCP with ZeroMQ (the paper's
tele-presence link), packets as in :mod:`coco_mr_vision.stream_codec`.

The server binds a PUB socket and sends one packet per frame; a slow or absent receiver never
blocks it (ZeroMQ drops beyond the high-water mark). The receiver connects a SUB socket and, each
activation, drains every packet that arrived and delivers only the newest ("newest frame only",
what live use wants); the older ones are counted as dropped, as are gaps in the sequence numbers.
In a triggered activity its sockets wake it (:class:`~coco_core.descriptor_trigger.DescriptorTrigger`
on their ``ZMQ_FD``): a packet is read as soon as it has arrived, not at the next tick of a period,
and nothing polls; in a periodic one it looks at each cycle.
Garbage, truncated and out-of-order packets are counted by kind, and together in the profile's
refused column, and skipped: a bad packet is never a crash. Each server run names itself in its packets, so a server that starts again (its sequence
numbers from 1) is counted once as a restart and its frames delivered, not taken for stale ones.
Latency is measured from the frame's acquisition stamp on the server side; the receiver's stamps
carry the time the server took the frame (its packet's ``sent``, taken before the encoding) and the
time the receiver decoded it as the stamp's first ``steps``. The packet's times are on the
application's clock (the server converts with its host's offset, the receiver back with its own:
:attr:`Component.host_clock <coco_core.component.Component.host_clock>`), so that a server and a
receiver on two hosts of one application (``<host>``) give latencies on one clock, the first
host's, within the offsets' uncertainty; on one host the clock is the monotonic clock its processes
share.

The receiver trusts nothing in a packet (see :mod:`coco_mr_vision.stream_codec`): ZeroMQ refuses a
message larger than the packet of the receiver's ``max_frame`` (``MAXMSGSIZE``), every header field
is checked, image sizes are checked against ``max_frame`` from the header and from the encoded
image's own first bytes before decoding, a sequence number far ahead of the last is taken only once
the next packet confirms it, and each activation reads only the headers of the packets it drains
(at most ``MAX_DRAIN``) and decodes the newest alone, so that under a flood what it delivers is
recent. One bad packet costs that one packet.
"""

from __future__ import annotations

import logging
import secrets
import time
from dataclasses import replace

import zmq

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.descriptor_trigger import DescriptorTrigger
from coco_core.errors import PacketError
from coco_core.ports import InputPort, OutputPort
from coco_core.stamps import Stamp, Stamped, unstamped

from .image import Image
from .rgbd import RGBDFrame
from .stream_codec import COLOR_ENCODINGS, DEPTH_ENCODINGS, OpenedPacket, decode_opened, encode, open_packet
from .stream_header import FrameLimit, PacketHeader

log = logging.getLogger("coco.vision")


def _loopback_or_any(address: str) -> str | None:
    if not address.startswith("tcp://"):
        return f"address {address!r} must be tcp://host:port"
    return None


class StreamingServer(Component):
    """Sends each RGB-D frame or image it receives to every connected receiver."""

    address = Attribute(str, "tcp://127.0.0.1:5600", "where to bind the PUB socket", check=_loopback_or_any)
    color_encoding = Attribute(str, "jpeg", "jpeg or raw", choices=COLOR_ENCODINGS)
    quality = Attribute(int, 90, "JPEG quality", min=1, max=100)
    depth_encoding = Attribute(str, "zstd", "zstd (Zstandard on the 16-bit depth: lossless, smallest and fastest), "
                               "png (16-bit, lossless) or raw", choices=DEPTH_ENCODINGS)
    high_water_mark = Attribute(int, 2, "frames ZeroMQ queues per receiver before dropping", min=1)

    rgbd = InputPort(RGBDFrame | Stamped, event=True, doc="RGB-D frames to send")
    image = InputPort(Image | Stamped, event=True, doc="colour images to send (no depth)")

    def init(self) -> None:
        self.sent = 0
        self.bytes = 0

    def on_config(self) -> None:
        self._context: zmq.Context[zmq.Socket[bytes]] = zmq.Context.instance()
        self._socket = self._context.socket(zmq.PUB)
        self._socket.setsockopt(zmq.SNDHWM, self.high_water_mark)
        self._socket.setsockopt(zmq.LINGER, 0)
        self._socket.bind(self.address)
        self._seq = 0
        self._stream = secrets.token_hex(8)

    def on_update(self) -> None:
        for value in self.rgbd.read_all():
            frame, stamp = unstamped(value)
            depth = frame.depth
            if frame.intrinsics is not None and depth.intrinsics is None:
                # The packet carries the depth image's intrinsics: a frame whose intrinsics came
                # beside its images (a bag's camera_info) would reach the receivers without any.
                depth = replace(depth, intrinsics=frame.intrinsics)
            self._send(frame.color, depth, frame.depth_scale, stamp)
        for value in self.image.read_all():
            image, stamp = unstamped(value)
            self._send(image, None, 1000.0, stamp)

    def _send(self, color: Image | None, depth: Image | None, depth_scale: float, stamp: Stamp | None) -> None:
        self._seq += 1
        now = time.perf_counter()
        to_app = self.host_clock.to_app
        packet = encode(self._seq, to_app(stamp.time if stamp is not None else now), to_app(now), color, depth,
                        depth_scale=depth_scale, color_encoding=self.color_encoding, quality=self.quality,
                        depth_encoding=self.depth_encoding, source=stamp.source if stamp else self.name,
                        stream=self._stream)
        try:
            self._socket.send(packet, zmq.NOBLOCK, copy=False)
        except zmq.Again:
            return  # no receiver is keeping up: a live stream drops, it does not wait
        self.sent += 1
        self.bytes += len(packet)

    def on_stop(self) -> None:
        self._socket.close(0)


MAX_DRAIN = 1000
"""Packets one activation takes at most: under a flood it delivers the newest of these and leaves
the rest to the next activation, instead of draining for ever."""

MAX_JUMP = 300
"""Sequence numbers that one packet may skip ahead of the last (10 s at 30 Hz). A larger jump is
taken only when the next packet confirms it: a forged or damaged number costs that one packet,
not every packet until the stream catches up with it."""

MAX_LATENCY = 3600.0
"""Latencies outside 0 to an hour are not a shared clock's (another host's monotonic clock): they are
left out of the mean."""


def _frame_limit_problem(value: list[int]) -> str | None:
    if len(value) != 2 or not all(16 <= side <= 16384 for side in value):
        return f"max_frame must be a width and a height of 16 to 16384 pixels, got {value}"
    return None


class StreamingReceiver(Component):
    """Receives the server's packets and delivers the newest frame at each activation."""

    address = Attribute(str, "tcp://127.0.0.1:5600", "the server's address", check=_loopback_or_any)
    max_frame = Attribute(list[int], [1920, 1080], "the largest width and height of an image (pixels): larger "
                          "packets are refused as garbage before decoding, and ZeroMQ refuses messages "
                          "larger than such a frame's packet", check=_frame_limit_problem)

    rgbd = OutputPort(Stamped, "Stamped(RGBDFrame) for packets with depth")
    image = OutputPort(Stamped, "Stamped(Image) for packets with colour only")

    def init(self) -> None:
        self.frames = 0
        self.dropped = 0
        """Packets received but superseded by a newer one before delivery, plus sequence gaps."""
        self.bytes = 0
        self.garbage = 0
        self.truncated = 0
        self.out_of_order = 0
        self.restarts = 0
        """Times the server started again (a new run, its sequence numbers from 1 again)."""
        self.disconnects = 0
        """Times the connection to the server broke: the server went away, or it sent a message larger
        than ``max_frame``'s packet, which ZeroMQ refuses by closing the connection for good; the
        receiver connects again either way."""
        self.latency_last = float("nan")
        self.latency_sum = 0.0
        self.latency_count = 0
        self._last_seq = 0
        self._stream: str | None = None
        self._jump: tuple[str, int] | None = None
        """The last packet that jumped more than MAX_JUMP ahead (stream, seq), to be confirmed."""

    def counters(self) -> dict[str, float]:
        """What the profile shows: frames, drops, bad packets by kind, bytes, latency (s)."""
        return {"frames": self.frames, "dropped": self.dropped, "bytes": self.bytes, "garbage": self.garbage,
                "truncated": self.truncated, "out_of_order": self.out_of_order,
                "restarts": self.restarts, "disconnects": self.disconnects, "latency_last": self.latency_last,
                "latency_mean": self.latency_sum / self.latency_count if self.latency_count else float("nan")}

    @property
    def last_seq(self) -> int:
        """The sequence number of the newest packet taken from the current stream (0 before one)."""
        return self._last_seq

    def on_config(self) -> None:
        self._limit = FrameLimit(*self.max_frame)
        self._socket: zmq.Socket[bytes] = zmq.Context.instance().socket(zmq.SUB)
        self._socket.setsockopt(zmq.SUBSCRIBE, b"")
        self._socket.setsockopt(zmq.LINGER, 0)
        self._socket.setsockopt(zmq.RCVHWM, 4)
        # A peer announcing a larger message is disconnected before ZeroMQ allocates it.
        self._socket.setsockopt(zmq.MAXMSGSIZE, self._limit.packet_bytes)
        self._monitor: zmq.Socket[bytes] = self._socket.get_monitor_socket(zmq.EVENT_DISCONNECTED)
        self._socket.connect(self.address)
        self._trigger: DescriptorTrigger | None = None
        activity = self.activity
        if activity is not None and activity.wakes_on_data:
            # Woken by the sockets, not by a period: a packet is read as soon as it is whole.
            self._trigger = DescriptorTrigger(f"coco:{self.name} (socket)", [self._socket.getsockopt(zmq.FD),
                                              self._monitor.getsockopt(zmq.FD)], activity.wake)
            self._trigger.start()

    def _reconnect_after_disconnects(self) -> None:
        """ZeroMQ connects again after a server went away, but not after a protocol error (a message
        over MAXMSGSIZE): then the receiver would wait for ever. Connecting again after each
        disconnection covers both."""
        disconnected = False
        while True:
            try:
                self._monitor.recv_multipart(zmq.NOBLOCK)  # [event and value, endpoint]
            except zmq.Again:
                break
            self.disconnects += 1
            disconnected = True
        if disconnected:
            log.warning("%s: the connection to %s broke (%d so far): connecting again", self.name, self.address,
                        self.disconnects)
            self._socket.disconnect(self.address)
            self._socket.connect(self.address)

    def _refuse(self, error: PacketError) -> None:
        """Count a bad packet by its kind and in the profile's refused column (with the launcher's
        summary, the one place a flood shows); the first of each kind is logged as a warning (a
        server configured for larger frames than ``max_frame`` shows up at once), the others at
        debug level."""
        count = getattr(self, error.kind) + 1
        setattr(self, error.kind, count)
        self.stats.refused += 1
        log.log(logging.WARNING if count == 1 else logging.DEBUG, "%s: %s packet: %s%s", self.name, error.kind,
                error, " (further ones are counted)" if count == 1 else "")

    def _in_order(self, header: PacketHeader) -> bool:
        """Whether ``header`` follows the packets taken so far; counts gaps, restarts, reorders."""
        if header.stream != self._stream:  # the first packet, or a server that started again
            if self._stream is not None:
                self.restarts += 1
                log.info("%s: the server started again (stream %s)", self.name, header.stream)
            self._stream, self._last_seq = header.stream, 0  # numbered from 1: a gap before is a drop
        gap = header.seq - self._last_seq
        if gap <= 0:
            self._refuse(PacketError("out_of_order", f"sequence number {header.seq} after {self._last_seq}"))
            return False
        if gap > MAX_JUMP:
            if self._last_seq and self._jump != (header.stream, header.seq - 1):
                self._jump = (header.stream, header.seq)
                self._refuse(PacketError("garbage", f"sequence number {header.seq} jumps {gap} ahead of "
                                         f"{self._last_seq}: taken when the next packet confirms it"))
                return False
            gap = 1  # joined a stream long under way, or a jump confirmed: what was lost before is unknown
        self._jump = None
        self.dropped += gap - 1
        self._last_seq = header.seq
        return True

    def on_update(self) -> None:
        more = False
        try:
            more = self._receive()
        finally:  # whatever happened, the sockets are watched again
            if self._trigger is not None:
                self._trigger.rearm(more)

    def _receive(self) -> bool:
        """Take what arrived, deliver the newest; whether packets were left for the next activation
        (``MAX_DRAIN`` reached before the socket was empty)."""
        self._reconnect_after_disconnects()
        newest: OpenedPacket | None = None
        more = True
        for _ in range(MAX_DRAIN):  # only headers are read here (~10 us): the newest alone is decoded
            try:
                packet = self._socket.recv(zmq.NOBLOCK, copy=False)
            except zmq.Again:
                more = False
                break
            self.bytes += len(packet.buffer)
            try:
                opened = open_packet(packet.buffer, self._limit)
            except PacketError as error:
                self._refuse(error)
                continue
            if not self._in_order(opened.header):
                continue
            if newest is not None:
                self.dropped += 1
            newest = opened
        if newest is None:
            return more
        try:
            frame = decode_opened(newest)
        except PacketError as error:
            self._refuse(error)
            return more
        received = time.perf_counter()
        from_app = self.host_clock.from_app
        acquired, sent = from_app(frame.acquired), from_app(frame.sent)
        latency = received - acquired
        self.latency_last = latency
        if 0.0 <= latency <= MAX_LATENCY:
            self.latency_sum += latency
            self.latency_count += 1
        self.frames += 1
        # The way so far, for a latency split by step downstream: taken by the server to send (before
        # its encoding), received here (decoded: what the receiver's readers get).
        stamp = Stamp(acquired, frame.seq, frame.source, (("sent", sent), ("received", received)))
        if frame.depth is not None and frame.color is not None:
            self.rgbd.write(Stamped(RGBDFrame(frame.color, frame.depth, frame.depth.intrinsics,
                                              frame.depth_scale), stamp))
        elif frame.color is not None:
            self.image.write(Stamped(frame.color, stamp))
        return more

    def on_stop(self) -> None:
        if self._trigger is not None:
            self._trigger.close()
        self._socket.disable_monitor()
        self._monitor.close(0)
        self._socket.close(0)
