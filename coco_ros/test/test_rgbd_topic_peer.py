"""A ROS 2 camera driver's topics as the RgbdCameraReader's peer (coco_ros.vision.rgbd_topics), and
the pairing by header stamp it uses (message_filters' ApproximateTimeSynchronizer's). The peer is
hosted in-process by ExecutorHost; a publisher node of the same context plays the driver, with the
realsense2_camera driver's topic names and sensor-data QoS. Domain 158, localhost only."""

from __future__ import annotations

import time

import numpy as np
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo
from sensor_msgs.msg import Image as ImageMsg

from coco_core import Application, Component, InputPort, PeriodicActivity
from coco_mr_vision.image import CameraIntrinsics, Image, ImageFormat
from coco_mr_vision.rgbd import RGBDFrame
from coco_mr_vision.rgbd_reader import RgbdCameraReader
from coco_ros.convert.images import CameraInfoConverter, ImageMessageConverter
from coco_ros.vision.approximate_time import ApproximateTime
from test_launcher_hosting import BUFFERED, Hosting, wait_until

COLOR, DEPTH, INFO = ("/camera/camera/color/image_raw", "/camera/camera/aligned_depth_to_color/image_raw",
                      "/camera/camera/color/camera_info")


def test_pairs_are_the_nearest_stamps_within_the_slop_and_the_lost_are_counted() -> None:
    sync = ApproximateTime(2, queue_size=3, slop=0.010)
    ms = 1_000_000
    assert sync.add(0, 100 * ms, "c100") is None
    assert sync.add(1, 130 * ms, "d130") is None  # 30 ms apart: no pair
    assert sync.add(0, 133 * ms, "c133") == ["c133", "d130"]
    assert sync.add(1, 200 * ms, "d200") is None
    assert sync.add(0, 195 * ms, "c195") == ["c195", "d200"]
    for stamp in (300, 400, 500, 600):  # colour alone: the queue keeps 3, the oldest are lost
        sync.add(0, stamp * ms, f"c{stamp}")
    assert sync.unpaired == 2  # c100, then c300, pushed out of the full queue
    assert sync.add(1, 604 * ms, "d604") == ["c600", "d604"]
    assert sync.add(0, 350 * ms, "c350") is None
    assert sync.add(0, 340 * ms, "c340") is None and sync.unpaired == 3  # older than the full queue: pushed out
    assert sync.add(1, 2000 * ms, "d2000") is None
    assert sync.add(1, 50 * ms, "d50") is None  # a jump back in time (a recording played again): start again
    assert sync.jumps == 1 and sync.unpaired == 7 and sync.add(0, 52 * ms, "c52") == ["c52", "d50"]
    with pytest.raises(ValueError):
        ApproximateTime(1, 3, 0.01)


class Frames(Component):
    rgbd = InputPort(object, event=True)

    def init(self) -> None:
        self.frames: list[RGBDFrame] = []

    def on_update(self) -> None:
        self.frames += [value.value for value in self.rgbd.read_all()]


@pytest.fixture
def rig(monkeypatch: pytest.MonkeyPatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", "158")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    hosting = Hosting()
    driver = Node("camera", namespace="camera", context=hosting.context)
    executor = SingleThreadedExecutor(context=hosting.context)
    executor.add_node(driver)
    yield hosting, driver, executor
    executor.shutdown()
    driver.destroy_node()
    hosting.close()


def test_a_camera_drivers_topics_feed_the_reader_paired_with_their_intrinsics(rig) -> None:
    """Colour, aligned depth and camera_info as realsense2_camera publishes them (best effort), the
    depth stamped a few milliseconds after the colour; one depth lost, one colour image in an
    encoding the converter refuses: every other pair arrives in order, exact, with the intrinsics;
    the refused image is counted."""
    hosting, driver, executor = rig
    app = Application("topic_camera")
    camera = app.add(RgbdCameraReader("camera", backend="topic"), PeriodicActivity("grab", 0.005))
    sink = app.add(Frames("sink"), PeriodicActivity("sinking", 0.005))
    app.connect("camera.rgbd", "sink.rgbd", BUFFERED)
    publishers = {topic: driver.create_publisher(kind, topic, qos_profile_sensor_data)
                  for topic, kind in ((COLOR, ImageMsg), (DEPTH, ImageMsg), (INFO, CameraInfo))}
    hosting.start(app)
    peer = camera.peers[0]
    assert wait_until(lambda: all(p.get_subscription_count() == 1 for p in publishers.values()))
    intrinsics = CameraIntrinsics(32, 24, 30.0, 30.0, 15.5, 11.5, frame_id="camera_color_optical_frame")
    images, infos = ImageMessageConverter(), CameraInfoConverter()
    publishers[INFO].publish(infos.to_ros(intrinsics))
    assert wait_until(lambda: peer.received[2] == 1)  # a pair before the first camera_info would be dropped
    sent = []
    for index in range(12):
        stamp = 100.0 + index / 30
        color = Image(np.full((24, 32, 3), index, np.uint8), ImageFormat.RGB8, stamp, "camera_color_optical_frame")
        depth = Image(np.full((24, 32), 500 + index, np.uint16), ImageFormat.DEPTH16, stamp + 0.004,
                      "camera_color_optical_frame")
        color_message = images.to_ros(color)
        if index == 5:
            color_message.encoding = "mystery8"
        publishers[INFO].publish(infos.to_ros(intrinsics))  # with every frame, as drivers do
        publishers[COLOR].publish(color_message)
        if index != 8:
            publishers[DEPTH].publish(images.to_ros(depth))
        if index not in (5, 8):
            sent.append(index)
        # One frame at a time, at the camera's pace: each is taken before the next (a live camera's
        # reader that falls behind takes the newest; that is counted, not tested here).
        assert wait_until(lambda: len(sink.frames) == len(sent) and peer.stats.refused == (index >= 5)), \
            (index, len(sink.frames), peer.call("counts").result(1))
    assert hosting.stop()
    assert [int(frame.color.data[0, 0, 0]) for frame in sink.frames] == sent
    assert [int(frame.depth.data[0, 0]) for frame in sink.frames] == [500 + index for index in sent]
    assert all(frame.intrinsics is not None and frame.intrinsics.fx == 30.0 for frame in sink.frames)
    assert peer.call("counts").result(1) == {"color": 12, "depth": 11, "camera_info": 13, "paired": 10, "unpaired": 0}
    assert peer.stats.refused == 1
