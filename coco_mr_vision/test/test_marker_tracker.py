"""MarkerTracker on a real camera image of an ArUco marker: corners against the source project's
expected values, the pose against its reprojection, edges in the transformation graph, a rendered
marker at a known pose, and clear errors for unknown dictionaries."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from coco_core import Application, BufferPolicy, Component, ConnectionPolicy, OutputPort  # noqa: E402
from coco_core.attributes import AttributeValueError  # noqa: E402
from coco_core.stamps import Stamp, Stamped  # noqa: E402
from coco_mr_vision.image import CameraIntrinsics, Image, ImageFormat  # noqa: E402
from coco_mr_vision.marker_tracker import MarkerTracker, square_points  # noqa: E402

ARUCO = Path(__file__).resolve().parents[3] / "shared" / "data" / "aruco"


@pytest.fixture(scope="module")
def tag():
    png, meta = ARUCO / "tag_01_d7_14cm.png", ARUCO / "tag_01_d7_14cm.json"
    if not png.exists():
        pytest.skip(f"{ARUCO} is absent (the shared data sets are not beside this checkout)")
    document = json.loads(meta.read_text())
    intrinsics = CameraIntrinsics.from_json(document)
    image = Image(cv2.imread(str(png), cv2.IMREAD_COLOR), ImageFormat.BGR8, 42.0, "usb_cam", intrinsics)
    return image, document


class Camera(Component):
    image = OutputPort(object)


def rig(**attributes):
    app = Application("markers")
    camera = app.add(Camera("camera"))
    tracker = app.add(MarkerTracker("tracker", **attributes))
    app.connect(camera.image, tracker.image, ConnectionPolicy(BufferPolicy.BUFFER, size=8))
    sink_port = tracker.markers
    tracker.on_config()
    return app, camera, tracker, sink_port


def test_corners_within_half_a_pixel_of_the_expected_ones(tag):
    image, document = tag
    _, _, tracker, _ = rig(dictionary=document["dictionary"], marker_length=document["marker_length_m"])
    detections = tracker.detect(image)
    assert detections.ids.tolist() == [1]
    expected = np.array(document["expected"][0]["corners_px"])
    error = np.linalg.norm(detections.corners[0] - expected, axis=1)
    assert error.max() < 0.5, error


def test_pose_reprojects_onto_the_corners_and_goes_into_the_graph(tag):
    image, document = tag
    app, camera, tracker, _ = rig(dictionary=document["dictionary"], marker_length=document["marker_length_m"],
                                  marker_frame="tag{id}")
    yuyv = image.to("YUYV")  # as a V4L2 camera delivers it: the tracker converts to grey itself
    camera.image.write(Stamped(yuyv, Stamp(1.0, 3, "camera")))
    tracker.on_update()
    pose = app.transforms.lookup("usb_cam", "tag1")
    detections = tracker.detect(yuyv)
    assert np.allclose(pose, detections.pose(1))
    rvec = cv2.Rodrigues(pose[:3, :3])[0]
    projected, _ = cv2.projectPoints(square_points(0.145), rvec, pose[:3, 3], image.intrinsics.K, image.intrinsics.D)
    assert np.abs(projected.reshape(4, 2) - detections.corners[0]).max() < 1.0
    assert 0.3 < pose[2, 3] < 1.5 and pose[2, 2] < 0, "in front of the camera, facing it"
    assert app.transforms.edge("usb_cam", "tag1").kind.value == "dynamic"
    assert tracker.frames == 1 and tracker.detected == 1


def test_synthetic_marker_at_a_known_pose_is_found_there():
    """A marker drawn by OpenCV, warped into a pinhole camera at a known pose: the pose comes back."""
    intrinsics = CameraIntrinsics(640, 480, 600.0, 600.0, 320.0, 240.0)
    length, pixels = 0.1, 400
    marker = cv2.aruco.generateImageMarker(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), 7, pixels)
    canvas = np.full((pixels * 2, pixels * 2), 255, np.uint8)
    canvas[pixels // 2:pixels // 2 + pixels, pixels // 2:pixels // 2 + pixels] = marker
    truth = np.eye(4)
    truth[:3, :3] = cv2.Rodrigues(np.array([0.3, -0.2, 0.1]))[0] @ np.diag([1.0, -1.0, -1.0])
    truth[:3, 3] = [0.02, -0.01, 0.5]
    # Canvas pixel -> marker plane (metres), then plane -> image by the true pose.
    scale = length / pixels
    plane = np.array([[scale, 0, -pixels * scale], [0, -scale, pixels * scale], [0, 0, 1]])
    homography = intrinsics.K @ np.column_stack([truth[:3, 0], truth[:3, 1], truth[:3, 3]]) @ plane
    image = cv2.warpPerspective(canvas, homography, (640, 480), flags=cv2.INTER_LINEAR, borderValue=128)
    _, _, tracker, _ = rig(dictionary="DICT_4X4_50", marker_length=length)
    detections = tracker.detect(Image(image, ImageFormat.GRAY8, intrinsics=intrinsics))
    pose = detections.pose(7)
    assert np.linalg.norm(pose[:3, 3] - truth[:3, 3]) < 0.003
    angle = np.degrees(np.arccos(np.clip((np.trace(pose[:3, :3].T @ truth[:3, :3]) - 1) / 2, -1, 1)))
    assert angle < 1.0


def test_id_filter_and_images_without_intrinsics(tag):
    image, document = tag
    _, _, tracker, _ = rig(dictionary=document["dictionary"], ids=[5, 6])
    assert tracker.detect(image).ids.size == 0
    _, _, tracker, _ = rig(dictionary=document["dictionary"])
    bare = Image(image.data, ImageFormat.BGR8)
    detections = tracker.detect(bare)
    assert detections.ids.tolist() == [1] and np.isnan(detections.poses).all()
    assert tracker.without_intrinsics == 1


def test_unknown_dictionary_lists_the_valid_ones():
    with pytest.raises(AttributeValueError, match="unknown marker dictionary 'DICT_5X5_1001'.*DICT_5X5_1000"):
        MarkerTracker("tracker", dictionary="DICT_5X5_1001")


def test_rgbd_frames_are_searched_in_their_colour_image(tag):
    """A streamed RGB-D camera (StreamingReceiver.rgbd) feeds the tracker directly: the colour image
    with the frame's intrinsics, the same detection as of the image itself."""
    from coco_mr_vision.rgbd import RGBDFrame

    image, document = tag
    app, camera, tracker, _ = rig(dictionary=document["dictionary"], marker_length=document["marker_length_m"])
    colour = Image(image.data, image.format, image.stamp, image.frame_id)  # the intrinsics are the frame's
    depth = Image(np.full(image.data.shape[:2], 1000, np.uint16), ImageFormat.DEPTH16, image.stamp, image.frame_id)
    camera.image.write(Stamped(RGBDFrame(colour, depth, image.intrinsics), Stamp(1.0, 1, "camera")))
    tracker.on_update()
    assert tracker.frames == 1 and tracker.without_intrinsics == 0
    assert np.allclose(app.transforms.lookup("usb_cam", "marker_1"), tracker.detect(image).pose(1))
