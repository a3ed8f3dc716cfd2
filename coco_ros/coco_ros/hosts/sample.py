"""How one message crosses between hosts: a ``coco_interfaces/Sample`` made of what a connection's
``push`` receives, and the message the reader's side makes of it again.

What a writer's end receives is what the output port hands its connections: a
:class:`~coco_core.stamps.Message` (the value and the fields of its stamp: number on the port,
iteration of the writing activity, source port, time, user stamps), the message of a stamps-only
connection (its value the :class:`~coco_core.stamps.Stamp`), or, from a pooled output, the
:class:`~coco_core.pool.Slot` itself, its stamp fields in :attr:`Slot.message
<coco_core.pool.Slot.message>`. The Sample carries the stamp in fields of its own (readable without
the payload, by ``ros2 topic echo`` or a bag too) and the value in ``payload``, as the connection's
codec says:

- ``pickle`` (the default): the value pickled (protocol 5; numpy arrays go out of band, not pickled
  into bytes first: joined into the payload, which rclpy's setter copies once more; on the reader's
  side they are arrays over the received buffer, not copied). A pooled frame goes as :class:`Frame` (its array and its
  ``Slot.stamp``). The hosts of one application trust each other as the processes of one launch do
  (a pickle can run code): the DDS domain of an application is its own (``docs/hosts.md``);
- ``rgbd``: the same pickle, except that every :class:`~coco_mr_vision.rgbd.RGBDFrame` and
  :class:`~coco_mr_vision.image.Image` in the value goes through the vision stream codec
  (:mod:`coco_mr_vision.stream_codec`): JPEG colour (quality 90; GRAY8, RGB8 and BGR8; other colour
  formats raw), Zstandard depth (lossless 16-bit at the frame's depth scale: a DEPTH16 depth arrives
  exact, a DEPTH32F one at 1/depth_scale metres). Each image comes back in the format it left in,
  with its stamp, frame and intrinsics. A 640x480 Redwood frame is about 0.15 MB instead of 1.5 MB;
- ``stamp`` (stamps-only connections, FlowVR's dashed ones): no payload at all.

Times: a stamp's times are ``time.perf_counter`` seconds of the process that made them, a clock that
means nothing on another host. The writer converts them to the application's clock (``to_app``,
given by the caller: the hosts' clock offsets, ``docs/hosts.md``) and the reader back to its own
(``from_app``); identity by default. That holds for the Sample's stamp fields and for every
:class:`~coco_core.stamps.Stamp` inside the value too (a ``Stamped`` value's, a frame's
``Slot.stamp`` such as a mesh's), converted as they are pickled. An image's own ``stamp`` is on the
graph's time base (ROS time), not converted.

Damaged input (a payload that does not decode, an unknown codec, user stamps that are not user
stamps) raises :class:`~coco_core.errors.PacketError`: the reader's end counts and reports it
(:mod:`.channel`) and goes on.

The ``uint8[]`` fields are ``array.array('B')`` in rclpy, whose setter copies what it is given
(one C copy of ``bytes`` or of an ``array.array``; a ``memoryview`` it would iterate over byte by byte
in Python). Each encoder fills one Sample of its own again for every message (its writer publishes
it at once): making a Sample costs 12 us (37 us with ``check_fields``), filling one 4.5 us. A 1 MB
payload's extra copy in the setter costs 0.1 ms, against about 1.5 ms for DDS to carry it.
"""

from __future__ import annotations

import array
import copyreg
import functools
import io
import pickle
import struct
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from coco_core.errors import ChannelError, PacketError
from coco_core.pool import Slot
from coco_core.stamps import NO_USER_STAMPS, Message, Stamp, UserStamps
from coco_interfaces.msg import Sample

Clock = Callable[[float], float]
"""Converts a time in seconds from one clock to another (``time.perf_counter`` of this process to
the application's clock on the writer's side, back on the reader's)."""

STAMP_CODEC = "stamp"
"""The codec of a stamps-only connection's samples: the stamp fields, no payload."""
PAYLOAD_CODECS = ("pickle", "rgbd")
JPEG_FORMATS = ("GRAY8", "RGB8", "BGR8")
"""Colour formats the rgbd codec sends as JPEG; the others go raw (lossless)."""
JPEG_QUALITY = 90

_COUNT = struct.Struct("<I")


def same_clock(seconds: float) -> float:
    """The default :data:`Clock`: both hosts' times are the same (one host, or clocks synchronised
    by PTP as in the paper)."""
    return seconds


@dataclass(frozen=True, slots=True)
class Frame:
    """A pooled output's frame as it crosses between hosts: the slot's array and its
    :attr:`Slot.stamp <coco_core.pool.Slot.stamp>` (e.g. a mesh's layout and counts). The reader's
    end copies it into a slot of its own pool (:class:`~.channel.DdsFrameReader`)."""

    array: np.ndarray
    stamp: Any


def _app_stamp(time: float, seq: int, source: str, steps: tuple[tuple[str, float], ...], it: int,
               user: UserStamps) -> Stamp:
    """A :class:`Stamp` pickled by a writer's end, its times on the application's clock. The
    reader's end converts them back instead (:class:`SampleDecoder`): this is what a plain
    ``pickle.loads`` of a payload gives."""
    return Stamp(time, seq, source, steps, it, user)


@functools.lru_cache(maxsize=64)
def _table(parts: int) -> struct.Struct:
    """The lengths that lead a payload: the pickle's, then each out-of-band buffer's."""
    return struct.Struct(f"<I{parts + 1}Q")


class SampleEncoder:
    """The writer's side: Samples of the messages one connection's ``push`` receives, with ``codec``
    (``pickle``, ``rgbd`` or ``stamp``). One encoder per writer's end, used by the writing port's
    thread only: its pickler and buffer are reused from one message to the next (their making was a
    third of a small sample's encoding between processes, :mod:`coco_core.shm.channel`)."""

    def __init__(self, codec: str, to_app: Clock = same_clock) -> None:
        if codec != STAMP_CODEC and codec not in PAYLOAD_CODECS:
            raise ChannelError(f"unknown codec {codec!r} of a connection between hosts; expected one of "
                               f"{', '.join((*PAYLOAD_CODECS, STAMP_CODEC))}")
        self.codec = codec
        self.to_app = to_app
        self._out = io.BytesIO()
        self._parts: list[pickle.PickleBuffer] = []
        self._pickler = pickle.Pickler(self._out, 5, buffer_callback=self._parts.append)
        table: dict[Any, Any] = {**copyreg.dispatch_table, Stamp: self._reduce_stamp}
        if codec == "rgbd":
            from coco_mr_vision.image import Image
            from coco_mr_vision.rgbd import RGBDFrame

            table[RGBDFrame] = _reduce_rgbd_frame
            table[Image] = _reduce_image
        self._pickler.dispatch_table = table
        self._sample = Sample()

    def _reduce_stamp(self, stamp: Stamp) -> tuple[Any, ...]:
        to_app = self.to_app
        return _app_stamp, (to_app(stamp.time), stamp.seq, stamp.source,
                            tuple((name, to_app(at)) for name, at in stamp.steps), stamp.it, stamp.user)

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
        sample.user = self._dump(user) if user else b""
        sample.codec = self.codec
        sample.payload = self._dump(value) if self.codec != STAMP_CODEC else b""
        sample.sent = to_app(time.perf_counter())
        return sample

    def done(self, number: int, routed_away: int = 0) -> Sample:
        """The sample that tells the reader the writer finished after ``number`` writes (and
        ``routed_away`` messages routed to other connections)."""
        sample = Sample()
        sample.number = number
        sample.routed_away = routed_away
        sample.writer_done = True
        sample.codec = self.codec
        sample.sent = self.to_app(time.perf_counter())
        return sample

    def _dump(self, value: Any) -> bytes:
        """``value`` pickled into a payload: the table of lengths, the pickle, the out-of-band buffers."""
        out, parts, pickler = self._out, self._parts, self._pickler
        try:
            out.seek(0)
            out.truncate()
            pickler.dump(value)
            raws = [part.raw() for part in parts]
            with out.getbuffer() as data:  # released at once: the BytesIO cannot be reused while a view lives
                table = _table(len(raws)).pack(len(raws), data.nbytes, *(raw.nbytes for raw in raws))
                return b"".join((table, data, *raws))
        finally:
            parts.clear()
            pickler.clear_memo()


class _Unpickler(pickle.Unpickler):
    """Unpickles a payload, the stamps in it converted back from the application's clock."""

    def __init__(self, data: memoryview, buffers: list[memoryview], stamp: Callable[..., Stamp]) -> None:
        super().__init__(io.BytesIO(data), buffers=buffers)
        self._stamp = stamp

    def find_class(self, module: str, name: str) -> Any:
        if module == __name__ and name == _app_stamp.__name__:
            return self._stamp
        return super().find_class(module, name)


class SampleDecoder:
    """The reader's side: the message a Sample carries, as the writer's port made it, its times on
    this process's clock (``from_app``)."""

    def __init__(self, from_app: Clock = same_clock) -> None:
        self.from_app = from_app

    def _stamp(self, time: float, seq: int, source: str, steps: tuple[tuple[str, float], ...], it: int,
               user: UserStamps) -> Stamp:
        from_app = self.from_app
        return Stamp(from_app(time), seq, source, tuple((name, from_app(at)) for name, at in steps), it, user)

    def decode(self, sample: Sample) -> Any:
        """A :class:`Message` (a :class:`Stamp` its value for a stamps-only sample, a :class:`Frame`
        for a pooled frame's), or the bare value of a sample without a message (``seq`` 0);
        :class:`PacketError` when the sample does not decode."""
        try:
            return self._decode(sample)
        except PacketError:
            raise
        except Exception as error:  # whatever a damaged pickle makes pickle, numpy or a codec raise
            raise PacketError("garbage", f"sample {sample.number} ({sample.codec}) does not decode: "
                              f"{type(error).__name__}: {error}") from None

    def _decode(self, sample: Sample) -> Any:
        user = self._load(sample.user) if len(sample.user) else NO_USER_STAMPS
        if not isinstance(user, UserStamps):
            raise PacketError("garbage", f"sample {sample.number}: its user stamps are a {type(user).__name__}")
        from_app = self.from_app
        at = from_app(sample.time)
        codec = sample.codec
        if codec == STAMP_CODEC:
            steps = tuple(zip(sample.step_names, map(from_app, sample.step_times)))
            value: Any = Stamp(at, sample.seq, sample.source, steps, sample.it, user)
        elif codec in PAYLOAD_CODECS:
            value = self._load(sample.payload)
        else:
            raise PacketError("garbage", f"sample {sample.number}: unknown codec {codec!r}; expected one of "
                              f"{', '.join((*PAYLOAD_CODECS, STAMP_CODEC))}")
        if not sample.seq:
            return value
        return Message(value, at, sample.seq, sample.source, sample.it, user)

    def _load(self, payload: array.array[int]) -> Any:
        """The value pickled in ``payload``; its arrays are views of the payload's memory."""
        view = memoryview(payload)
        count = _COUNT.unpack_from(view)[0]
        if count > len(view) // 8:
            raise PacketError("garbage", f"a payload of {len(view)} bytes cannot hold {count} buffers")
        table = _table(count)
        _, pickled, *lengths = table.unpack_from(view)
        at = table.size + pickled
        if at + sum(lengths) != len(view):
            raise PacketError("garbage", f"a payload of {len(view)} bytes, its table says {at + sum(lengths)}")
        parts = []
        for length in lengths:
            parts.append(view[at:at + length])
            at += length
        return _Unpickler(view[table.size:table.size + pickled], parts, self._stamp).load()


# --- the rgbd codec: images through the vision stream codec -----------------------------------------

def _reduce_image(image: Any) -> tuple[Any, ...]:
    """An :class:`~coco_mr_vision.image.Image` as a stream packet (colour or depth alone)."""
    from coco_mr_vision.stream_codec import encode

    if image.format.is_depth:
        packet = encode(1, 0.0, 0.0, None, image)
    else:
        packet = encode(1, 0.0, 0.0, image, None, color_encoding=_color_encoding(image), quality=JPEG_QUALITY)
    return _image, (pickle.PickleBuffer(packet), image.format.value)


def _reduce_rgbd_frame(frame: Any) -> tuple[Any, ...]:
    """An :class:`~coco_mr_vision.rgbd.RGBDFrame` as one stream packet, and what the packet does not
    hold: the formats it left in, the frame's own intrinsics and its depth scale."""
    from coco_mr_vision.stream_codec import encode

    color, depth = frame.color, frame.depth
    packet = encode(1, 0.0, 0.0, color, depth, depth_scale=frame.depth_scale, color_encoding=_color_encoding(color),
                    quality=JPEG_QUALITY)
    return _rgbd_frame, (pickle.PickleBuffer(packet), color.format.value, depth.format.value, frame.intrinsics,
                         frame.depth_scale)


def _color_encoding(image: Any) -> str:
    return "jpeg" if image.format.value in JPEG_FORMATS else "raw"


def _image(packet: memoryview, image_format: str) -> Any:
    """The image of a packet that :func:`_reduce_image` made, in the format it left in."""
    from coco_mr_vision.stream_codec import decode

    frame = decode(packet)
    image = frame.depth if frame.depth is not None else frame.color
    if image is None:
        raise PacketError("garbage", "an image's packet holds no image")
    return image.to(image_format)


def _rgbd_frame(packet: memoryview, color_format: str, depth_format: str, intrinsics: Any,
                depth_scale: float) -> Any:
    """The frame of a packet that :func:`_reduce_rgbd_frame` made."""
    from coco_mr_vision.rgbd import RGBDFrame
    from coco_mr_vision.stream_codec import decode

    frame = decode(packet)
    if frame.color is None or frame.depth is None:
        raise PacketError("garbage", "an RGB-D frame's packet lacks its colour or its depth")
    return RGBDFrame(frame.color.to(color_format), frame.depth.to(depth_format, depth_scale), intrinsics, depth_scale)
