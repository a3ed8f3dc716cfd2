"""RGBDFrame: pairing checks, depth scale, and the real Redwood and TUM RGB-D pairs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from coco_mr_vision.image import CameraIntrinsics, Image, ImageFormat
from coco_mr_vision.pointcloud import PointCloud
from coco_mr_vision.rgbd import RGBDFrame

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
REDWOOD = DATA / "rgbd" / "redwood"
TUM = DATA / "rgbd" / "tum"


def needs(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"{path} is absent (the shared data sets are not beside this checkout)")
    return path


def pair(width: int = 8, height: int = 6, depth_format: ImageFormat = ImageFormat.DEPTH16) -> tuple[Image, Image]:
    color = Image(np.zeros((height, width, 3), np.uint8), ImageFormat.RGB8)
    depth = Image(np.ones((height, width), depth_format.dtype), depth_format, 2.5, "camera_optical")
    return color, depth


def test_stamp_frame_and_intrinsics_come_from_the_depth_image():
    intrinsics = CameraIntrinsics(8, 6, 5.0, 5.0, 3.5, 2.5)
    color, _ = pair()
    depth = Image(np.ones((6, 8), np.uint16), ImageFormat.DEPTH16, 2.5, "camera_optical", intrinsics)
    frame = RGBDFrame(color, depth)
    assert frame.stamp == 2.5 and frame.frame_id == "camera_optical" and frame.size == (8, 6)
    assert frame.intrinsics is intrinsics
    other = CameraIntrinsics(8, 6, 7.0, 7.0, 3.5, 2.5)
    assert RGBDFrame(color, depth, other).intrinsics is other


@pytest.mark.parametrize("make, message", [
    (lambda c, d: RGBDFrame(d, d), "color image of an RGBDFrame must not be depth, got DEPTH16"),
    (lambda c, d: RGBDFrame(c, c), "depth image of an RGBDFrame must be DEPTH16 or DEPTH32F, got RGB8"),
    (lambda c, d: RGBDFrame(Image(np.zeros((6, 4, 3), np.uint8), ImageFormat.RGB8), d),
     r"color \(4x6\) and depth \(8x6\) must be registered"),
    (lambda c, d: RGBDFrame(c, d, depth_scale=0), "depth_scale is depth units per metre and must be > 0"),
    (lambda c, d: RGBDFrame(c, d, CameraIntrinsics(640, 480, 525, 525, 319.5, 239.5)),
     "intrinsics are for 640x480 images, the frame is 8x6"),
])
def test_bad_pairs_are_refused_with_what_is_wrong(make, message):
    color, depth = pair()
    with pytest.raises(ValueError, match=message):
        make(color, depth)


def test_depth_scale_applies_to_depth16_only():
    color, depth = pair()
    data = depth.data.copy()
    data[0, 0], data[0, 1] = 0, 5000
    depth16 = Image(data, ImageFormat.DEPTH16)
    metres = RGBDFrame(color, depth16, depth_scale=5000).depth_metres()
    assert np.isnan(metres[0, 0]) and metres[0, 1] == pytest.approx(1.0) and metres[1, 1] == pytest.approx(0.0002)
    # the default scale is the millimetres DEPTH16 normally holds: the same as Image.depth_metres
    np.testing.assert_array_equal(RGBDFrame(color, depth16).depth_metres(), depth16.depth_metres())
    depth32 = Image(np.full((6, 8), 1.5, np.float32), ImageFormat.DEPTH32F)
    assert RGBDFrame(color, depth32, depth_scale=5000).depth_metres() is depth32.data


def test_redwood_pair_loads_with_its_intrinsics():
    intrinsics = CameraIntrinsics.from_json(needs(REDWOOD / "camera_primesense.json"))
    frame = RGBDFrame.load(REDWOOD / "color" / "00000.jpg", REDWOOD / "depth" / "00000.png", intrinsics,
                           stamp=1.0, frame_id="camera_optical")
    assert frame.color.format is ImageFormat.BGR8 and frame.depth.format is ImageFormat.DEPTH16
    assert frame.size == (640, 480) and frame.intrinsics is intrinsics and frame.stamp == 1.0
    metres = frame.depth_metres()
    valid = np.isfinite(metres)
    assert 0.8 < valid.mean() < 0.95  # a real sensor: some pixels have no depth
    assert 0.3 < np.nanmedian(metres) < 3.0  # an indoor scene, in metres
    # the frame's depth goes through the existing back-projection unchanged
    cloud = PointCloud.from_depth(frame.depth, intrinsics, frame.color)
    assert len(cloud) == int(valid.sum())


def test_tum_depth_needs_its_scale_of_5000():
    frame = RGBDFrame.load(needs(TUM / "color.png"), TUM / "depth.png", depth_scale=5000)
    metres = frame.depth_metres()
    assert 0.5 < np.nanmedian(metres) < 5.0
    assert np.nanmedian(frame.depth.depth_metres()) == pytest.approx(np.nanmedian(metres) * 5, rel=1e-5)


def test_unreadable_files_are_named(tmp_path):
    color = needs(REDWOOD / "color" / "00000.jpg")
    with pytest.raises(FileNotFoundError, match="missing.png"):
        RGBDFrame.load(color, tmp_path / "missing.png")
    with pytest.raises(ValueError, match="expected a single-channel 16-bit depth image, got uint8"):
        RGBDFrame.load(color, color)
