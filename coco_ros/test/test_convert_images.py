"""sensor_msgs/Image and CameraInfo <-> Image and CameraIntrinsics: round trips on real images,
padded rows, byte order, YUV layouts, and proof that no pixel is handled in Python."""

from __future__ import annotations

import array
import sys
from pathlib import Path

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from conftest import python_lines
from coco_mr_vision.image import CameraIntrinsics, Image, ImageFormat
from coco_ros.convert import converter_for
from coco_ros.convert.stamps import RosTime
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import CameraInfo, RegionOfInterest
from sensor_msgs.msg import Image as ImageMsg
from std_msgs.msg import Header

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
REDWOOD = DATA / "rgbd" / "redwood"
ARUCO_JSON = DATA / "aruco" / "tag_01_d7_14cm.json"

images = converter_for("sensor_msgs/msg/Image")
infos = converter_for("sensor_msgs/msg/CameraInfo")


def through_the_wire(msg):
    """Serialize and deserialize: the message is valid for ROS, and arrives as a subscriber sees it."""
    received = deserialize_message(serialize_message(msg), type(msg))
    assert received == msg
    return received


def redwood(name: str, flags_name: str) -> np.ndarray:
    cv2 = pytest.importorskip("cv2")
    path = REDWOOD / name
    if not path.exists():
        pytest.skip(f"{path} is absent (the shared data sets are not beside this checkout)")
    return cv2.imread(str(path), getattr(cv2, flags_name))


def message(data: bytes, encoding: str, width: int, height: int, step: int, bigendian: bool = False) -> ImageMsg:
    msg = ImageMsg(header=Header(stamp=Time(sec=1_700_000_000, nanosec=123_456_789), frame_id="camera"),
                   height=height, width=width, encoding=encoding, is_bigendian=bigendian, step=step)
    msg.data = array.array("B", data)
    return msg


def padded(rows: np.ndarray, step: int, fill: int = 0xAB) -> bytes:
    """Rows of ``rows`` (HxN bytes) each padded to ``step`` bytes with ``fill``."""
    out = np.full((rows.shape[0], step), fill, np.uint8)
    out[:, :rows.shape[1]] = rows
    return out.tobytes()


# --- real images ---------------------------------------------------------------------------------

@pytest.mark.parametrize("encoding, image_format", [("bgr8", ImageFormat.BGR8), ("rgb8", ImageFormat.RGB8)])
def test_redwood_color_round_trips(encoding, image_format):
    bgr = redwood("color/00000.jpg", "IMREAD_COLOR")
    data = bgr if image_format is ImageFormat.BGR8 else np.ascontiguousarray(bgr[..., ::-1])
    image = Image(data, image_format, RosTime(1_700_000_000, 5), "camera_color_optical_frame")
    msg = through_the_wire(images.to_ros(image))
    assert (msg.encoding, msg.width, msg.height, msg.step, len(msg.data)) == (encoding, 640, 480, 1920, 921600)
    assert msg.header.stamp == Time(sec=1_700_000_000, nanosec=5)
    back = images.to_coco(msg)
    assert back.format is image_format and back.frame_id == "camera_color_optical_frame"
    assert back.stamp == image.stamp and back.stamp.nanosec == 5
    np.testing.assert_array_equal(back.data, data)
    np.testing.assert_array_equal(back.to_rgb(), bgr[..., ::-1])
    assert images.to_ros(back) == msg


def test_redwood_depth16_round_trips():
    depth = redwood("depth/00000.png", "IMREAD_UNCHANGED")
    assert depth.dtype == np.uint16
    msg = through_the_wire(images.to_ros(Image(depth, ImageFormat.DEPTH16, 12.5, "depth")))
    assert (msg.encoding, msg.step, msg.is_bigendian) == ("16UC1", 1280, sys.byteorder == "big")
    back = images.to_coco(msg)
    assert back.format is ImageFormat.DEPTH16 and back.data.dtype == np.uint16 and back.stamp == 12.5
    np.testing.assert_array_equal(back.data, depth)
    assert images.to_ros(back) == msg


def test_depth32f_and_grey_round_trips():
    rng = np.random.default_rng(3)
    metres = rng.uniform(0.3, 4.0, (5, 7)).astype(np.float32)
    metres[0, 0] = np.nan
    cases = [(metres, ImageFormat.DEPTH32F, "32FC1", 28), (rng.integers(0, 256, (5, 7), dtype=np.uint8),
             ImageFormat.GRAY8, "mono8", 7), (rng.integers(0, 65536, (5, 7), dtype=np.uint16), ImageFormat.GRAY16,
             "mono16", 14), (rng.integers(0, 256, (5, 7, 4), dtype=np.uint8), ImageFormat.RGBA8, "rgba8", 28),
             (rng.integers(0, 256, (5, 7, 4), dtype=np.uint8), ImageFormat.BGRA8, "bgra8", 28)]
    for data, image_format, encoding, step in cases:
        msg = through_the_wire(images.to_ros(Image(data, image_format)))
        assert (msg.encoding, msg.step) == (encoding, step)
        assert msg.header.stamp == Time() and msg.header.frame_id == ""
        back = images.to_coco(msg)
        assert back.format is image_format and back.stamp is None
        np.testing.assert_array_equal(back.data, data)


# --- layouts ---------------------------------------------------------------------------------------

def test_padded_rows_are_skipped_by_a_strided_view():
    rgb = np.random.default_rng(4).integers(0, 256, (6, 5, 3), dtype=np.uint8)
    msg = message(padded(rgb.reshape(6, 15), 15 + 13), "rgb8", 5, 6, 28)
    image = images.to_coco(msg)
    np.testing.assert_array_equal(image.data, rgb)
    assert np.shares_memory(image.data, np.frombuffer(msg.data, np.uint8))
    assert image.stamp.sec == 1_700_000_000 and image.stamp.nanosec == 123_456_789
    out = images.to_ros(image)
    assert out.step == 15 and len(out.data) == 90  # written unpadded
    np.testing.assert_array_equal(images.to_coco(out).data, rgb)


def test_odd_padding_of_16_bit_rows():
    depth = np.arange(24, dtype="<u2").reshape(4, 6) * 111
    msg = message(padded(depth.view(np.uint8).reshape(4, 12), 15), "16UC1", 6, 4, 15)
    np.testing.assert_array_equal(images.to_coco(msg).data, depth)


def test_big_endian_data_is_swapped_to_native_order():
    depth = np.arange(20, dtype=np.uint16).reshape(4, 5) * 3001
    msg = message(depth.astype(">u2").tobytes(), "mono16", 5, 4, 10, bigendian=True)
    image = images.to_coco(msg)
    assert image.data.dtype == np.uint16 and image.data.dtype.isnative
    np.testing.assert_array_equal(image.data, depth)
    metres = np.linspace(0.5, 3.0, 6, dtype=np.float32).reshape(2, 3)
    image = images.to_coco(message(metres.astype(">f4").tobytes(), "32FC1", 3, 2, 12, bigendian=True))
    np.testing.assert_array_equal(image.data, metres)


def test_uyvy_becomes_yuyv_without_a_copy():
    yuyv = np.random.default_rng(5).integers(0, 256, (2, 4, 2), dtype=np.uint8)
    uyvy = yuyv[..., ::-1].tobytes()
    for encoding in ("uyvy", "yuv422"):
        msg = message(uyvy, encoding, 4, 2, 8)
        image = images.to_coco(msg)
        assert image.format is ImageFormat.YUYV
        np.testing.assert_array_equal(image.data, yuyv)
        assert np.shares_memory(image.data, np.frombuffer(msg.data, np.uint8))
    for encoding in ("yuyv", "yuv422_yuy2"):
        np.testing.assert_array_equal(images.to_coco(message(yuyv.tobytes(), encoding, 4, 2, 8)).data, yuyv)
    msg = through_the_wire(images.to_ros(Image(yuyv, ImageFormat.YUYV)))
    assert (msg.encoding, msg.step) == ("yuyv", 8)


def test_i420_unpadded_and_padded():
    cv2 = pytest.importorskip("cv2")
    rgb = np.random.default_rng(6).integers(0, 256, (6, 8, 3), dtype=np.uint8)
    i420 = cv2.cvtColor(rgb, cv2.COLOR_RGB2YUV_I420)
    assert i420.shape == (9, 8)
    msg = through_the_wire(images.to_ros(Image(i420, ImageFormat.I420)))
    assert (msg.encoding, msg.width, msg.height, msg.step, len(msg.data)) == ("i420", 8, 6, 8, 72)
    image = images.to_coco(msg)
    np.testing.assert_array_equal(image.data, i420)
    assert np.shares_memory(image.data, np.frombuffer(msg.data, np.uint8))
    # Padded: luma rows of 12 bytes, chroma rows of 6 (GStreamer and ROS nv21 layout).
    luma, chroma = i420[:6], i420[6:].reshape(2, 3, 4)  # U and V planes, 3 rows of 4
    data = padded(luma, 12) + padded(chroma[0], 6) + padded(chroma[1], 6)
    image = images.to_coco(message(data, "I420", 8, 6, 12))
    np.testing.assert_array_equal(image.data, i420)
    assert image.data.flags.writeable  # a copy of its own


def test_copy_option_gives_an_array_of_ones_own():
    msg = images.to_ros(Image(np.arange(12, dtype=np.uint8).reshape(3, 4), ImageFormat.GRAY8))
    view = images.to_coco(msg).data
    assert not view.flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        view[0, 0] = 1
    owned = converter_for("sensor_msgs/Image", copy=True).to_coco(msg).data
    assert owned.flags.writeable and not np.shares_memory(owned, view)


@pytest.mark.parametrize("encoding, width, height, step, size, error", [
    ("bayer_rggb8", 2, 2, 2, 4, "encoding 'bayer_rggb8' is not supported; supported: mono8, .*16UC1"),
    ("rgb8", 4, 2, 10, 20, r"needs step >= 12 bytes, got step 10"),
    ("mono16", 4, 2, 8, 12, r"needs 16 bytes of data, got 12"),
    ("i420", 3, 2, 3, 9, "even width and height"),
])
def test_bad_messages_are_refused(encoding, width, height, step, size, error):
    with pytest.raises(ValueError, match=error):
        images.to_coco(message(bytes(size), encoding, width, height, step))


def test_wrong_types_are_refused():
    with pytest.raises(TypeError, match="converts sensor_msgs/msg/Image messages, got CameraInfo"):
        images.to_coco(CameraInfo())
    with pytest.raises(TypeError, match="publishes Image values as sensor_msgs/msg/Image, got ndarray"):
        images.to_ros(np.zeros((2, 2), np.uint8))


# --- no Python loop over pixels -------------------------------------------------------------------

@pytest.mark.parametrize("image_format", [ImageFormat.RGB8, ImageFormat.BGR8, ImageFormat.DEPTH16,
                                          ImageFormat.YUYV, ImageFormat.I420])
def test_a_vga_image_costs_as_many_python_lines_as_a_tiny_one(image_format):
    def lines(width, height):
        data = np.ones(image_format.shape(width, height), image_format.dtype)
        image = Image(data, image_format, 1.0, "camera")
        msg, to_ros_lines = python_lines(lambda: images.to_ros(image))
        back, to_coco_lines = python_lines(lambda: images.to_coco(msg))
        np.testing.assert_array_equal(back.data, data)
        return to_ros_lines, to_coco_lines, back, msg

    lines(4, 2)  # warm up: imports and caches
    small = lines(4, 2)[:2]
    to_ros_lines, to_coco_lines, back, msg = lines(640, 480)
    assert (to_ros_lines, to_coco_lines) == small
    assert to_ros_lines + to_coco_lines < 1000 < 640 * 480
    assert np.shares_memory(back.data, np.frombuffer(msg.data, np.uint8))  # and nothing was copied


# --- camera info -----------------------------------------------------------------------------------

def test_camera_info_round_trip_from_a_calibration_file():
    if not ARUCO_JSON.exists():
        pytest.skip(f"{ARUCO_JSON} is absent")
    intrinsics = CameraIntrinsics.from_json(ARUCO_JSON, frame_id="camera", stamp=RosTime(1_700_000_000, 42))
    msg = through_the_wire(infos.to_ros(intrinsics))
    assert (msg.width, msg.height, msg.distortion_model, msg.header.frame_id) == (1280, 960, "plumb_bob", "camera")
    assert msg.header.stamp == Time(sec=1_700_000_000, nanosec=42)
    np.testing.assert_array_equal(msg.k, intrinsics.K.ravel())
    np.testing.assert_array_equal(msg.d, intrinsics.distortion)
    np.testing.assert_array_equal(msg.r, np.eye(3).ravel())
    np.testing.assert_array_equal(msg.p, intrinsics.P.ravel())
    back = infos.to_coco(msg)
    for name in ("width", "height", "fx", "fy", "cx", "cy", "skew", "distortion_model", "distortion", "binning",
                 "roi", "frame_id", "stamp"):
        assert getattr(back, name) == getattr(intrinsics, name), name
    for name in ("K", "D", "R", "P"):
        np.testing.assert_array_equal(getattr(back, name), getattr(intrinsics, name), err_msg=name)


def test_camera_info_round_trip_keeps_every_field():
    msg = CameraInfo(header=Header(stamp=Time(sec=3, nanosec=7), frame_id="left"), width=752, height=480,
                     distortion_model="rational_polynomial", d=[0.1, -0.2, 0.001, 0.002, 0.03, 0.1, -0.05, 0.01],
                     k=[460.1, 0.5, 370.2, 0.0, 459.3, 240.7, 0.0, 0.0, 1.0],
                     r=[0.999, -0.01, 0.02, 0.01, 0.999, 0.0, -0.02, 0.0, 0.999],
                     p=[440.0, 0.0, 360.0, -33.0, 0.0, 440.0, 240.0, 0.0, 0.0, 0.0, 1.0, 0.0],
                     binning_x=2, binning_y=2,
                     roi=RegionOfInterest(x_offset=10, y_offset=20, height=300, width=400, do_rectify=True))
    intrinsics = infos.to_coco(through_the_wire(msg))
    assert (intrinsics.fx, intrinsics.skew, intrinsics.cy) == (460.1, 0.5, 240.7)
    assert intrinsics.binning == (2, 2) and intrinsics.roi == (10, 20, 300, 400, True)
    assert infos.to_ros(intrinsics) == msg
