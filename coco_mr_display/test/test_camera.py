"""GLCameraManager: perspective and Kooima off-axis views against independent, textbook computations."""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import Cube, Frames, render_once
from coco_core import Application
from coco_core.component import Component
from coco_core.ports import OutputPort
from coco_core.policy import BufferPolicy, ConnectionPolicy, SyncPolicy
from coco_core.transforms import se3
from coco_core.transforms.samples import FramePose, TransformSample
from coco_mr_display.camera import GLCameraManager
from coco_mr_display.manager import GLManager
from coco_mr_display.view import Eye

# A 0.52 x 0.32 m monitor standing on a desk: x right, z up, the viewer on -y.
LL, LR, UL = np.array([-0.26, 0.0, 0.0]), np.array([0.26, 0.0, 0.0]), np.array([-0.26, 0.0, 0.32])
NEAR, FAR = 0.05, 10.0


def gl_frustum(left: float, right: float, bottom: float, top: float, near: float, far: float) -> np.ndarray:
    """The glFrustum matrix as printed in the OpenGL 2.1 reference pages (written out independently)."""
    a, b = (right + left) / (right - left), (top + bottom) / (top - bottom)
    c, d = -(far + near) / (far - near), -(2 * far * near) / (far - near)
    return np.array([[2 * near / (right - left), 0, a, 0], [0, 2 * near / (top - bottom), b, 0],
                     [0, 0, c, d], [0, 0, -1, 0]], dtype=float)


def make_camera(**attributes: object) -> GLCameraManager:
    app = Application("camera-test")
    camera = GLCameraManager("camera", **attributes)
    app.add(camera)
    assert camera.configure()
    return camera


def oblique(corners: tuple[np.ndarray, ...], eye: np.ndarray) -> GLCameraManager:
    ll, lr, ul = corners
    return make_camera(projection="oblique", screen_lower_left=list(ll), screen_lower_right=list(lr),
                       screen_upper_left=list(ul), eye_position=list(eye), near=NEAR, far=FAR)


def ndc(view_projection: np.ndarray, points: np.ndarray) -> np.ndarray:
    clip = np.c_[points, np.ones(len(points))] @ view_projection.T
    return clip[:, :3] / clip[:, 3:]


@pytest.mark.parametrize("eye", [(0.0, -0.6, 0.16), (0.2, -0.45, 0.3), (-0.4, -0.9, -0.1)])
def test_oblique_frustum_matches_gl_frustum_through_the_screen_edges(eye: tuple[float, float, float]) -> None:
    pe = np.array(eye)
    view = oblique((LL, LR, UL), pe).render_views((640, 480), False, 0.0, "world")[0]
    # Screen-aligned axes are the world's here (right = x, up = z, normal = -y): distance and the
    # edges measured on the near plane, by similar triangles.
    distance = LL[1] - pe[1]
    scale = NEAR / distance
    expected = gl_frustum((LL[0] - pe[0]) * scale, (LR[0] - pe[0]) * scale, (LL[2] - pe[2]) * scale,
                          (UL[2] - pe[2]) * scale, NEAR, FAR)
    np.testing.assert_allclose(view.projection, expected, atol=1e-12)
    # The screen's corners land exactly on the viewport's corners, whatever the eye position.
    ur = LR + UL - LL
    np.testing.assert_allclose(ndc(view.view_projection, np.array([LL, LR, UL, ur]))[:, :2],
                               [[-1, -1], [1, -1], [-1, 1], [1, 1]], atol=1e-12)
    # The view looks along the screen normal from the eye; the screen stays upright.
    np.testing.assert_allclose(view.camera_position, pe, atol=1e-12)
    np.testing.assert_allclose(view.view[:3, :3], [[1, 0, 0], [0, 0, 1], [0, -1, 0]], atol=1e-12)


def test_oblique_is_invariant_to_where_the_screen_is_in_the_world() -> None:
    pe = np.array([0.1, -0.5, 0.2])
    reference = oblique((LL, LR, UL), pe).render_views((640, 480), False, 0.0, "world")[0]
    # The same screen and eye, moved by a rigid transform: same frustum, view composed with the motion.
    motion = se3.make(se3.axis_angle(np.array([1.0, 2.0, 3.0]) / math.sqrt(14), 0.7), [0.4, 1.5, -0.3])
    moved = [motion[:3, :3] @ p + motion[:3, 3] for p in (LL, LR, UL, pe)]
    view = oblique(tuple(moved[:3]), moved[3]).render_views((640, 480), False, 0.0, "world")[0]
    np.testing.assert_allclose(view.projection, reference.projection, atol=1e-12)
    np.testing.assert_allclose(view.view, reference.view @ se3.inverse(motion), atol=1e-12)


def test_oblique_stereo_gives_each_eye_its_own_frustum_through_the_same_screen() -> None:
    camera = oblique((LL, LR, UL), np.array([0.0, -0.6, 0.16]))
    left, right = camera.render_views((1280, 480), True, 0.064, "world")
    assert (left.eye, right.eye) == (Eye.LEFT, Eye.RIGHT)
    assert left.viewport == (0, 0, 640, 480) and right.viewport == (640, 0, 640, 480)
    np.testing.assert_allclose(left.camera_position, [-0.032, -0.6, 0.16], atol=1e-12)
    np.testing.assert_allclose(right.camera_position, [0.032, -0.6, 0.16], atol=1e-12)
    ur = LR + UL - LL
    for view in (left, right):
        np.testing.assert_allclose(ndc(view.view_projection, np.array([LL, LR, UL, ur]))[:, :2],
                                   [[-1, -1], [1, -1], [-1, 1], [1, 1]], atol=1e-12)
    # A point 0.3 m behind the screen: uncrossed disparity (right eye sees it further right), a point
    # on the screen: none.
    behind, on = np.array([[0.0, 0.3, 0.16]]), np.array([[0.1, 0.0, 0.2]])
    assert ndc(right.view_projection, behind)[0, 0] > ndc(left.view_projection, behind)[0, 0]
    np.testing.assert_allclose(ndc(right.view_projection, on), ndc(left.view_projection, on), atol=1e-12)


class Source(Component):
    """Writes what the test gives it (a tracker, a pose publisher)."""

    out = OutputPort(object)


def connect_source(camera: GLCameraManager, port: str) -> OutputPort:
    source = Source(f"source_{port}")
    camera.app.add(source)
    camera.app.connect(source.out, camera.port(port))
    return source.out


def test_tracked_head_pose_moves_the_eyes_along_the_head_axis() -> None:
    camera = oblique((LL, LR, UL), np.array([0.0, -0.6, 0.16]))
    tracker = connect_source(camera, "eye")
    # A tracked point moves the eye, the separation axis stays the screen's right axis.
    tracker.write(np.array([0.1, -0.5, 0.1]))
    camera.step()
    left, right = camera.render_views((1280, 480), True, 0.06, "world")
    np.testing.assert_allclose(left.camera_position, [0.07, -0.5, 0.1], atol=1e-12)
    # Head turned 90 degrees about z (its x axis is world y): eyes separate along y.
    head = se3.make(se3.axis_angle([0.0, 0.0, 1.0], math.pi / 2), [0.05, -0.7, 0.2])
    tracker.write(FramePose("world", "head", head))
    camera.step()
    np.testing.assert_allclose(camera.head_position, [0.05, -0.7, 0.2])
    left, right = camera.render_views((1280, 480), True, 0.06, "world")
    np.testing.assert_allclose(left.camera_position, [0.05, -0.73, 0.2], atol=1e-12)
    np.testing.assert_allclose(right.camera_position, [0.05, -0.67, 0.2], atol=1e-12)


def test_perspective_matches_glu_perspective_and_look_at() -> None:
    camera = make_camera(position=[3.0, 0.0, 1.0], look_at=[0.0, 0.0, 1.0], up=[0.0, 0.0, 1.0],
                         fov_y=60.0, near=0.1, far=50.0)
    view = camera.render_views((800, 400), False, 0.0, "map")[0]
    assert view.frame == "map" and view.viewport == (0, 0, 800, 400)
    top = 0.1 * math.tan(math.radians(30.0))
    np.testing.assert_allclose(view.projection, gl_frustum(-2 * top, 2 * top, -top, top, 0.1, 50.0), atol=1e-12)
    # The camera at +3 x looks along -x with z up, so +y is on its right: x_eye = y, y_eye = z - 1,
    # z_eye = x - 3.
    p = np.array([0.0, 0.5, 2.0, 1.0])
    np.testing.assert_allclose(view.view @ p, [0.5, 1.0, -3.0, 1.0], atol=1e-12)


def test_pose_port_and_followed_frame_use_the_optical_convention() -> None:
    # An optical camera frame (z forward, y down) 2 m in front of the origin looking at it along +y.
    optical = se3.make(np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]), [0.0, -2.0, 0.0])
    for source in ("port", "graph"):
        app = Application("pose-test")
        camera = GLCameraManager("camera", follow_frame="cam" if source == "graph" else "")
        app.add(camera)
        assert camera.configure()
        if source == "graph":
            app.transforms.set_transform("world", "cam", optical)
        else:
            connect_source(camera, "pose").write(TransformSample("world", "cam", optical))
        camera.step()
        view = camera.render_views((100, 100), False, 0.0, "world")[0]
        # The origin is straight ahead, 2 m away; world z is up in the image.
        np.testing.assert_allclose(view.view @ [0, 0, 0, 1.0], [0, 0, -2.0, 1.0], atol=1e-12)
        np.testing.assert_allclose(view.view @ [0, 0, 1.0, 1.0], [0, 1.0, -2.0, 1.0], atol=1e-12)


def test_screen_sized_box_on_the_screen_fills_the_frame_from_any_eye() -> None:
    """Co-location, rendered: a thin box covering the physical screen covers exactly the viewport."""
    for eye in ([0.0, -0.6, 0.16], [0.3, -0.4, 0.4]):
        app = Application("oblique-render")
        manager = GLManager("display", width=160, height=100)
        manager.add_peer(GLCameraManager("camera", projection="oblique", screen_lower_left=list(LL),
                                         screen_lower_right=list(LR), screen_upper_left=list(UL), eye_position=eye))
        # 2 mm thick, 1 mm inset: the front face is inside the screen rectangle by a sub-pixel margin.
        manager.add_peer(Cube("panel", position=[0.0, 0.001, 0.16], size=[0.518, 0.002, 0.318]))
        smaller = Cube("marker", position=[0.13, -0.05, 0.24], size=[0.05], rgb=[0.0, 1.0, 0.0])
        manager.add_peer(smaller)
        frames = Frames("frames")
        app.add(manager)
        app.add(frames)
        app.connect("display.color", "frames.image", ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 4))
        image = render_once(manager, frames.image).data
        red = np.all(image == (255, 0, 0), axis=2)
        green = np.all(image == (0, 255, 0), axis=2)
        assert (red | green)[1:-1, 1:-1].all(), f"eye {eye}: the screen-sized panel does not fill the frame"
        assert green.sum() > 20
