"""BagRgbdPeer: a rosbag2 recording of a camera's topics as the peer of an RgbdCameraReader.

It reads the bag with this package's reader and converters, so it lives here rather than in
coco_mr_vision, which this package depends on (the reader finds it by its registered name,
``BagRgbdPeer``, for its ``backend="bag"``; application files name it as before).
"""

from __future__ import annotations

import time
from typing import Any

from coco_core.attributes import Attribute
from coco_core.errors import CameraError
from coco_mr_vision.image import CameraIntrinsics, Image
from coco_mr_vision.rgbd import RGBDFrame
from coco_mr_vision.rgbd_peers import RgbdPeer

from ..bag import BagReader
from ..convert.compressed import CompressedImageConverter
from ..convert.images import CameraInfoConverter, ImageMessageConverter


class BagRgbdPeer(RgbdPeer):
    """A rosbag2 bag (MCAP or SQLite) with ``sensor_msgs/Image`` or ``CompressedImage`` colour and depth
    (image_transport's ``compressed`` and ``compressedDepth``, as librealsense records them) and
    ``sensor_msgs/CameraInfo``.

    Colour and depth are paired by header stamp (nearest within ``max_difference``), the newest
    CameraInfo gives the intrinsics. Messages go through this package's bag reader and image converters. A
    malformed message (an image encoding the converter does not read, a depth image that is not
    depth, colour and depth of different sizes, images that disagree with the camera_info) is
    skipped, counted in the profile's refused column and reported as damaged input; the frames
    after it are delivered."""

    path = Attribute(str, "", "the bag folder, .mcap or .db3 file")
    color_topic = Attribute(str, "/camera/color/image_raw", "colour images")
    depth_topic = Attribute(str, "/camera/depth/image_raw", "depth images registered to the colour ones")
    info_topic = Attribute(str, "/camera/color/camera_info", "camera intrinsics")
    max_difference = Attribute(float, 0.02, "largest colour/depth stamp difference paired, s", min=0.0)
    depth_scale = Attribute(float, 1000.0, "units per metre of 16UC1 depth (ROS: millimetres)", min=1e-9)
    realtime = Attribute(bool, False, "deliver the recording as the live camera did: each frame once the "
                         "time since the first one reaches its stamp's; frames the reader could not take in "
                         "time are skipped (the profile's merged column); false: the next frame at each grab")

    def on_config(self) -> None:
        try:
            self._reader = BagReader(self.path)
        except Exception as error:  # noqa: BLE001 - the bag layer's errors say what is wrong
            raise CameraError(f"{self.name}: cannot read the bag {self.path!r}: {error}") from None
        topics = set(self._reader.topics)
        missing = [t for t in (self.color_topic, self.depth_topic) if t not in topics]
        if missing:
            raise CameraError(f"{self.name}: bag {self.path!r} has no topic {', '.join(missing)}; "
                              f"it has {', '.join(sorted(topics))}")
        self._images, self._infos = ImageMessageConverter(copy=True), CameraInfoConverter()
        self._compressed = CompressedImageConverter()
        self.refused_messages = 0
        """Malformed messages skipped, over every pass of a looped recording."""
        self._start()

    def _start(self) -> None:
        wanted = [self.color_topic, self.depth_topic, self.info_topic]
        self._messages = self._reader.messages([t for t in wanted if t in self._reader.topics])
        self._intrinsics: CameraIntrinsics | None = None
        self._color: list[Image] = []
        self._depth: list[Image] = []
        self.exhausted = False
        self._pending: RGBDFrame | None = None
        """With realtime: the next frame, read but not due yet."""
        self._offset: float | None = None
        """With realtime: perf_counter time minus stamp of the recording's clock."""

    def grab(self) -> RGBDFrame | None:
        if not self.realtime:
            return self._next_pair()
        # Why: a replay that falls behind (a loaded machine, a slow reader) would deliver a scene
        # ever older than the other streams of the same recording (a hand, a robot); a live camera
        # never waits, it drops. The frame of the recording's present is delivered, never one early.
        now = time.perf_counter()
        frame = self._pending if self._pending is not None else self._next_pair()
        self._pending = None
        if frame is None or frame.stamp is None:
            return frame
        if self._offset is None:
            self._offset = now - frame.stamp
        if frame.stamp + self._offset > now:
            self._pending = frame
            return None
        while (later := self._next_pair()) is not None:
            if later.stamp is None or later.stamp + self._offset > now:
                self._pending = later
                break
            self.record_merged()  # superseded: a later frame is due already
            frame = later
        return frame

    def _next_pair(self) -> RGBDFrame | None:
        for message in self._messages:
            try:
                frame = self._take(message)
            except Exception as error:  # noqa: BLE001 - a malformed message must cost itself only
                self._refuse(message, error)
                continue
            if frame is not None:
                return frame
        self.exhausted = True
        return None

    def _take(self, message: Any) -> RGBDFrame | None:
        """The frame ``message`` completes, if any; raises when it is malformed (an encoding the
        converter does not read, a depth that is not depth, images of sizes that disagree with each
        other or with the camera_info)."""
        if message.topic == self.info_topic:
            self._intrinsics = self._infos.to_coco(message.message)
            return None
        converter = self._compressed if message.type == CompressedImageConverter.type_name else self._images
        image = converter.to_coco(message.message)
        (self._color if message.topic == self.color_topic else self._depth).append(image)
        return self._pair()

    def _refuse(self, message: Any, error: Exception) -> None:
        """Refuse a malformed message as damaged input (:meth:`Component.refuse_damaged_input`); the
        frames after it are delivered. Why: it raised out of the reader before, counted as the
        reader's error and nowhere else, and the run exited 0 as if the recording were sound."""
        self.refused_messages += 1
        offset = (message.log_time - self._reader.start_time) / 1e9
        self.refuse_damaged_input(self.path, f"the {message.topic} message {offset:.3f} s into the bag", error)

    def _pair(self) -> RGBDFrame | None:
        for depth in self._depth:
            for color in self._color:
                if color.stamp is not None and depth.stamp is not None and \
                        abs(color.stamp - depth.stamp) <= self.max_difference:
                    # Older unpaired images can never pair now: drop them with the pair.
                    self._color = [c for c in self._color if c.stamp is not None and c.stamp > color.stamp]
                    self._depth = [d for d in self._depth if d.stamp is not None and d.stamp > depth.stamp]
                    return RGBDFrame(color, depth, self._intrinsics, self.depth_scale)
        return None

    def rewind(self) -> bool:
        self._start()
        return True

    def on_stop(self) -> None:
        self._reader.close()
