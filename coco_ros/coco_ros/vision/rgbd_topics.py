"""TopicRgbdPeer: a ROS 2 camera driver's topics as the peer of an RgbdCameraReader.

The paper's RgbdCameraReader has one peer per camera SDK; on a ROS 2 robot the camera is already
driven by its vendor's node (realsense2_camera, orbbec_camera, zed_wrapper, ...), which publishes
colour, depth registered to colour and the colour camera's CameraInfo. This peer subscribes to the
three topics on the ROS launcher's node, pairs colour and depth by header stamp as message_filters'
ApproximateTimeSynchronizer does (:mod:`.approximate_time`: ``queue_size`` and ``slop``), takes the
newest CameraInfo as the intrinsics (a pair before the first CameraInfo is dropped, counted), and delivers the newest pair at each grab, as a live camera
does: pairs the reader did not take in time are counted in the profile's ``merged`` column, with the
images that never found a partner; a malformed message (an encoding the converter does not read,
colour and depth of different sizes) is refused and counted in the ``refused`` column.

The defaults are realsense2_camera's topic names (its node ``camera`` in the namespace ``camera``,
depth aligned to colour: ``align_depth.enable:=true``); docs/vision.md lists those of other drivers.
The subscriptions are best effort by default, which matches both a sensor-data publisher (best
effort, what camera drivers use) and a reliable one; ``reliability="reliable"`` asks a reliable
publisher (a recording played with ``coco-replay``) to repair what a loaded machine lost (a frame is
hundreds of kilobytes: one lost fragment loses it), and matches reliable publishers only.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from typing import Any

from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from coco_core.attributes import Attribute
from coco_core.errors import CameraError
from coco_core.operations import operation
from coco_mr_vision.image import CameraIntrinsics
from coco_mr_vision.rgbd import RGBDFrame
from coco_mr_vision.rgbd_peers import RgbdPeer

from ..convert.images import CameraInfoConverter, ImageMessageConverter
from ..interface.component import launcher_node
from .approximate_time import ApproximateTime

log = logging.getLogger("coco.vision")

COLOR, DEPTH = 0, 1


class TopicRgbdPeer(RgbdPeer):
    """Colour, depth and CameraInfo from a ROS 2 camera driver's topics (see the module docstring)."""

    color_topic = Attribute(str, "/camera/camera/color/image_raw", "colour images (sensor_msgs/Image)")
    depth_topic = Attribute(str, "/camera/camera/aligned_depth_to_color/image_raw",
                            "depth images registered to the colour ones (sensor_msgs/Image, 16UC1 or 32FC1)")
    info_topic = Attribute(str, "/camera/camera/color/camera_info", "the colour camera's intrinsics")
    queue_size = Attribute(int, 10, "images of each topic kept while waiting for their partner", min=1)
    slop = Attribute(float, 0.02, "largest colour/depth stamp difference paired, s", min=0.0)
    depth_scale = Attribute(float, 1000.0, "units per metre of 16UC1 depth (ROS: millimetres)", min=1e-9)
    reliability = Attribute(str, "best_effort", "the subscriptions' QoS reliability: best_effort (matches any "
                            "publisher) or reliable (lost fragments repaired; reliable publishers only)",
                            choices=("best_effort", "reliable"))

    def on_config(self) -> None:
        node, group = launcher_node(self)
        self._node = node
        self._images, self._infos = ImageMessageConverter(copy=True), CameraInfoConverter()
        self._pairing = ApproximateTime(2, self.queue_size, self.slop)
        self._frames: deque[RGBDFrame] = deque(maxlen=self.queue_size)
        self._intrinsics: CameraIntrinsics | None = None
        self._lock = threading.Lock()
        self.received = [0, 0, 0]
        """Messages taken from the colour, depth and CameraInfo topics."""
        self.paired = 0
        self.waiting_for_intrinsics = 0
        """Pairs dropped because no CameraInfo had come yet."""
        self._unpaired_counted = 0
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=self.queue_size,
                         reliability=ReliabilityPolicy.RELIABLE if self.reliability == "reliable"
                         else ReliabilityPolicy.BEST_EFFORT)
        message = self._images.message_type
        # The CameraInfo first: a wait set takes what is ready in this order, so a frame's intrinsics
        # that came with it are known when its images pair.
        self._subscriptions = [
            node.create_subscription(self._infos.message_type, self.info_topic, self._info, qos, callback_group=group,
                                     raw=True),
            node.create_subscription(message, self.color_topic, lambda data: self._image(COLOR, data), qos,
                                     callback_group=group, raw=True),
            node.create_subscription(message, self.depth_topic, lambda data: self._image(DEPTH, data), qos,
                                     callback_group=group, raw=True)]
        log.info("%s: colour %s, depth %s, intrinsics %s (paired within %g s, %d queued)", self.name,
                 self.color_topic, self.depth_topic, self.info_topic, self.slop, self.queue_size)

    def _image(self, topic: int, data: bytes) -> None:
        self.received[topic] += 1
        try:
            image = self._images.from_cdr(data)
            if topic == DEPTH and not image.format.is_depth:
                raise CameraError(f"{self.depth_topic} carries {image.format.name} images, not depth (16UC1 or 32FC1)")
            if image.stamp is None:
                raise CameraError("an image without a header stamp cannot be paired")
        except Exception as error:  # noqa: BLE001 - a malformed message costs itself only
            self.record_refusal(f"an image from {self.color_topic if topic == COLOR else self.depth_topic}", error)
            return
        with self._lock:
            pair = self._pairing.add(topic, round(image.stamp * 1e9), image)
            if pair is None:
                return
            color, depth = pair
            if self._intrinsics is None:  # a frame no mesh can use: the driver's camera_info comes with each frame
                self.waiting_for_intrinsics += 1
                return
            try:
                frame = RGBDFrame(color, depth, self._intrinsics, self.depth_scale)
            except Exception as error:  # noqa: BLE001 - images that disagree are refused, not raised
                self.record_refusal(f"a colour/depth pair stamped {color.stamp:.6f}", error)
                return
            self.paired += 1
            self._frames.append(frame)

    def _info(self, data: bytes) -> None:
        self.received[2] += 1
        try:
            intrinsics = self._infos.from_cdr(data)
        except Exception as error:  # noqa: BLE001
            self.record_refusal(f"a camera_info from {self.info_topic}", error)
            return
        self._intrinsics = intrinsics

    def grab(self) -> RGBDFrame | None:
        with self._lock:
            if not self._frames:
                return None
            frame = self._frames.pop()
            superseded = len(self._frames)
            self._frames.clear()
            unpaired = self._pairing.unpaired - self._unpaired_counted
            self._unpaired_counted += unpaired
        if superseded or unpaired:  # what a live camera's reader never sees: merged into a later frame
            self.record_merged(superseded + unpaired)
        return frame

    @operation
    def counts(self) -> dict[str, int]:
        """Colour, depth and CameraInfo messages taken, frames paired, and images never paired."""
        return {"color": self.received[COLOR], "depth": self.received[DEPTH], "camera_info": self.received[2],
                "paired": self.paired, "unpaired": self._pairing.unpaired}

    def on_stop(self) -> None:
        node = getattr(self, "_node", None)
        if node is None:
            return
        for subscription in self._subscriptions:
            node.destroy_subscription(subscription)
        self._node = None
        log.info("%s: %d colour, %d depth, %d camera_info messages; %d frames paired, %d images unpaired, %d "
                 "refused", self.name, *self.received, self.paired, self._pairing.unpaired, self.stats.refused)

