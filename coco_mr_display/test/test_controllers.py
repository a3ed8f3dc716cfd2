"""FPSCamera and ArcBallCamera, fed window events through the dispatch path GLManager uses for a window."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from conftest import project
from coco_core import Application
from coco_mr_display.camera import GLCameraManager
from coco_mr_display.controllers import ArcBallCamera, FPSCamera
from coco_mr_display.events import Action, EventKind, InputEvent, MouseButton, dispatch

SIZE = (640, 480)


def rig(controller_type: type, **attributes: object) -> tuple[GLCameraManager, object]:
    """A configured camera at (0, -4, 1) looking at (0, 0, 1) (z up) with one controller peer."""
    app = Application("controller-test")
    camera = GLCameraManager("camera", position=[0.0, -4.0, 1.0], look_at=[0.0, 0.0, 1.0], up=[0.0, 0.0, 1.0])
    controller = camera.add_peer(controller_type("controller", **attributes))
    app.add(camera)
    assert camera.configure()
    return camera, controller


def feed(camera: GLCameraManager, *events: InputEvent) -> None:
    """What GLManager does with a window's events each frame: dispatch, then step."""
    dispatch(events, camera.walk())
    camera.step()


def key(name: str, action: Action = Action.PRESS, mods: int = 0) -> InputEvent:
    return InputEvent(EventKind.KEY, SIZE, key=name, action=action, mods=mods)


def button(which: MouseButton, action: Action, x: float, y: float) -> InputEvent:
    return InputEvent(EventKind.MOUSE_BUTTON, SIZE, action=action, button=int(which), x=x, y=y)


def cursor(x: float, y: float) -> InputEvent:
    return InputEvent(EventKind.CURSOR, SIZE, x=x, y=y)


def drag(which: MouseButton, path: list[tuple[float, float]]) -> list[InputEvent]:
    return [button(which, Action.PRESS, *path[0]), *(cursor(x, y) for x, y in path[1:]),
            button(which, Action.RELEASE, *path[-1])]


def hold(camera: GLCameraManager, seconds: float) -> float:
    """Step the camera for about ``seconds`` (as frames would); the time that really passed."""
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        time.sleep(0.01)
        camera.step()
    return time.perf_counter() - start


def test_fps_w_moves_forward_at_the_set_speed_and_release_stops() -> None:
    camera, _ = rig(FPSCamera, speed=2.0)
    feed(camera, key("W"))
    elapsed = hold(camera, 0.3)
    feed(camera, key("W", Action.RELEASE))
    position = camera.camera_pose[:3, 3]
    moved = position[1] + 4.0
    # Forward is +y here; the distance is speed x time held (each update integrates its own interval).
    assert position[0] == pytest.approx(0.0, abs=1e-12) and position[2] == pytest.approx(1.0, abs=1e-12)
    assert 2.0 * (elapsed - 0.05) < moved <= 2.0 * (elapsed + 0.05)
    hold(camera, 0.05)
    np.testing.assert_allclose(camera.camera_pose[:3, 3], position)


def test_fps_strafe_up_and_shift() -> None:
    camera, _ = rig(FPSCamera, speed=1.0, fast_factor=4.0)
    feed(camera, key("D"), key("E"))
    hold(camera, 0.2)
    feed(camera, key("D", Action.RELEASE), key("E", Action.RELEASE))
    x, y, z = camera.camera_pose[:3, 3]
    assert x > 0.1 and z - 1.0 > 0.1 and x == pytest.approx(z - 1.0, rel=0.05) and y == pytest.approx(-4.0)
    # Shift held (its own press carries no modifier yet, the next keys do): 4 times faster.
    feed(camera, key("LEFT_SHIFT"), key("A", mods=0x0001))
    before = camera.camera_pose[0, 3]
    elapsed = hold(camera, 0.2)
    assert before - camera.camera_pose[0, 3] > 4.0 * (elapsed - 0.06)
    # Shift released (X still reports Shift on its release event): normal speed again.
    feed(camera, key("LEFT_SHIFT", Action.RELEASE, mods=0x0001))
    before = camera.camera_pose[0, 3]
    elapsed = hold(camera, 0.2)
    feed(camera, key("A", Action.RELEASE))
    assert 0.0 < before - camera.camera_pose[0, 3] < 1.0 * (elapsed + 0.06)


def test_fps_drag_turns_yaw_about_up_and_pitch_is_clamped() -> None:
    camera, _ = rig(FPSCamera, sensitivity=0.01)
    # 100 px to the right: turn right by 1 rad about world z.
    feed(camera, *drag(MouseButton.LEFT, [(300, 200), (350, 200), (400, 200)]))
    forward = -camera.camera_pose[:3, 2]
    np.testing.assert_allclose(forward, [math.sin(1.0), math.cos(1.0), 0.0], atol=1e-12)
    np.testing.assert_allclose(camera.camera_pose[:3, 3], [0.0, -4.0, 1.0])
    # Dragging far down looks down, but never past 89 degrees (no flip over the pole).
    feed(camera, *drag(MouseButton.LEFT, [(300, 100), (300, 600)]))
    forward = -camera.camera_pose[:3, 2]
    assert math.degrees(math.asin(forward[2])) == pytest.approx(-89.0, abs=1e-9)
    assert camera.camera_pose[:3, 1] @ [0.0, 0.0, 1.0] > 0  # still upright
    # Another button does not turn.
    before = camera.camera_pose
    feed(camera, *drag(MouseButton.RIGHT, [(0, 0), (100, 50)]))
    np.testing.assert_allclose(camera.camera_pose, before)


def test_arcball_drag_orbits_around_the_target() -> None:
    camera, arcball = rig(ArcBallCamera)
    target = np.array([0.0, 0.0, 1.0])
    feed(camera, *drag(MouseButton.LEFT, [(320, 240), (380, 240), (440, 240)]))
    pose = camera.camera_pose
    # Dragging right from the centre turns the scene right: the camera orbits to its left (-x) about
    # the up axis, at the same distance, still looking at the target.
    assert np.linalg.norm(pose[:3, 3] - target) == pytest.approx(4.0)
    assert pose[0, 3] < -1.0 and pose[2, 3] == pytest.approx(1.0)
    view = camera.render_views(SIZE, False, 0.0, "world")[0]
    np.testing.assert_allclose(project(view, target[None], SIZE[1])[0], [320, 240], atol=1e-9)
    # The angle is the arc between the two sphere points of the drag (Shoemake).
    p0, p1 = ArcBallCamera.sphere_point(320, 240, SIZE), ArcBallCamera.sphere_point(440, 240, SIZE)
    angle = math.acos(p0 @ p1)
    assert math.atan2(-pose[0, 3], -pose[1, 3]) == pytest.approx(angle, abs=1e-9)
    # Dragging back to the start returns to the start pose.
    feed(camera, *drag(MouseButton.LEFT, [(440, 240), (320, 240)]))
    np.testing.assert_allclose(camera.camera_pose[:3, 3], [0.0, -4.0, 1.0], atol=1e-9)


def test_arcball_scroll_zooms_and_pan_keeps_the_dragged_point_under_the_cursor() -> None:
    camera, arcball = rig(ArcBallCamera, zoom_factor=2.0)
    feed(camera, InputEvent(EventKind.SCROLL, SIZE, x=0.0, y=1.0))
    np.testing.assert_allclose(camera.camera_pose[:3, 3], [0.0, -2.0, 1.0])
    feed(camera, InputEvent(EventKind.SCROLL, SIZE, x=0.0, y=-2.0))
    np.testing.assert_allclose(camera.camera_pose[:3, 3], [0.0, -8.0, 1.0])
    # Pan: the target point, seen at the centre, follows the cursor 100 px right and 50 px down.
    feed(camera, *drag(MouseButton.RIGHT, [(320, 240), (420, 290)]))
    view = camera.render_views(SIZE, False, 0.0, "world")[0]
    np.testing.assert_allclose(project(view, np.array([[0.0, 0.0, 1.0]]), SIZE[1])[0], [420, 290], atol=1e-9)
    np.testing.assert_allclose(arcball.centre, camera.camera_pose[:3, 3] + [0.0, 8.0, 0.0], atol=1e-12)


def test_a_controller_outside_a_camera_is_a_clear_error(caplog: pytest.LogCaptureFixture) -> None:
    app = Application("misplaced")
    controller = FPSCamera("fps")
    app.add(controller)
    assert not controller.configure()
    assert "FPSCamera fps must be a peer of a GLCameraManager, not of nothing" in caplog.text


class Faulty(FPSCamera):
    def handle_event(self, event: InputEvent) -> None:
        raise RuntimeError("faulty controller")


def test_a_controller_that_raises_does_not_keep_events_from_the_others(caplog: pytest.LogCaptureFixture) -> None:
    app = Application("faulty")
    camera = GLCameraManager("camera", position=[0.0, -4.0, 1.0], look_at=[0.0, 0.0, 1.0])
    faulty = camera.add_peer(Faulty("faulty"))
    camera.add_peer(ArcBallCamera("arcball", zoom_factor=2.0))
    app.add(camera)
    assert camera.configure()
    feed(camera, InputEvent(EventKind.SCROLL, SIZE, y=1.0), InputEvent(EventKind.SCROLL, SIZE, y=1.0))
    np.testing.assert_allclose(camera.camera_pose[:3, 3], [0.0, -1.0, 1.0])
    assert faulty.stats.errors == 2 and "component faulty raised in handle_event" in caplog.text
