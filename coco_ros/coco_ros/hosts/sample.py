"""How one message crosses between hosts: a ``coco_interfaces/Sample`` made of what a connection's
``push`` receives, sealed with the application's key, and the message the reader's side makes of it.

What a writer's end receives is what the output port hands its connections: a
:class:`~coco_core.stamps.Message` (the value and the fields of its stamp: number on the port,
iteration of the writing activity, source port, time, user stamps), the message of a stamps-only
connection (its value the :class:`~coco_core.stamps.Stamp`), or, from a pooled output, the
:class:`~coco_core.pool.Slot` itself, its stamp fields in :attr:`Slot.message
<coco_core.pool.Slot.message>`. The Sample carries the stamp in fields of its own (readable without
the payload, by ``ros2 topic echo`` or a bag too) and the value in ``payload``, as the connection's
codec says:

- ``plain`` (the default): the value in the typed encoding of :mod:`coco_core.wire`, which builds
  plain data and registered value types only, never a pickle (a pickle from the network could run
  any code). Numpy arrays go out of band (after the packed part: on the reader's side they are
  arrays over the received buffer, not copied). A pooled frame goes as :class:`Frame` (its array
  and its ``Slot.stamp``);
- ``rgbd``: the same, except that every :class:`~coco_mr_vision.rgbd.RGBDFrame` and
  :class:`~coco_mr_vision.image.Image` in the value goes through the vision stream codec
  (:mod:`coco_mr_vision.stream_codec`): JPEG colour (quality 90; GRAY8, RGB8 and BGR8; other colour
  formats raw), Zstandard depth (lossless 16-bit at the frame's depth scale: a DEPTH16 depth arrives
  exact, a DEPTH32F one at 1/depth_scale metres). Each image comes back in the format it left in,
  with its stamp, frame and intrinsics. A 640x480 Redwood frame is about 0.15 MB instead of 1.5 MB;
- ``stamp`` (stamps-only connections, FlowVR's dashed ones): no payload at all.

Every sample is sealed (:mod:`coco_core.hosts.auth`): its ``sender``, ``session``, ``counter``,
``wall`` and ``mac`` fields authenticate every other field and the topic with the application's
key. The reader's end checks the seal before anything is decoded (:func:`sample_parts` lists what
the MAC covers).

Times: a stamp's times are ``time.perf_counter`` seconds of the process that made them, a clock that
means nothing on another host. The writer converts them to the application's clock (``to_app``,
given by the caller: the hosts' clock offsets, ``docs/hosts.md``) and the reader back to its own
(``from_app``); identity by default. That holds for the Sample's stamp fields and for every
:class:`~coco_core.stamps.Stamp` inside the value too (a ``Stamped`` value's, a frame's
``Slot.stamp`` such as a mesh's). An image's own ``stamp`` is on the graph's time base (ROS time),
not converted.

Damaged input (a payload that does not decode, an unknown codec, stamps that are not finite, write
numbers out of range) raises :class:`~coco_core.errors.PacketError`: the reader's end counts and
reports it (:mod:`.channel`) and goes on.

The ``uint8[]`` fields are ``array.array('B')`` in rclpy, whose setter copies what it is given
(one C copy of ``bytes`` or of an ``array.array``; a ``memoryview`` it would iterate over byte by byte
in Python). Each encoder fills one Sample of its own again for every message (its writer publishes
it at once): making a Sample costs 12 us (37 us with ``check_fields``), filling one 4.5 us. A 1 MB
payload's extra copy in the setter costs 0.1 ms, against about 1.5 ms for DDS to carry it.
"""

from __future__ import annotations

import math
import struct
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import msgpack
import numpy as np

from coco_core.errors import ChannelError, PacketError
from coco_core.hosts.auth import Sealer
from coco_core.pool import Slot
from coco_core.stamps import NO_USER_STAMPS, Message, Stamp, UserStamps
from coco_core.wire import FIRST_EXTENSION, Clock, Decoder, Encoder, Pack, Unpack, same_clock, value_type
from coco_interfaces.msg import Sample

from .seal import sealed

STAMP_CODEC = "stamp"
"""The codec of a stamps-only connection's samples: the stamp fields, no payload."""
PAYLOAD_CODECS = ("plain", "rgbd")
JPEG_FORMATS = ("GRAY8", "RGB8", "BGR8")
"""Colour formats the rgbd codec sends as JPEG; the others go raw (lossless)."""
JPEG_QUALITY = 90
IMAGE, RGBD_FRAME = FIRST_EXTENSION, FIRST_EXTENSION + 1
"""The rgbd codec's extension codes (:mod:`coco_core.wire`)."""
MAX_NUMBER = 2 ** 53
"""Write numbers and counts beyond this are refused: no connection writes that much, and the
profile would show absurd figures."""

_FIELDS = struct.Struct("<QqqddQ?I")


@value_type
@dataclass(frozen=True, slots=True)
class Frame:
    """A pooled output's frame as it crosses between hosts: the slot's array and its
    :attr:`Slot.stamp <coco_core.pool.Slot.stamp>` (e.g. a mesh's layout and counts). The reader's
    end copies it into a slot of its own pool (:class:`~.channel.DdsFrameReader`)."""

    array: np.ndarray
    stamp: Any


def sample_parts(sample: Sample) -> Iterator[Any]:
    """What a Sample's seal covers besides the topic and the seal's own fields: every other field."""
    yield _FIELDS.pack(sample.number, sample.seq, sample.it, sample.time, sample.sent, sample.routed_away,
                       sample.writer_done, len(sample.step_names))
    yield sample.source
    yield sample.codec
    yield from sample.step_names
    yield sample.step_times
    yield sample.user
    yield sample.payload


class SampleEncoder:
    """The writer's side: Samples of the messages one connection's ``push`` receives, with ``codec``
    (``plain``, ``rgbd`` or ``stamp``), each sealed by ``sealer``. One encoder per writer's end,
    used by the writing port's thread only."""

    def __init__(self, codec: str, sealer: Sealer, to_app: Clock = same_clock) -> None:
        if codec != STAMP_CODEC and codec not in PAYLOAD_CODECS:
            raise ChannelError(f"unknown codec {codec!r} of a connection between hosts; expected one of "
                               f"{', '.join((*PAYLOAD_CODECS, STAMP_CODEC))}")
        self.codec = codec
        self.sealer = sealer
        self.to_app = to_app
        extensions: dict[type, Any] = {}
        if codec == "rgbd":
            from coco_mr_vision.image import Image
            from coco_mr_vision.rgbd import RGBDFrame

            extensions = {RGBDFrame: _rgbd_frame_extension, Image: _image_extension}
        self._encoder = Encoder(to_app, extensions)
        self._sample = Sample()

    def encode(self, item: Any, number: int, routed_away: int = 0) -> Sample:
        """The Sample of ``item`` (a :class:`Message`, a pooled :class:`Slot`, or a bare value pushed
        without a port, which arrives bare), the ``number``-th write on its connection, after
        ``routed_away`` messages its writer's Split or Cull kept from it: this encoder's own Sample,
        filled again by the next call (publish it before)."""
        to_app = self.to_app
        if type(item) is Message:
            stamp = item.stamp
            value: Any = item.value
            seq, it, source, user = item.seq, item.it, item.source, item.user
        elif type(item) is Slot:
            message = item.message
            value = Frame(item.array, item.stamp)
            stamp = message.stamp if message is not None else Stamp.now()
            seq, it, source, user = stamp.seq, stamp.it, stamp.source, stamp.user
        else:
            value, stamp, seq, it, source, user = item, Stamp.now(), 0, -1, "", NO_USER_STAMPS
        sample = self._sample
        sample.number = number
        sample.routed_away = routed_away
        sample.seq, sample.it, sample.source = seq, it, source
        sample.time = to_app(stamp.time)
        sample.step_names = [name for name, _ in stamp.steps]
        sample.step_times = [to_app(at) for _, at in stamp.steps]
        sample.user = self._encoder.encode(dict(user)) if user else b""
        sample.codec = self.codec
        sample.payload = self._encoder.encode(value) if self.codec != STAMP_CODEC else b""
        sample.sent = to_app(time.perf_counter())
        return self._seal(sample)

    def done(self, number: int, routed_away: int = 0) -> Sample:
        """The sample that tells the reader the writer finished after ``number`` writes (and
        ``routed_away`` messages routed to other connections)."""
        sample = Sample()
        sample.number = number
        sample.routed_away = routed_away
        sample.writer_done = True
        sample.codec = self.codec
        sample.sent = self.to_app(time.perf_counter())
        return self._seal(sample)

    def _seal(self, sample: Sample) -> Sample:
        return sealed(sample, self.sealer, sample_parts(sample))


class SampleDecoder:
    """The reader's side: the message a Sample carries, as the writer's port made it, its times on
    this process's clock (``from_app``). The Sample's seal was checked before (:mod:`.channel`)."""

    def __init__(self, from_app: Clock = same_clock) -> None:
        self.from_app = from_app
        self._decoder = Decoder(from_app, {IMAGE: _image, RGBD_FRAME: _rgbd_frame})

    def decode(self, sample: Sample) -> Any:
        """A :class:`Message` (a :class:`Stamp` its value for a stamps-only sample, a :class:`Frame`
        for a pooled frame's), or the bare value of a sample without a message (``seq`` 0);
        :class:`PacketError` when the sample does not decode."""
        check_numbers(sample)
        try:
            return self._decode(sample)
        except PacketError as error:
            raise PacketError(error.kind, f"sample {sample.number} ({sample.codec}) does not decode: {error}") from None

    def _decode(self, sample: Sample) -> Any:
        user = self._decoder.decode(sample.user) if len(sample.user) else NO_USER_STAMPS
        if type(user) is dict and all(type(name) is str and name for name in user):
            user = UserStamps(user)
        elif user is not NO_USER_STAMPS:
            raise PacketError("garbage", f"its user stamps are a {type(user).__name__}")
        from_app = self.from_app
        at = from_app(sample.time)
        codec = sample.codec
        if codec == STAMP_CODEC:
            steps = tuple(zip(sample.step_names, map(from_app, sample.step_times)))
            value: Any = Stamp(at, sample.seq, sample.source, steps, sample.it, user)
        elif codec in PAYLOAD_CODECS:
            value = self._decoder.decode(sample.payload)
        else:
            raise PacketError("garbage", f"an unknown codec {codec!r}; expected one of "
                                         f"{', '.join((*PAYLOAD_CODECS, STAMP_CODEC))}")
        if not sample.seq:
            return value
        return Message(value, at, sample.seq, sample.source, sample.it, user)


def check_numbers(sample: Sample) -> None:
    """A :class:`PacketError` when a sample's numbers cannot be a writer's: a count beyond
    :data:`MAX_NUMBER` or a time that is not finite (the profile would show absurd figures, a
    latency NaN)."""
    problem = ""
    if not 0 <= sample.number <= MAX_NUMBER or (sample.number == 0 and not sample.writer_done):
        problem = f"write number {sample.number} out of range (1 to 2^53)"
    elif not 0 <= sample.routed_away <= MAX_NUMBER or not -1 <= sample.seq <= MAX_NUMBER:
        problem = f"counts out of range (seq {sample.seq}, routed away {sample.routed_away})"
    elif not (math.isfinite(sample.time) and math.isfinite(sample.sent) and all(map(math.isfinite, sample.step_times))):
        problem = "a stamp time that is not a finite number"
    elif len(sample.step_names) != len(sample.step_times):
        problem = f"{len(sample.step_names)} step names for {len(sample.step_times)} step times"
    if problem:
        raise PacketError("garbage", f"sample {sample.number}: {problem}")


# --- the rgbd codec: images through the vision stream codec -----------------------------------------

def _image_extension(image: Any, pack: Pack) -> msgpack.ExtType:
    """An :class:`~coco_mr_vision.image.Image` as a stream packet (colour or depth alone)."""
    from coco_mr_vision.stream_codec import encode

    if image.format.is_depth:
        packet = encode(1, 0.0, 0.0, None, image)
    else:
        packet = encode(1, 0.0, 0.0, image, None, color_encoding=_color_encoding(image), quality=JPEG_QUALITY)
    return msgpack.ExtType(IMAGE, pack([packet, image.format.value]))


def _rgbd_frame_extension(frame: Any, pack: Pack) -> msgpack.ExtType:
    """An :class:`~coco_mr_vision.rgbd.RGBDFrame` as one stream packet, and what the packet does not
    hold: the formats it left in, the frame's own intrinsics and its depth scale."""
    from coco_mr_vision.stream_codec import encode

    color, depth = frame.color, frame.depth
    packet = encode(1, 0.0, 0.0, color, depth, depth_scale=frame.depth_scale, color_encoding=_color_encoding(color),
                    quality=JPEG_QUALITY)
    return msgpack.ExtType(RGBD_FRAME, pack([packet, color.format.value, depth.format.value, frame.intrinsics,
                                             frame.depth_scale]))


def _color_encoding(image: Any) -> str:
    return "jpeg" if image.format.value in JPEG_FORMATS else "raw"


def _image(data: bytes, unpack: Unpack) -> Any:
    """The image of a packet that :func:`_image_extension` made, in the format it left in."""
    from coco_mr_vision.stream_codec import decode

    packet, image_format = _parts(unpack(data), 2)
    frame = decode(packet)
    image = frame.depth if frame.depth is not None else frame.color
    if image is None:
        raise PacketError("garbage", "an image's packet holds no image")
    return image.to(image_format)


def _rgbd_frame(data: bytes, unpack: Unpack) -> Any:
    """The frame of a packet that :func:`_rgbd_frame_extension` made."""
    from coco_mr_vision.image import CameraIntrinsics
    from coco_mr_vision.rgbd import RGBDFrame
    from coco_mr_vision.stream_codec import decode

    packet, color_format, depth_format, intrinsics, depth_scale = _parts(unpack(data), 5)
    if not (intrinsics is None or isinstance(intrinsics, CameraIntrinsics)) or type(depth_scale) is not float:
        raise PacketError("garbage", "an RGB-D frame's intrinsics or depth scale are not those of a frame")
    frame = decode(packet)
    if frame.color is None or frame.depth is None:
        raise PacketError("garbage", "an RGB-D frame's packet lacks its colour or its depth")
    return RGBDFrame(frame.color.to(color_format), frame.depth.to(depth_format, depth_scale), intrinsics, depth_scale)


def _parts(items: Any, count: int) -> list[Any]:
    if type(items) is not list or len(items) != count or type(items[0]) is not bytes:
        raise PacketError("garbage", "an image extension that is not one")
    return items
