"""StreamingServer and StreamingReceiver: images and depth over TCP with ZeroMQ (the paper's
tele-presence link), packets as in :mod:`coco_mr_vision.stream_codec`.

The server binds a PUB socket and sends one packet per frame; a slow or absent receiver never
blocks it (ZeroMQ drops beyond the high-water mark). The receiver connects a SUB socket and, each
activation, drains every packet that arrived and delivers only the newest ("newest frame only",
what live use wants); the older ones are counted as dropped, as are gaps in the sequence numbers.
Garbage, truncated and out-of-order packets are counted by kind and skipped: a bad packet is never
a crash. Each server run names itself in its packets, so a server that starts again (its sequence
numbers from 1) is counted once as a restart and its frames delivered, not taken for stale ones. Latency is measured from the frame's acquisition stamp on the server side (the monotonic
clock is shared by the processes of one host).
"""

from __future__ import annotations

import logging
import secrets
import time

import zmq

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import PacketError
from coco_core.ports import InputPort, OutputPort
from coco_core.stamps import Stamp, Stamped, unstamped

from .image import Image
from .rgbd import RGBDFrame
from .stream_codec import COLOR_ENCODINGS, DEPTH_ENCODINGS, decode, encode

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
            self._send(frame.color, frame.depth, frame.depth_scale, stamp)
        for value in self.image.read_all():
            image, stamp = unstamped(value)
            self._send(image, None, 1000.0, stamp)

    def _send(self, color: Image | None, depth: Image | None, depth_scale: float, stamp: Stamp | None) -> None:
        self._seq += 1
        now = time.perf_counter()
        packet = encode(self._seq, stamp.time if stamp is not None else now, now, color, depth,
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


class StreamingReceiver(Component):
    """Receives the server's packets and delivers the newest frame at each activation."""

    address = Attribute(str, "tcp://127.0.0.1:5600", "the server's address", check=_loopback_or_any)

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
        self.latency_last = float("nan")
        self.latency_sum = 0.0
        self._last_seq = 0
        self._stream: str | None = None

    def counters(self) -> dict[str, float]:
        """What the profile shows: frames, drops, bad packets by kind, bytes, latency (s)."""
        return {"frames": self.frames, "dropped": self.dropped, "bytes": self.bytes, "garbage": self.garbage,
                "truncated": self.truncated, "out_of_order": self.out_of_order,
                "restarts": self.restarts, "latency_last": self.latency_last,
                "latency_mean": self.latency_sum / self.frames if self.frames else float("nan")}

    def on_config(self) -> None:
        self._socket: zmq.Socket[bytes] = zmq.Context.instance().socket(zmq.SUB)
        self._socket.setsockopt(zmq.SUBSCRIBE, b"")
        self._socket.setsockopt(zmq.LINGER, 0)
        self._socket.setsockopt(zmq.RCVHWM, 4)
        self._socket.connect(self.address)

    def on_update(self) -> None:
        newest = None
        while True:
            try:
                packet = self._socket.recv(zmq.NOBLOCK, copy=False)
            except zmq.Again:
                break
            self.bytes += len(packet.buffer)
            try:
                frame = decode(packet.buffer)
            except PacketError as error:
                setattr(self, error.kind, getattr(self, error.kind) + 1)
                log.debug("%s: %s packet: %s", self.name, error.kind, error)
                continue
            if frame.stream != self._stream:  # the first packet, or a server that started again
                if self._stream is not None:
                    self.restarts += 1
                    log.info("%s: the server started again (stream %s)", self.name, frame.stream)
                self._stream, self._last_seq = frame.stream, 0  # numbered from 1: a gap before is a drop
            if frame.seq <= self._last_seq:
                self.out_of_order += 1
                continue
            if newest is not None:
                self.dropped += 1
            self.dropped += frame.seq - self._last_seq - 1
            self._last_seq = frame.seq
            newest = frame
        if newest is None:
            return
        latency = time.perf_counter() - newest.acquired
        self.latency_last = latency
        self.latency_sum += latency
        self.frames += 1
        stamp = Stamp(newest.acquired, newest.seq, newest.source)
        if newest.depth is not None and newest.color is not None:
            self.rgbd.write(Stamped(RGBDFrame(newest.color, newest.depth, newest.depth.intrinsics,
                                              newest.depth_scale), stamp))
        elif newest.color is not None:
            self.image.write(Stamped(newest.color, stamp))

    def on_stop(self) -> None:
        self._socket.close(0)
