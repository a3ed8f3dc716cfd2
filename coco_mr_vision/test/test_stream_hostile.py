"""Hostile packets on the vision stream: crafted headers and payloads, sent over real ZeroMQ sockets.

Each bad packet must cost that one packet, counted as garbage: never an exception, never a large
allocation before the size is known to fit the receiver's largest frame, never a value that spoils
the packets after it (their order, the latency mean)."""

from __future__ import annotations

import json
import math
import struct
import time

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")
zmq = pytest.importorskip("zmq")

from coco_core.errors import PacketError  # noqa: E402
from coco_mr_vision.image import Image, ImageFormat  # noqa: E402
from coco_mr_vision.stream_codec import decode, encode  # noqa: E402
from coco_mr_vision.stream_header import FrameLimit  # noqa: E402
from coco_mr_vision.streaming import MAX_JUMP  # noqa: E402

from test_streaming import drained, free_port, receiver_rig  # noqa: E402

STREAM = "0123456789abcdef"


def colour(value: int = 90, width: int = 64, height: int = 48) -> Image:
    return Image(np.full((height, width, 3), value, np.uint8), ImageFormat.RGB8, 1.0, "camera")


def good(seq: int) -> bytes:
    now = time.perf_counter()
    return encode(seq, now, now, colour(), None, stream=STREAM)


def craft(header: object, payload: bytes = b"") -> bytes:
    """A packet with ``header`` (a JSON text, or a value made JSON) in front of ``payload``."""
    text = (header if isinstance(header, str) else json.dumps(header)).encode()
    return b"CCV1" + struct.pack("<I", len(text)) + text + payload


def header_of(packet: bytes) -> dict:
    (length,) = struct.unpack_from("<I", packet, 4)
    return json.loads(packet[8:8 + length])


def payload_of(packet: bytes) -> bytes:
    (length,) = struct.unpack_from("<I", packet, 4)
    return packet[8 + length:]


def with_fields(number: int, **fields: object) -> str:
    """The JSON header of good(number) with fields replaced by raw JSON text (``Infinity``, ``1e400``)."""
    header = header_of(good(number))
    text = json.dumps(header)
    for name, raw in fields.items():
        if name in header:
            text = text.replace(f'"{name}": {json.dumps(header[name])}', f'"{name}": {raw}', 1)
        else:
            text = text.replace(f'"{name}": {json.dumps(header["color"][name])}', f'"{name}": {raw}', 1)
    return text


def hostile_headers(seq: int) -> list[bytes]:
    """Each a JSON header of the wrong shape or out of range, in front of a valid payload."""
    payload = payload_of(good(seq))
    deep = "[" * 1000 + "]" * 1000
    texts = [
        "[1, 2, 3]", "null", '"text"', "{" + '"a":' * 0 + '"seq": ' + deep + "}", deep,
        with_fields(seq, seq="1e400"), with_fields(seq, seq="Infinity"), with_fields(seq, seq="NaN"),
        with_fields(seq, seq="1" + "0" * 5000), with_fields(seq, seq="-3"), with_fields(seq, seq="true"),
        with_fields(seq, seq="[1]"), with_fields(seq, seq="null"), with_fields(seq, seq="1" + "0" * 18),
        with_fields(seq, acquired="NaN"), with_fields(seq, acquired="1e400"), with_fields(seq, sent="-Infinity"),
        with_fields(seq, depth_scale="0"), with_fields(seq, source="[]"), with_fields(seq, stream="{}"),
        with_fields(seq, width="Infinity"), with_fields(seq, width="30000"), with_fields(seq, width="64.5"),
        with_fields(seq, bytes="1e400"), with_fields(seq, bytes="-1"), with_fields(seq, format='"NOPE"'),
        with_fields(seq, encoding="3"), with_fields(seq, frame_id='{"x": 1}'), with_fields(seq, stamp="NaN"),
        with_fields(seq, intrinsics='{"width": 64, "height": 48, "K": ["a"], "D": [], "distortion_model": ""}'),
        with_fields(seq, color='"everything"'),
    ]
    return [craft(text, payload) for text in texts]


def test_hostile_headers_are_garbage_and_nothing_else():
    for packet in hostile_headers(1):
        with pytest.raises(PacketError) as caught:
            decode(packet)
        assert caught.value.kind == "garbage", header_of(packet) if len(packet) < 20000 else packet[:80]
    assert decode(good(1)).color.data.shape == (48, 64, 3)


def jpeg_claiming(width: int, height: int) -> bytes:
    """A small real JPEG whose frame header is rewritten to claim ``width`` x ``height``."""
    ok, data = cv2.imencode(".jpg", np.full((48, 64, 3), 90, np.uint8))
    data = bytearray(data.tobytes())
    sof = data.index(b"\xff\xc0")
    struct.pack_into(">HH", data, sof + 5, height, width)
    return bytes(data)


def png16_claiming(width: int, height: int) -> bytes:
    ok, data = cv2.imencode(".png", np.full((48, 64), 1500, np.uint16))
    data = bytearray(data.tobytes())
    struct.pack_into(">II", data, 16, width, height)
    return bytes(data)


def sized(part: str, fmt: str, encoding: str, width: int, height: int, payload: bytes) -> bytes:
    header = {"seq": 1, "acquired": 1.0, "sent": 1.0, "source": "", "stream": "", "depth_scale": 1000.0,
              part: {"format": fmt, "encoding": encoding, "width": width, "height": height, "bytes": len(payload),
                     "stamp": None, "frame_id": "", "intrinsics": None}}
    return craft(header, payload)


@pytest.mark.parametrize("packet, words", [
    # an 877-byte JPEG claiming 30000 x 30000 pixels, the header agreeing: over the largest frame
    (sized("color", "BGR8", "jpeg", 30000, 30000, jpeg_claiming(30000, 30000)), "'width' is 30000"),
    # the header within the limit, the JPEG's own header not: found before OpenCV allocates
    (sized("color", "BGR8", "jpeg", 64, 48, jpeg_claiming(16000, 16000)), "jpeg payload is 16000x16000"),
    (sized("color", "BGR8", "jpeg", 640, 480, jpeg_claiming(640, 479)), "jpeg payload is 640x479"),
    (sized("depth", "DEPTH16", "png", 64, 48, png16_claiming(20000, 20000)), "png payload is 20000x20000"),
    (sized("depth", "DEPTH16", "png", 64, 48, cv2.imencode(".png", np.zeros((48, 64), np.uint8))[1].tobytes()),
     "1 channel(s) of 8 bits"),
    (sized("depth", "DEPTH16", "zstd", 16000, 16000, b"\x28\xb5\x2f\xfd" + bytes(20)), "'width' is 16000"),
    (sized("color", "RGB8", "raw", 64, 48, bytes(64 * 48 * 3 - 1)), "raw payload of 9215 bytes"),
])
def test_image_sizes_are_checked_before_decoding(packet, words):
    with pytest.raises(PacketError) as caught:
        decode(packet, FrameLimit(1920, 1080))
    assert caught.value.kind == "garbage" and words in str(caught.value)


@pytest.fixture
def stream():
    """A bare ZeroMQ publisher and a receiver rig (max_frame 640 x 480) connected to it."""
    port = free_port()
    publisher = zmq.Context.instance().socket(zmq.PUB)
    publisher.setsockopt(zmq.LINGER, 0)
    publisher.setsockopt(zmq.SNDHWM, 100000)  # the test decides what is sent, ZeroMQ drops nothing
    publisher.bind(f"tcp://127.0.0.1:{port}")
    receiver, sink = receiver_rig(f"tcp://127.0.0.1:{port}", max_frame=[640, 480])
    yield publisher, receiver, sink
    publisher.close(0)
    receiver.on_stop()


def subscribe(publisher, receiver) -> int:
    """Send good packets until one is delivered and the rest have arrived; returns the next
    sequence number to send."""
    seq = 1
    deadline = time.monotonic() + 10
    while receiver.frames == 0 and time.monotonic() < deadline:
        publisher.send(good(seq))
        seq += 1
        time.sleep(0.01)
        receiver.on_update()
    assert receiver.frames == 1
    assert drained(receiver, lambda counters: receiver.last_seq == seq - 1)
    return seq


def test_one_bad_packet_costs_one_packet(stream):
    """A hostile header between every two good packets: each is counted as garbage, every good one is
    delivered, and the latency mean stays a number."""
    publisher, receiver, sink = stream
    seq = subscribe(publisher, receiver)
    before = receiver.counters()
    hostile = hostile_headers(seq)
    for bad in hostile:
        publisher.send(bad)
        publisher.send(good(seq))
        assert drained(receiver, lambda counters: receiver.last_seq == seq)
        seq += 1
    after = receiver.counters()
    assert after["garbage"] - before["garbage"] == len(hostile)
    assert after["frames"] - before["frames"] == len(hostile)
    assert after["out_of_order"] == before["out_of_order"] and after["truncated"] == before["truncated"]
    assert after["dropped"] == before["dropped"]
    assert math.isfinite(after["latency_mean"]) and 0 <= after["latency_mean"] < 60
    assert sink.image.read_all()[-1].stamp.seq == seq - 1


def test_a_forged_sequence_number_costs_one_packet(stream):
    """seq 10^15 with the server's own stream id (below 2^53, so a valid number): refused until the
    next packet confirms the jump, so the server's packets after it are delivered, not out of order."""
    publisher, receiver, sink = stream
    seq = subscribe(publisher, receiver)
    before = receiver.counters()
    publisher.send(good(10 ** 15))
    for later in range(seq, seq + 20):
        publisher.send(good(later))
    assert drained(receiver, lambda counters: receiver.last_seq == seq + 19)
    after = receiver.counters()
    assert after["garbage"] - before["garbage"] == 1
    assert after["out_of_order"] == before["out_of_order"] and after["restarts"] == before["restarts"]
    # each of the 20 was delivered or superseded by a newer one; no gap was invented
    assert (after["frames"] - before["frames"]) + (after["dropped"] - before["dropped"]) == 20
    assert sink.image.read_all()[-1].stamp.seq == seq + 19


def test_a_long_gap_is_taken_once_the_next_packet_confirms_it(stream):
    """A server the receiver lost for longer than MAX_JUMP frames: one packet is held back, then the
    stream goes on."""
    publisher, receiver, sink = stream
    seq = subscribe(publisher, receiver) + MAX_JUMP + 50
    before = receiver.counters()
    for later in range(seq, seq + 5):
        publisher.send(good(later))
    assert drained(receiver, lambda counters: receiver.last_seq == seq + 4)
    after = receiver.counters()
    assert after["garbage"] - before["garbage"] == 1
    assert after["frames"] > before["frames"] and after["out_of_order"] == before["out_of_order"]


def test_zeromq_refuses_a_message_larger_than_the_largest_frame(stream):
    """ZeroMQ is told the largest packet (MAXMSGSIZE): a peer sending more is disconnected before the
    message is allocated (ZeroMQ then never connects again by itself), the receiver counts the
    disconnection and connects again, and the stream goes on."""
    publisher, receiver, sink = stream
    assert receiver._socket.getsockopt(zmq.MAXMSGSIZE) == FrameLimit(640, 480).packet_bytes
    seq = subscribe(publisher, receiver)
    before = receiver.counters()
    publisher.send(b"CCV1" + bytes(FrameLimit(640, 480).packet_bytes + 1))
    deadline = time.monotonic() + 10
    while receiver.last_seq < seq and time.monotonic() < deadline:  # resent until it is through
        publisher.send(good(seq))
        time.sleep(0.02)
        receiver.on_update()
    after = receiver.counters()
    assert receiver.last_seq >= seq
    assert after["bytes"] - before["bytes"] < FrameLimit(640, 480).packet_bytes, "the large one never came"
    assert after["garbage"] == before["garbage"] and after["truncated"] == before["truncated"]
    assert after["disconnects"] - before["disconnects"] == 1


def damaged(seq: int) -> bytes:
    """A packet whose header is right and whose JPEG is not (its entropy-coded data zeroed)."""
    packet = bytearray(good(seq))
    start = packet.index(b"\xff\xda")
    packet[start + 20:-2] = bytes(len(packet) - start - 22)
    return bytes(packet)


def test_under_a_flood_only_the_newest_packet_of_an_activation_is_decoded(stream):
    """Packets queued faster than they are delivered: each activation reads every header it drains
    (cheap) but decodes only the newest, so a superseded packet is a drop, not a decode, even when
    its payload is damaged; every packet is still accounted for."""
    publisher, receiver, sink = stream
    seq = subscribe(publisher, receiver)
    before = receiver.counters()
    count = 400
    for later in range(seq, seq + count):
        publisher.send(damaged(later) if later % 2 == 0 and later != seq + count - 1 else good(later))
    activations = 0
    deadline = time.monotonic() + 20
    while receiver.last_seq < seq + count - 1 and time.monotonic() < deadline:
        took = receiver.bytes
        receiver.on_update()
        activations += receiver.bytes != took
    after = receiver.counters()
    frames, garbage = after["frames"] - before["frames"], after["garbage"] - before["garbage"]
    dropped = after["dropped"] - before["dropped"]
    assert frames + garbage + dropped == count
    assert dropped > 0, "no activation took more than one packet: nothing was tested"
    assert frames + garbage == activations, "one decode per activation that took packets"
    assert sink.image.read_all()[-1].stamp.seq == seq + count - 1
