"""SimulatedCamera: the rendering of a real OpenGL context made a camera image. Its intrinsics are
checked against the rendering itself (a sphere drawn at a known point lands where the pinhole model
projects it), its noise against its attribute, and its output against MarkerTracker's expectations."""

from __future__ import annotations

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from coco_core import Application, BufferPolicy, Component, ConnectionPolicy, InputPort  # noqa: E402
from coco_core.errors import AttributeValueError  # noqa: E402
from coco_mr_vision.image import CameraIntrinsics, Image, ImageFormat  # noqa: E402
from coco_mr_vision.simulated_camera import SimulatedCamera, render_intrinsics  # noqa: E402

W, H, FOV = 320, 240, 50.0
POINT = np.array([0.12, -0.07, 1.0])
"""A point in the camera's optical frame (x right, y down, z forward), off the image centre."""


class Images(Component):
    image = InputPort(object)
    camera_info = InputPort(CameraIntrinsics)


def test_intrinsics_project_where_opengl_draws():
    from coco_mr_display.camera import GLCameraManager
    from coco_mr_display.entity import GLEntity
    from coco_mr_display.manager import GLManager

    app = Application("simulated-camera")
    app.transforms.add_static("world", "camera")  # the optical frame at the world origin
    display = GLManager("display", width=W, height=H, world="world", background=[0, 0, 0, 1])
    display.add_peer(GLCameraManager("view", follow_frame="camera", fov_y=FOV, near=0.05, far=10.0))
    display.add_peer(GLEntity("dot", mesh="sphere", size=[0.01], position=POINT.tolist(), color=[1, 1, 1],
                              ambient=1.0, diffuse=0.0, specular=0.0))
    app.add(display)
    camera = app.add(SimulatedCamera("camera", fov_y=FOV, noise=0.0, frame_id="head_camera"))
    sink = app.add(Images("sink"))
    app.connect(display.color, camera.rendered, ConnectionPolicy(BufferPolicy.BUFFER, size=4))
    app.connect(camera.image, sink.image, ConnectionPolicy(BufferPolicy.BUFFER, size=4))
    app.connect(camera.camera_info, sink.camera_info)
    assert display.configure() and camera.configure()
    try:
        display.step()
        camera.on_update()
    finally:
        display.stop()
    (stamped,) = sink.image.read_all()
    image = stamped.value
    assert image.format is ImageFormat.GRAY8 and image.frame_id == "head_camera"
    _, info = sink.camera_info.read()
    assert info.stamp == image.stamp and (info.width, info.height) == (W, H)
    mask = image.data > 128
    assert mask.sum() > 10, "the sphere is drawn"
    rows, cols = np.nonzero(mask)
    centre = np.array([cols.mean(), rows.mean()])
    projected = cv2.projectPoints(POINT[None], np.zeros(3), np.zeros(3), image.intrinsics.K, None)[0].ravel()
    assert np.linalg.norm(centre - projected) < 0.5, f"drawn at {centre}, projected at {projected}"


def test_noise_has_the_asked_deviation_and_a_seed_repeats_it():
    flat = Image(np.full((200, 300, 3), 100, np.uint8), ImageFormat.RGB8, 1.0)
    images = []
    for _ in range(2):
        camera = SimulatedCamera("camera", noise=5.0, seed=3)
        camera.on_config()
        images.append(camera.capture(flat))
    assert np.array_equal(images[0].data, images[1].data)
    assert abs(images[0].data.astype(float).std() - 5.0) < 0.2 and abs(images[0].data.mean() - 100) < 0.2
    np.testing.assert_array_equal(images[0].intrinsics.K, render_intrinsics(300, 200, 45.0, "camera").K)


def test_only_eight_bit_formats():
    with pytest.raises(AttributeValueError, match="8-bit images, not GRAY16"):
        SimulatedCamera("camera", format="GRAY16")


def test_marker_tracker_takes_intrinsics_from_camera_info():
    """A ROS Image topic carries no intrinsics: its camera_info topic beside it gives them."""
    from coco_mr_vision.marker_tracker import MarkerTracker

    marker = cv2.aruco.generateImageMarker(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), 3, 120)
    picture = np.full((240, 320), 255, np.uint8)
    picture[60:180, 100:220] = marker
    app = Application("info")
    tracker = app.add(MarkerTracker("tracker", dictionary="DICT_4X4_50", marker_length=0.1, publish=False))
    source = app.add(Images("source"))
    sink = app.add(Images("sink"))
    image_out = source.add_output("frames", object)
    info_out = source.add_output("info", CameraIntrinsics)
    app.connect(image_out, tracker.image)
    app.connect(info_out, tracker.camera_info)
    app.connect(tracker.markers, sink.image)
    tracker.on_config()
    image_out.write(Image(picture, ImageFormat.GRAY8, 1.0, "camera"))
    tracker.on_update()
    assert np.isnan(sink.image.read()[1].value.poses).all(), "no intrinsics yet: no pose"
    info_out.write(render_intrinsics(320, 240, 50.0, "camera"))
    image_out.write(Image(picture, ImageFormat.GRAY8, 2.0, "camera"))
    tracker.on_update()
    detections = sink.image.read()[1].value
    assert detections.ids.tolist() == [3] and np.isfinite(detections.poses).all()
    assert tracker.without_intrinsics == 1
