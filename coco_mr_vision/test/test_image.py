"""Image, CameraIntrinsics and PointCloud: shape and dtype checks, display conversion, calibration
files, back-projection of a real depth image."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from coco_core.errors import CocoError, ImageError, UnknownNameError, WrongTypeError
from coco_mr_vision.image import CameraIntrinsics, Image, ImageFormat
from coco_mr_vision.pointcloud import PointCloud

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
REDWOOD = DATA / "rgbd" / "redwood"
ARUCO_JSON = DATA / "aruco" / "tag_01_d7_14cm.json"


def needs(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"{path} is absent (the shared data sets are not beside this checkout)")
    return path


def redwood_rgb() -> np.ndarray:
    cv2 = pytest.importorskip("cv2")
    bgr = cv2.imread(str(needs(REDWOOD / "color" / "00000.jpg")), cv2.IMREAD_COLOR)
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


# --- formats and checks ---------------------------------------------------------------------------

@pytest.mark.parametrize("image_format, shape, dtype", [
    (ImageFormat.GRAY8, (4, 6), np.uint8), (ImageFormat.GRAY16, (4, 6), np.uint16),
    (ImageFormat.RGB8, (4, 6, 3), np.uint8), (ImageFormat.BGR8, (4, 6, 3), np.uint8),
    (ImageFormat.RGBA8, (4, 6, 4), np.uint8), (ImageFormat.BGRA8, (4, 6, 4), np.uint8),
    (ImageFormat.YUYV, (4, 6, 2), np.uint8), (ImageFormat.I420, (6, 6), np.uint8),
    (ImageFormat.DEPTH32F, (4, 6), np.float32), (ImageFormat.DEPTH16, (4, 6), np.uint16),
])
def test_every_format_has_its_natural_shape(image_format, shape, dtype):
    assert image_format.shape(6, 4) == shape
    image = Image(np.zeros(shape, dtype), image_format, 1.25, "camera")
    assert (image.width, image.height, image.size) == (6, 4, (6, 4))
    assert image.format is image_format and image.stamp == 1.25 and image.frame_id == "camera"


def test_format_given_by_name():
    assert Image(np.zeros((2, 2), np.uint8), "gray8").format is ImageFormat.GRAY8
    with pytest.raises(ValueError, match="unknown image format 'NV12'.*GRAY8"):
        Image(np.zeros((2, 2), np.uint8), "NV12")


@pytest.mark.parametrize("data, image_format, message", [
    (np.zeros((4, 6, 3), np.uint16), ImageFormat.RGB8, "RGB8 image data must be uint8, got uint16"),
    (np.zeros((4, 6), np.uint8), ImageFormat.RGB8, r"must have shape HxWx3, got \(4, 6\)"),
    (np.zeros((4, 6, 1), np.uint8), ImageFormat.GRAY8, r"must have shape HxW, got \(4, 6, 1\)"),
    (np.zeros((4, 6, 3), np.uint8), ImageFormat.RGBA8, r"HxWx4, got \(4, 6, 3\)"),
    (np.zeros((4, 5, 2), np.uint8), ImageFormat.YUYV, "even width"),
    (np.zeros((5, 6), np.uint8), ImageFormat.I420, r"\(H\*3/2\)xW with H and W even"),
    (np.zeros((6, 5), np.uint8), ImageFormat.I420, r"\(H\*3/2\)xW with H and W even"),
    (np.zeros((4, 6), np.float64), ImageFormat.DEPTH32F, "must be float32, got float64"),
    (np.zeros((4, 6), ">u2"), ImageFormat.DEPTH16, "swap the byte order"),
])
def test_bad_data_is_refused_with_what_was_expected(data, image_format, message):
    with pytest.raises(ValueError, match=message):
        Image(data, image_format)


def test_data_must_be_an_array_and_stamp_seconds():
    with pytest.raises(TypeError, match="numpy array, got list"):
        Image([[0]], ImageFormat.GRAY8)
    with pytest.raises(TypeError, match="stamp must be float seconds"):
        Image(np.zeros((2, 2), np.uint8), ImageFormat.GRAY8, stamp="now")
    assert Image(np.zeros((2, 2), np.uint8), ImageFormat.GRAY8, stamp=3).stamp == 3.0


def test_image_errors_are_coco_errors_that_keep_their_builtin_class() -> None:
    """The launcher reports a CocoError as a message; callers that catch ValueError or TypeError still do."""
    with pytest.raises(ImageError) as bad_format:
        Image(np.zeros((2, 2), np.uint8), "NV12")
    assert isinstance(bad_format.value, CocoError) and isinstance(bad_format.value, ValueError)
    with pytest.raises(WrongTypeError) as bad_stamp:
        Image(np.zeros((2, 2), np.uint8), ImageFormat.GRAY8, stamp="now")
    assert isinstance(bad_stamp.value, CocoError) and isinstance(bad_stamp.value, TypeError)
    with pytest.raises(ImageError):
        PointCloud(np.zeros((4, 2), np.float32))
    with pytest.raises(ImageError, match="lack K") as no_matrix:
        CameraIntrinsics.from_json({"width": 4, "height": 3})
    assert not isinstance(no_matrix.value, UnknownNameError), "the lookup's KeyError stays inside"


def test_images_are_frozen_and_share_their_data():
    data = np.zeros((2, 2), np.uint8)
    image = Image(data, ImageFormat.GRAY8)
    assert image.data is data
    with pytest.raises(AttributeError):
        image.frame_id = "other"  # type: ignore[misc]


# --- display --------------------------------------------------------------------------------------

def test_to_rgb_of_packed_color_formats_are_views():
    rgb = np.random.default_rng(1).integers(0, 256, (3, 4, 3), dtype=np.uint8)
    alpha = np.full((3, 4, 1), 7, np.uint8)
    cases = {ImageFormat.RGB8: rgb, ImageFormat.BGR8: rgb[..., ::-1].copy(),
             ImageFormat.RGBA8: np.concatenate([rgb, alpha], axis=2),
             ImageFormat.BGRA8: np.concatenate([rgb[..., ::-1], alpha], axis=2)}
    for image_format, data in cases.items():
        shown = Image(data, image_format).to_rgb()
        assert shown.shape == (3, 4, 3) and shown.dtype == np.uint8
        np.testing.assert_array_equal(shown, rgb, err_msg=image_format.name)
        assert np.shares_memory(shown, data), image_format.name


def test_to_rgb_of_grey():
    grey = np.arange(12, dtype=np.uint8).reshape(3, 4)
    np.testing.assert_array_equal(Image(grey, ImageFormat.GRAY8).to_rgb(), np.stack([grey] * 3, axis=2))
    wide = grey.astype(np.uint16) * 256 + 255
    np.testing.assert_array_equal(Image(wide, ImageFormat.GRAY16).to_rgb()[..., 1], grey)


def test_to_rgb_of_yuv_matches_the_original_colours():
    cv2 = pytest.importorskip("cv2")
    rgb = redwood_rgb()
    i420 = cv2.cvtColor(rgb, cv2.COLOR_RGB2YUV_I420)
    height, width = rgb.shape[:2]
    u = i420[height:height + height // 4].reshape(height // 2, width // 2)
    v = i420[height + height // 4:].reshape(height // 2, width // 2)
    packed = np.empty((height, width, 2), np.uint8)  # the same samples as 4:2:2 YUYV
    packed[..., 0] = i420[:height]
    packed[:, 0::2, 1] = np.repeat(u, 2, axis=0)
    packed[:, 1::2, 1] = np.repeat(v, 2, axis=0)
    for image in (Image(i420, ImageFormat.I420), Image(packed, ImageFormat.YUYV)):
        assert image.size == (640, 480)
        shown = image.to_rgb()
        assert shown.shape == rgb.shape and shown.dtype == np.uint8
        error = np.abs(shown.astype(int) - rgb.astype(int)).mean()
        assert error < 6, f"{image.format.name}: mean error {error}"


def test_depth_formats_in_metres_and_for_display():
    millimetres = np.array([[0, 500], [1000, 2000]], np.uint16)
    metres = Image(millimetres, ImageFormat.DEPTH16).depth_metres()
    assert metres.dtype == np.float32 and np.isnan(metres[0, 0])
    np.testing.assert_allclose(metres[1], [1.0, 2.0])
    float_depth = np.array([[np.nan, 0.5], [1.0, 2.0]], np.float32)
    assert Image(float_depth, ImageFormat.DEPTH32F).depth_metres() is float_depth
    shown = Image(millimetres, ImageFormat.DEPTH16).to_rgb()
    np.testing.assert_array_equal(shown[..., 0], [[0, 63], [127, 255]])
    np.testing.assert_array_equal(Image(float_depth, ImageFormat.DEPTH32F).to_rgb(depth_range=(0.0, 1.0))[..., 2],
                                  [[0, 127], [255, 255]])
    with pytest.raises(ValueError, match="a RGB8 image holds no depth"):
        Image(np.zeros((1, 1, 3), np.uint8), ImageFormat.RGB8).depth_metres()


# --- intrinsics -----------------------------------------------------------------------------------

def test_intrinsics_of_the_marker_data_set():
    intrinsics = CameraIntrinsics.from_json(needs(ARUCO_JSON), frame_id="camera")
    camera = json.loads(ARUCO_JSON.read_text())["camera"]
    np.testing.assert_array_equal(intrinsics.K, np.reshape(camera["K"], (3, 3)))
    np.testing.assert_array_equal(intrinsics.D, camera["D"])
    assert (intrinsics.width, intrinsics.height, intrinsics.distortion_model) == (1280, 960, "plumb_bob")
    assert intrinsics.frame_id == "camera" and intrinsics.stamp is None
    np.testing.assert_array_equal(intrinsics.R, np.eye(3))
    np.testing.assert_array_equal(intrinsics.P, np.hstack([intrinsics.K, np.zeros((3, 1))]))


def test_intrinsics_of_open3d_column_major_json():
    intrinsics = CameraIntrinsics.from_json(needs(REDWOOD / "camera_primesense.json"))
    assert (intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy) == (525.0, 525.0, 319.5, 239.5)
    assert (intrinsics.width, intrinsics.height, intrinsics.skew, intrinsics.distortion) == (640, 480, 0.0, ())


def test_intrinsics_errors_and_given_matrices():
    with pytest.raises(ValueError, match="lack height"):
        CameraIntrinsics.from_json({"width": 2, "K": [1] * 9})
    with pytest.raises(ValueError, match="lack K"):
        CameraIntrinsics.from_json({"width": 2, "height": 2})
    with pytest.raises(ValueError, match="projection must be 3x4"):
        CameraIntrinsics(2, 2, 1, 1, 1, 1, projection=np.eye(3))
    projection = np.arange(12.0).reshape(3, 4)
    intrinsics = CameraIntrinsics(2, 2, 1, 1, 1, 1, projection=projection.ravel())
    np.testing.assert_array_equal(intrinsics.P, projection)
    assert not intrinsics.projection.flags.writeable


def test_an_image_carries_its_intrinsics():
    intrinsics = CameraIntrinsics(4, 2, 10, 10, 2, 1)
    image = Image(np.zeros((2, 4), np.uint8), ImageFormat.GRAY8, intrinsics=intrinsics)
    assert image.intrinsics is intrinsics


# --- point clouds ---------------------------------------------------------------------------------

def test_point_cloud_checks():
    points = np.zeros((4, 3), np.float32)
    with pytest.raises(ValueError, match="Nx3 numpy array, got \\(4, 2\\)"):
        PointCloud(np.zeros((4, 2), np.float32))
    with pytest.raises(ValueError, match="must be float32, got float64"):
        PointCloud(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="colors must be uint8"):
        PointCloud(points, np.zeros((4, 3), np.float32))
    with pytest.raises(ValueError, match="like the points"):
        PointCloud(points, np.zeros((3, 3), np.uint8))
    with pytest.raises(ValueError, match="organized 2x3 cloud needs 6 points, got 4"):
        PointCloud(points, organized=(2, 3))
    cloud = PointCloud(points, organized=(2, 2), frame_id="lidar", stamp=2)
    assert len(cloud) == 4 and cloud.is_dense and cloud.stamp == 2.0 and cloud.finite() is cloud


def test_finite_drops_nan_points_and_their_colours():
    points = np.array([[0, 0, 1], [np.nan, 0, 0], [1, 2, 3]], np.float32)
    colors = np.array([[1, 1, 1], [2, 2, 2], [3, 3, 3]], np.uint8)
    cloud = PointCloud(points, colors, organized=(1, 3))
    assert not cloud.is_dense
    finite = cloud.finite()
    np.testing.assert_array_equal(finite.points, points[[0, 2]])
    np.testing.assert_array_equal(finite.colors, colors[[0, 2]])
    assert finite.organized is None


def test_cloud_of_the_redwood_depth_image():
    cv2 = pytest.importorskip("cv2")
    depth = cv2.imread(str(needs(REDWOOD / "depth" / "00000.png")), cv2.IMREAD_UNCHANGED)
    intrinsics = CameraIntrinsics.from_json(REDWOOD / "camera_primesense.json")
    image = Image(depth, ImageFormat.DEPTH16, 4.5, "camera")
    color = Image(redwood_rgb(), ImageFormat.RGB8)
    cloud = PointCloud.from_depth(image, intrinsics, color)
    assert len(cloud) == np.count_nonzero(depth) and cloud.is_dense
    assert cloud.stamp == 4.5 and cloud.frame_id == "camera"
    row, column = np.argwhere(depth > 0)[len(cloud) // 2]
    z = depth[row, column] / 1000.0
    expected = [(column - 319.5) * z / 525.0, (row - 239.5) * z / 525.0, z]
    index = np.count_nonzero(depth.reshape(-1)[:row * 640 + column])
    np.testing.assert_allclose(cloud.points[index], expected, rtol=1e-6)
    np.testing.assert_array_equal(cloud.colors[index], color.data[row, column])
    organized = PointCloud.from_depth(image, intrinsics, organized=True)
    assert organized.organized == (480, 640) and len(organized) == depth.size
    assert np.isnan(organized.points[depth.reshape(-1) == 0]).all()
    with pytest.raises(ValueError, match="intrinsics are for 320x240 images"):
        PointCloud.from_depth(image, CameraIntrinsics(320, 240, 1, 1, 1, 1))


def test_pickled_without_the_conversions_made_so_far():
    """What crosses a process boundary is the image, not every format a reader asked of it."""
    import pickle

    intrinsics = CameraIntrinsics(64, 48, 50.0, 50.0, 31.5, 23.5, frame_id="camera")
    image = Image(np.arange(64 * 48 * 3, dtype=np.uint8).reshape(48, 64, 3), "RGB8", 2.5, "camera", intrinsics)
    alone = len(pickle.dumps(image))
    image.to("GRAY8"), image.to("BGR8"), image.to("YUYV")
    assert len(pickle.dumps(image)) == alone
    back = pickle.loads(pickle.dumps(image))
    assert np.array_equal(back.data, image.data) and (back.format, back.stamp, back.frame_id) == \
        (image.format, image.stamp, image.frame_id)
    np.testing.assert_array_equal(back.intrinsics.K, intrinsics.K)
    assert np.array_equal(back.to("GRAY8").data, image.to("GRAY8").data)
