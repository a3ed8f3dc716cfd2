"""Streaming over ZeroMQ on TCP loopback: a server in another process sending real RGB-D frames,
newest-frame-only delivery with its counters, and garbage / truncated / out-of-order packets
counted, never a crash."""

from __future__ import annotations

import json
import os
import socket
import struct
import subprocess
import sys
import textwrap
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")
zmq = pytest.importorskip("zmq")

from coco_core import (Application, BufferPolicy, Component, ConnectionPolicy, InputPort, OutputPort,  # noqa: E402
                       TriggeredActivity)
from coco_core.errors import CocoError, PacketError  # noqa: E402
from coco_mr_vision.image import CameraIntrinsics  # noqa: E402
from coco_mr_vision.rgbd import RGBDFrame  # noqa: E402
from coco_mr_vision.stream_codec import decode, encode  # noqa: E402
from coco_mr_vision.streaming import StreamingReceiver  # noqa: E402

REDWOOD = Path(__file__).resolve().parents[3] / "shared" / "data" / "rgbd" / "redwood"


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def redwood(index: int = 0) -> RGBDFrame:
    if not REDWOOD.exists():
        pytest.skip(f"{REDWOOD} is absent")
    intrinsics = replace(CameraIntrinsics.from_json(REDWOOD / "camera_primesense.json"),
                         distortion=(0.1, -0.05, 0, 0, 0))
    return RGBDFrame.load(REDWOOD / "color" / f"{index:05d}.jpg", REDWOOD / "depth" / f"{index:05d}.png",
                          intrinsics, stamp=17.5, frame_id="camera")


class Sink(Component):
    rgbd = InputPort(object)
    image = InputPort(object)


def receiver_rig(address: str, **attributes):
    app = Application("receive")
    receiver = app.add(StreamingReceiver("receiver", address=address, **attributes))
    sink = app.add(Sink("sink"))
    app.connect(receiver.rgbd, sink.rgbd, ConnectionPolicy(BufferPolicy.BUFFER, size=1000))
    app.connect(receiver.image, sink.image, ConnectionPolicy(BufferPolicy.BUFFER, size=1000))
    receiver.on_config()
    return receiver, sink


@pytest.mark.parametrize("depth_encoding", ["png", "zstd", "raw"])
def test_codec_round_trip_lossless_depth_and_raw_colour(depth_encoding):
    frame = redwood()
    packet = encode(3, 1.0, 2.0, frame.color, frame.depth, color_encoding="raw", depth_encoding=depth_encoding)
    got = decode(packet)
    assert got.seq == 3 and np.array_equal(got.color.data, frame.color.data)
    assert np.array_equal(got.depth.data, frame.depth.data)
    assert got.depth.intrinsics.fx == 525.0 and got.depth.intrinsics.distortion[:2] == (0.1, -0.05)
    assert got.color.stamp == 17.5 and got.color.frame_id == "camera"
    jpeg = decode(encode(4, 1.0, 2.0, frame.color, None, quality=80))
    assert jpeg.depth is None and np.abs(jpeg.color.data.astype(int) - frame.color.data).mean() < 4
    assert len(encode(4, 1.0, 2.0, frame.color, None, quality=80)) < len(packet) / 5


def test_zstd_depth_is_the_default_and_smaller_than_png():
    frame = redwood()
    sizes = {encoding: len(encode(1, 0.0, 0.0, None, frame.depth, depth_encoding=encoding))
             for encoding in ("zstd", "png", "raw")}
    assert len(encode(1, 0.0, 0.0, None, frame.depth)) == sizes["zstd"] < sizes["png"] < sizes["raw"] / 4


def _depth_packet(payload: bytes, width: int = 64, height: int = 48) -> bytes:
    """A packet whose 16-bit depth is ``payload``, said to be Zstandard."""
    header = {"seq": 1, "acquired": 0.0, "sent": 0.0, "source": "", "stream": "", "depth_scale": 1000.0,
              "depth": {"format": "DEPTH16", "encoding": "zstd", "width": width, "height": height,
                        "bytes": len(payload), "stamp": None, "frame_id": "", "intrinsics": None}}
    text = json.dumps(header).encode()
    return b"CCV1" + struct.pack("<I", len(text)) + text + payload


def test_a_damaged_zstd_depth_payload_is_garbage():
    """A forged or damaged Zstandard payload is a counted bad packet: never a crash, and never a large
    allocation (the size the frame declares is checked against the header's before decompressing)."""
    import zstandard

    depth = np.full((48, 64), 1500, np.uint16).tobytes()
    good = zstandard.ZstdCompressor(level=1).compress(depth)
    assert np.array_equal(decode(_depth_packet(good)).depth.data, np.full((48, 64), 1500, np.uint16))
    flipped = good[:8] + bytes(b ^ 0x5A for b in good[8:])
    other_size = zstandard.ZstdCompressor(level=1).compress(bytes(2 * 48 * 63))  # one column short
    unknown_size = zstandard.ZstdCompressor(level=1, write_content_size=False).compress(depth)
    for payload in (flipped, other_size, unknown_size, good[:-3], b"\x28\xb5\x2f\xfd" + bytes(20)):
        with pytest.raises(PacketError) as caught:
            decode(_depth_packet(payload))
        assert caught.value.kind == "garbage"


@pytest.mark.parametrize("packet, kind", [
    (b"", "truncated"), (b"HTTP/1.1 200 OK\r\n\r\n", "garbage"), (b"CCV1\xff\xff\x00\x00{", "truncated"),
    (b"CCV1\x02\x00\x00\x00{]", "garbage"), (os.urandom(5000), "garbage"),
])
def test_bad_packets_raise_packet_errors_by_kind(packet, kind):
    with pytest.raises(PacketError) as caught:
        decode(packet)
    assert caught.value.kind == kind
    assert isinstance(caught.value, CocoError) and isinstance(caught.value, ValueError)


def test_server_in_another_process_to_receiver(tmp_path):
    redwood()
    port = free_port()
    script = textwrap.dedent(f"""
        import sys, time
        from coco_core import Application, Component, OutputPort
        from coco_core.stamps import Stamp, Stamped
        from coco_mr_vision.image import CameraIntrinsics
        from coco_mr_vision.rgbd import RGBDFrame
        from coco_mr_vision.streaming import StreamingServer
        class Camera(Component):
            rgbd = OutputPort(object)
        root = {str(REDWOOD)!r}
        k = CameraIntrinsics.from_json(root + "/camera_primesense.json")
        frames = [RGBDFrame.load(f"{{root}}/color/0000{{i}}.jpg", f"{{root}}/depth/0000{{i}}.png", k, stamp=float(i),
                                 frame_id="camera") for i in (0, 1)]
        app = Application("send")
        camera = app.add(Camera("camera"))
        server = app.add(StreamingServer("server", address="tcp://127.0.0.1:{port}", quality=85))
        app.connect(camera.rgbd, server.rgbd)
        server.on_config()
        for seq in range(1, 121):
            camera.rgbd.write(Stamped(frames[seq % 2], Stamp.now(seq, "camera")))
            server.on_update()
            time.sleep(1 / 30)
        print(server.sent, server.bytes, flush=True)
    """)
    sender = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    receiver, sink = receiver_rig(f"tcp://127.0.0.1:{port}")
    frames = []
    deadline = time.monotonic() + 30
    try:
        while sender.poll() is None and time.monotonic() < deadline:
            receiver.on_update()
            frames += sink.rgbd.read_all()
            time.sleep(0.01)
        time.sleep(0.05)
        receiver.on_update()
        frames += sink.rgbd.read_all()
        sent, sent_bytes = (int(n) for n in sender.communicate(timeout=10)[0].split())
    finally:
        if sender.poll() is None:
            sender.kill()
    assert sender.returncode == 0
    counters = receiver.counters()
    assert counters["frames"] >= 60, counters  # 4 s at 30 Hz; the first packets go before the connection
    assert counters["garbage"] == counters["truncated"] == counters["out_of_order"] == 0
    # Every frame sent is delivered or counted as dropped (those before the subscription too).
    assert counters["frames"] + counters["dropped"] == 120
    assert 0 < counters["latency_mean"] < 0.5 and counters["bytes"] <= sent_bytes and sent == 120
    last = frames[-1]
    original = redwood(int(last.value.stamp))  # the sender stamps frame i with i
    assert np.array_equal(last.value.depth.data, original.depth.data), "depth is lossless"
    assert np.abs(last.value.color.data.astype(int) - original.color.data).mean() < 5
    assert last.value.intrinsics.fx == 525.0 and last.stamp.source == "camera"
    # The way so far, for a latency split by step: sent by the server, received (decoded) here.
    assert [name for name, _ in last.stamp.steps] == ["sent", "received"]
    assert last.stamp.time <= last.stamp.steps[0][1] <= last.stamp.steps[1][1]


@pytest.fixture
def link():
    """A bare ZeroMQ publisher, whose packets the test makes, and a receiver rig on it:
    (publisher, receiver, sink)."""
    port = free_port()
    publisher = zmq.Context.instance().socket(zmq.PUB)
    publisher.setsockopt(zmq.LINGER, 0)
    publisher.bind(f"tcp://127.0.0.1:{port}")
    receiver, sink = receiver_rig(f"tcp://127.0.0.1:{port}")
    yield publisher, receiver, sink
    publisher.close(0)
    receiver.on_stop()


def subscribed(publisher, receiver, packet: bytes) -> None:
    """Send ``packet`` until the receiver delivers it (a ZeroMQ subscription takes a moment), then
    let the repeats that were on their way arrive."""
    deadline = time.monotonic() + 10
    while receiver.frames == 0 and time.monotonic() < deadline:
        publisher.send(packet)
        time.sleep(0.02)
        receiver.on_update()
    time.sleep(0.1)
    receiver.on_update()


def drained(receiver, done, timeout: float = 10.0) -> bool:
    """Activate ``receiver`` until ``done(counters)`` (packets take a moment on loopback)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        receiver.on_update()
        if done(receiver.counters()):
            return True
        time.sleep(0.005)
    return False


def test_garbage_truncated_out_of_order_and_gaps_are_counted(link):
    publisher, receiver, sink = link
    frame = redwood()

    def packet_of(seq: int) -> bytes:
        return encode(seq, time.perf_counter(), time.perf_counter(), frame.color, frame.depth)

    subscribed(publisher, receiver, packet_of(1))
    before, refused = receiver.counters(), receiver.stats.refused
    for bad in (b"not a packet", packet_of(2)[:-100], packet_of(1), os.urandom(300), packet_of(5),
                packet_of(6), packet_of(4)):
        publisher.send(bad)
    # One activation takes what has arrived: the seven may come over several.
    assert drained(receiver, lambda counters: counters["out_of_order"] - before["out_of_order"] == 2)
    after = receiver.counters()
    assert after["garbage"] - before["garbage"] == 2
    assert after["truncated"] - before["truncated"] == 1
    assert after["out_of_order"] - before["out_of_order"] == 2, "seq 1 again, and 4 after 6"
    # 2, 3, 4 never came in order; 5 was delivered, or superseded by 6 when both came at once.
    assert (after["frames"] - before["frames"]) + (after["dropped"] - before["dropped"]) == 5
    assert after["frames"] - before["frames"] in (1, 2)
    assert sink.rgbd.read_all()[-1].stamp.seq == 6
    # Every refused packet reaches the profile's refused column (9,389 / 12 / 8,357 in a flood did not).
    assert receiver.stats.refused - refused == 5


def test_a_server_that_starts_again_is_one_restart_and_its_frames_are_delivered(link):
    """Its sequence numbers begin at 1 again: not out-of-order packets to skip, but a new run."""
    publisher, receiver, sink = link
    frame = redwood()

    def packet_of(seq: int, stream: str) -> bytes:
        return encode(seq, time.perf_counter(), time.perf_counter(), frame.color, None, stream=stream)

    subscribed(publisher, receiver, packet_of(1, "first"))
    for later in (2, 3, 4):
        publisher.send(packet_of(later, "first"))
    time.sleep(0.2)
    receiver.on_update()
    before = receiver.counters()
    for again in (1, 2, 3):
        publisher.send(packet_of(again, "second"))
        time.sleep(0.1)
        receiver.on_update()
    after = receiver.counters()
    assert after["restarts"] - before["restarts"] == 1
    assert after["out_of_order"] == before["out_of_order"] and after["dropped"] == before["dropped"]
    assert after["frames"] - before["frames"] == 3
    assert [stamped.stamp.seq for stamped in sink.image.read_all()[-3:]] == [1, 2, 3]


def test_a_receiver_in_a_triggered_activity_is_woken_by_its_socket():
    """No period: the receiver's activity cycles when a packet has arrived (its socket's descriptor
    became readable), once per arrival, never in a loop; its stop ends the thread that watches."""
    frame = redwood()
    address = f"tcp://127.0.0.1:{free_port()}"
    publisher = zmq.Context.instance().socket(zmq.PUB)
    publisher.setsockopt(zmq.LINGER, 0)
    publisher.bind(address)
    app = Application("receive")
    activity = TriggeredActivity("stream")
    receiver = app.add(StreamingReceiver("receiver", address=address), activity)
    sink = app.add(Sink("sink"))
    app.connect(receiver.image, sink.image, ConnectionPolicy(BufferPolicy.BUFFER, size=1000))
    sent = 0

    def send() -> None:
        nonlocal sent
        sent += 1
        publisher.send(encode(sent, time.perf_counter(), time.perf_counter(), frame.color, None, stream="one"))

    app.start()
    try:
        deadline = time.monotonic() + 10
        while receiver.frames == 0 and time.monotonic() < deadline:  # until the subscription is up
            send()
            time.sleep(0.02)
        assert receiver.frames, "nothing received"
        for _ in range(5):  # one at a time: each is delivered without anyone activating the receiver
            send()
            deadline = time.monotonic() + 10
            while receiver.last_seq < sent and time.monotonic() < deadline:
                time.sleep(0.002)
            assert receiver.last_seq == sent
    finally:
        assert app.stop()
        publisher.close(0)
    counters = receiver.counters()
    assert counters["frames"] + counters["dropped"] == sent and counters["garbage"] == 0
    assert [stamped.stamp.seq for stamped in sink.image.read_all()][-5:] == list(range(sent - 4, sent + 1))
    # A cycle per wake-up of the socket (packets, ZeroMQ's own commands), not a polling loop's.
    assert activity.stats.cycles <= sent + 10, (activity.stats.cycles, sent)
    assert not any(thread.name == "coco:receiver (socket)" for thread in threading.enumerate())


def test_a_triggered_receiver_is_woken_by_a_broken_connection_and_connects_again():
    """A message over the largest packet makes ZeroMQ drop the connection for good: the monitor's
    descriptor wakes the receiver's activity (nobody activates it), which counts the disconnection and
    connects again, and the next packet is delivered."""
    from coco_mr_vision.image import Image, ImageFormat
    from coco_mr_vision.stream_header import FrameLimit

    address = f"tcp://127.0.0.1:{free_port()}"
    publisher = zmq.Context.instance().socket(zmq.PUB)
    publisher.setsockopt(zmq.LINGER, 0)
    publisher.bind(address)
    app = Application("receive")
    receiver = app.add(StreamingReceiver("receiver", address=address, max_frame=[640, 480]), TriggeredActivity("s"))
    image = Image(np.full((48, 64, 3), 9, np.uint8), ImageFormat.RGB8, 1.0, "camera")
    sent = 0

    def until(done, resend: bool) -> bool:
        nonlocal sent
        deadline = time.monotonic() + 10
        while not done() and time.monotonic() < deadline:
            if resend:
                sent += 1
                publisher.send(encode(sent, time.perf_counter(), time.perf_counter(), image, None, stream="one"))
            time.sleep(0.02)
        return done()

    app.start()
    try:
        assert until(lambda: receiver.frames > 0, resend=True)
        publisher.send(b"CCV1" + bytes(FrameLimit(640, 480).packet_bytes + 1))
        assert until(lambda: receiver.disconnects == 1, resend=False)
        before = receiver.frames
        assert until(lambda: receiver.frames > before, resend=True), "nothing after the connection broke"
    finally:
        assert app.stop()
        publisher.close(0)


def test_a_frame_whose_intrinsics_came_beside_its_images_keeps_them_through_the_stream():
    """A bag's RGB-D frames carry their intrinsics on the frame (from camera_info), not on the depth
    image: the packet took the depth image's, so every receiver got frames without intrinsics and
    MeshReconstructor refused them all (the palpation app meshed nothing)."""
    from coco_core.stamps import Stamp, Stamped
    from coco_mr_vision.image import Image, ImageFormat
    from coco_mr_vision.streaming import StreamingServer

    class Source(Component):
        rgbd = OutputPort(object)

    address = f"tcp://127.0.0.1:{free_port()}"
    app = Application("send")
    source = app.add(Source("source"))
    server = app.add(StreamingServer("server", address=address, color_encoding="raw"))
    app.connect(source.rgbd, server.rgbd, ConnectionPolicy(BufferPolicy.BUFFER, size=10))
    server.on_config()
    receiver, sink = receiver_rig(address)
    intrinsics = CameraIntrinsics(64, 48, 50.0, 51.0, 32.0, 24.0)
    color = Image(np.full((48, 64, 3), 90, np.uint8), ImageFormat.RGB8, 3.0, "camera")
    depth = Image(np.full((48, 64), 1000, np.uint16), ImageFormat.DEPTH16, 3.0, "camera")
    assert depth.intrinsics is None
    try:
        deadline = time.monotonic() + 10
        while receiver.frames == 0 and time.monotonic() < deadline:
            source.rgbd.write(Stamped(RGBDFrame(color, depth, intrinsics), Stamp.now(source="camera")))
            server.on_update()
            time.sleep(0.02)
            receiver.on_update()
        received = sink.rgbd.read_all()
        assert received, "no frame received"
        frame = received[-1].value
        assert (frame.intrinsics.fx, frame.intrinsics.fy, frame.intrinsics.cx) == (50.0, 51.0, 32.0)
    finally:
        server.on_stop()
        receiver.on_stop()
