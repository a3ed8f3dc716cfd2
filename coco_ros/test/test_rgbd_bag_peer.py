"""BagRgbdPeer (coco_ros.vision.rgbd_bag): a rosbag2 recording of camera topics as the peer of
coco_mr_vision's RgbdCameraReader, declared as a peer or made from the reader's ``backend="bag"``
(found by its registered name: coco_mr_vision imports nothing of coco_ros, which
test/test_package_dependencies.py checks)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("cv2")

from conftest import SHARED_DATA  # noqa: E402
from coco_core import Application, BufferPolicy, Component, ConnectionPolicy, InputPort  # noqa: E402
from coco_core.errors import CameraError  # noqa: E402
from coco_mr_vision.image import CameraIntrinsics, Image, ImageFormat  # noqa: E402
from coco_mr_vision.rgbd import RGBDFrame  # noqa: E402
from coco_mr_vision.rgbd_peers import PRIMESENSE  # noqa: E402
from coco_mr_vision.rgbd_reader import RgbdCameraReader  # noqa: E402
from coco_ros.bag import BagWriter  # noqa: E402
from coco_ros.convert.images import CameraInfoConverter, ImageMessageConverter  # noqa: E402
from coco_ros.vision.rgbd_bag import BagRgbdPeer  # noqa: E402

REDWOOD = SHARED_DATA / "rgbd" / "redwood"


def needs(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"{path} is absent (the shared data sets are not beside this checkout)")
    return path


class Sink(Component):
    rgbd = InputPort(object)


def run(reader: RgbdCameraReader, updates: int) -> list:
    app = Application("rgbd")
    app.add(reader)
    sink = app.add(Sink("sink"))
    app.connect(reader.rgbd, sink.rgbd, ConnectionPolicy(BufferPolicy.BUFFER, size=100))
    for peer in reader.peers:
        peer.on_config()
    reader.on_config()
    for _ in range(updates):
        reader.on_update()
    return sink.rgbd.read_all()


def test_the_bag_backend_is_this_packages_peer():
    reader = RgbdCameraReader("r", backend="bag", path="x")
    reader.init()
    assert type(reader.peers[0]) is BagRgbdPeer and reader.peers[0].path == "x"



def test_rosbag2_bag_with_image_and_camera_info(tmp_path):
    needs(REDWOOD)

    images, infos = ImageMessageConverter(), CameraInfoConverter()
    writer = BagWriter(tmp_path / "camera_bag")
    originals = []
    for index in range(2):
        stamp = 100.0 + index / 30
        frame = RGBDFrame.load(REDWOOD / "color" / f"{index:05d}.jpg", REDWOOD / "depth" / f"{index:05d}.png",
                               PRIMESENSE, stamp=stamp, frame_id="camera_color_optical_frame")
        originals.append(frame)
        ns = int(stamp * 1e9)
        writer.write("/camera/color/camera_info", infos.to_ros(PRIMESENSE), ns)
        writer.write("/camera/color/image_raw", images.to_ros(frame.color), ns + 1000)
        writer.write("/camera/depth/image_raw", images.to_ros(frame.depth), ns + 2000)
    writer.close()
    got = run(RgbdCameraReader("bag", backend="bag", path=str(tmp_path / "camera_bag")), 3)
    assert len(got) == 2
    for value, original in zip(got, originals):
        frame = value.value
        assert frame.stamp == pytest.approx(original.stamp)
        assert np.array_equal(frame.color.data, original.color.data)
        assert np.array_equal(frame.depth.data, original.depth.data)
        assert frame.intrinsics.fx == 525.0 and frame.frame_id == "camera_color_optical_frame"


def test_bag_without_the_topics_lists_those_it_has():
    bag = needs(SHARED_DATA / "rosbag2" / "talker.mcap")
    peer = BagRgbdPeer("bag", path=str(bag))
    with pytest.raises(CameraError, match="has no topic /camera/color/image_raw.*/topic"):
        peer.on_config()


def test_a_bag_replayed_in_real_time_skips_the_frames_a_slow_reader_missed(tmp_path):
    """With ``realtime`` the bag is a live camera: a frame is delivered once the time since the first
    one reaches its stamp's, never earlier, and a reader that fell behind gets the newest due frame,
    the ones it missed counted in the profile's merged column (without it the palpation app's remote
    camera delivered an ever older scene: the calibration touch was seen a second after the hand's)."""

    images, infos = ImageMessageConverter(), CameraInfoConverter()
    period, count = 0.1, 12
    with BagWriter(tmp_path / "camera_bag") as writer:
        for index in range(count):
            stamp = 100.0 + index * period
            ns = int(round(stamp * 1e9))
            color = Image(np.full((48, 64, 3), index, np.uint8), ImageFormat.RGB8, stamp, "camera")
            depth = Image(np.full((48, 64), 1000 + index, np.uint16), ImageFormat.DEPTH16, stamp, "camera")
            writer.write("/camera/color/camera_info", infos.to_ros(CameraIntrinsics(64, 48, 50.0, 50.0, 32.0, 24.0)), ns)
            writer.write("/camera/color/image_raw", images.to_ros(color), ns + 1000)
            writer.write("/camera/depth/image_raw", images.to_ros(depth), ns + 2000)
    peer = BagRgbdPeer("bag", path=str(tmp_path / "camera_bag"), realtime=True)
    peer.on_config()
    start = time.perf_counter()
    first = peer.grab()
    assert first is not None and first.stamp == pytest.approx(100.0)
    delivered = [(time.perf_counter(), first.stamp)]
    # Fall behind: take nothing until four periods have passed.
    while time.perf_counter() < start + 4 * period:
        time.sleep(0.01)
    late = peer.grab()
    assert late is not None and late.stamp >= 100.0 + 3 * period - 1e-9, "the newest due frame"
    assert peer.stats.merged == round((late.stamp - 100.0) / period) - 1 >= 2
    delivered.append((time.perf_counter(), late.stamp))
    while not peer.exhausted:
        frame = peer.grab()
        if frame is not None:
            delivered.append((time.perf_counter(), frame.stamp))
        time.sleep(0.005)
    stamps = [stamp for _, stamp in delivered]
    assert stamps == sorted(stamps) and stamps[-1] == pytest.approx(100.0 + (count - 1) * period)
    assert len(delivered) + peer.stats.merged == count
    # Never early: each frame came once the time since the first reached its stamp's.
    assert all(when - start >= stamp - 100.0 - 1e-3 for when, stamp in delivered)


@pytest.mark.parametrize("declared", [True, False], ids=["declared-peer", "backend-attribute"])
def test_a_malformed_frame_in_a_bag_is_skipped_counted_and_reported(tmp_path, declared):
    """Issue 20: a colour image of another size than its depth, a depth image encoded rgb8, one of an
    encoding nobody knows and images that disagree with their camera_info raised out of the reader
    (its errors column, nothing else: the run exited 0). Now each is skipped alone, counted in the
    peer's refused column and named in the application's damage, and the frames after it come."""

    images, infos = ImageMessageConverter(), CameraInfoConverter()
    with BagWriter(tmp_path / "camera_bag") as writer:
        for index in range(7):
            stamp = 100.0 + index / 30
            ns = int(round(stamp * 1e9))
            info = CameraIntrinsics(32, 24, 25.0, 25.0, 16.0, 12.0) if index == 4 else \
                CameraIntrinsics(64, 48, 50.0, 50.0, 32.0, 24.0)
            color = Image(np.full((24, 32, 3) if index == 1 else (48, 64, 3), index, np.uint8), ImageFormat.RGB8,
                          stamp, "camera")
            depth = images.to_ros(Image(np.full((48, 64), 1000 + index, np.uint16), ImageFormat.DEPTH16, stamp,
                                        "camera"))
            if index == 2:  # the depth as colour: the right size in bytes for rgb8 and a wrong encoding
                depth = images.to_ros(Image(np.zeros((48, 64, 3), np.uint8), ImageFormat.RGB8, stamp, "camera"))
            if index == 3:
                depth.encoding = "bogus16"
            writer.write("/camera/color/camera_info", infos.to_ros(info), ns)
            writer.write("/camera/color/image_raw", images.to_ros(color), ns + 1000)
            writer.write("/camera/depth/image_raw", depth, ns + 2000)
    if declared:  # as the palpation app's XML does
        reader = RgbdCameraReader("camera")
        reader.add_peer(BagRgbdPeer("camera_bag", path=str(tmp_path / "camera_bag")))
    else:  # the peer made by the reader's init: the application holds it too (its damage, its profile row)
        reader = RgbdCameraReader("camera", backend="bag", path=str(tmp_path / "camera_bag"))
    got = run(reader, 8)
    peer = reader.peers[0]
    assert reader.app.component(peer.name) is peer
    assert [round(float(value.value.depth.data[0, 0])) - 1000 for value in got] == [0, 5, 6]
    assert peer.stats.refused == peer.refused_messages == 4 and reader.stats.errors == 0
    damage = reader.app.damage
    assert len(damage) == 4, damage
    assert all(entry.startswith(f"{peer.name}: {tmp_path / 'camera_bag'}: the /camera/") for entry in damage), damage
    assert "/camera/depth/image_raw message 0.033" in damage[0] and "must be registered: same size" in damage[0]
    assert "/camera/depth/image_raw message 0.067" in damage[1] and "must be DEPTH16 or DEPTH32F" in damage[1]
    assert "/camera/depth/image_raw message 0.100" in damage[2] and "'bogus16' is not supported" in damage[2]
    assert "intrinsics are for 32x24 images, the frame is 64x48" in damage[3]
