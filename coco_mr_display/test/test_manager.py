"""GLManager renders real frames headless: pixel regions, 2D, stereo disparity, depth, errors, two at once."""

from __future__ import annotations

import time

import cv2
import numpy as np
import pytest

from conftest import CUBE_CORNERS, Cube, Frames, project, render_once
from coco_core import Application, PeriodicActivity
from coco_core.component import Component, ErrorPolicy
from coco_core.policy import BufferPolicy, ConnectionPolicy, SyncPolicy
from coco_core.ports import InputPort
from coco_mr_display.camera import GLCameraManager
from coco_mr_display.manager import GLManager
from coco_mr_vision.image import ImageFormat

RED = (255, 0, 0)


def build(*peers: Component, **attributes: object) -> tuple[Application, GLManager, InputPort, InputPort]:
    """A manager with ``peers``, its color and depth ports connected to readers driven by the test."""
    app = Application("display-test")
    manager = GLManager("display", **attributes)
    for peer in peers:
        manager.add_peer(peer)
    colour, depth = Frames("colour_frames"), Frames("depth_frames")
    for component in (manager, colour, depth):
        app.add(component)
    frames = ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 16)
    app.connect("display.color", "colour_frames.image", frames)
    app.connect("display.depth", "depth_frames.image", frames)
    return app, manager, colour.image, depth.image


def camera(**attributes: object) -> GLCameraManager:
    defaults = dict(position=[2.0, -3.0, 1.5], look_at=[0.0, 0.0, 0.0], up=[0.0, 0.0, 1.0], fov_y=50.0)
    defaults.update(attributes)
    return GLCameraManager("camera", **defaults)


def assert_covers_projected_cube(mask: np.ndarray, cam: GLCameraManager, centre: list[float], size: float) -> None:
    """``mask`` (the pixels of the cube's colour) is the convex hull of the cube's 8 projected corners."""
    height, width = mask.shape
    view = cam.render_views((width, height), False, 0.0, "world")[0]
    hull = cv2.convexHull(project(view, CUBE_CORNERS * size + centre, height).astype(np.float32))
    expected = np.zeros_like(mask, np.uint8)
    cv2.fillPoly(expected, [np.round(hull - 0.5).astype(np.int32)], 1)
    area = cv2.contourArea(hull)
    assert area > 500, "the test scene should show a sizeable cube"
    # The same pixel count, up to the rasterisation of the outline, and the same place.
    assert abs(mask.sum() - area) < 0.02 * area + 2 * hull.shape[0]
    assert np.logical_xor(mask, expected.astype(bool)).sum() < 0.04 * area
    ys, xs = np.nonzero(mask)
    hx, hy = hull[:, 0, 0], hull[:, 0, 1]
    assert abs(xs.min() - hx.min()) <= 1 and abs(xs.max() + 1 - hx.max()) <= 1
    assert abs(ys.min() - hy.min()) <= 1 and abs(ys.max() + 1 - hy.max()) <= 1


def test_unit_cube_covers_its_projected_region() -> None:
    cam, cube = camera(), Cube("cube", position=[0.0, 0.0, 0.0])
    app, manager, colour, _ = build(cam, cube, width=320, height=240)
    image = render_once(manager, colour)
    assert image.format is ImageFormat.RGB8 and image.size == (320, 240) and image.frame_id == "world"
    red = np.all(image.data == RED, axis=2)
    assert_covers_projected_cube(red, cam, [0.0, 0.0, 0.0], 1.0)
    assert np.all(image.data[~red] == 0)  # the rest is the (default black) background


def test_moving_the_cube_moves_its_pixels_the_expected_way() -> None:
    cam = camera(position=[0.0, -5.0, 0.0], look_at=[0.0, 0.0, 0.0])
    cube = Cube("cube", position=[1.0, 0.0, 0.5], size=[0.5])
    app, manager, colour, _ = build(cam, cube, width=320, height=240, background=[0.0, 0.0, 1.0])
    image = render_once(manager, colour)
    red = np.all(image.data == RED, axis=2)
    assert_covers_projected_cube(red, cam, [1.0, 0.0, 0.5], 0.5)
    # World +x is image right and world +z image up for a camera on -y looking at the origin.
    ys, xs = np.nonzero(red)
    assert xs.min() > 160 and ys.max() < 120
    assert np.all(image.data[~red] == (0, 0, 255))


def test_stereo_halves_differ_by_the_expected_disparity() -> None:
    width, height, separation, depth = 640, 240, 0.1, 3.0
    cam = camera(position=[0.0, -depth, 0.0], look_at=[0.0, 0.0, 0.0], fov_y=60.0)
    # Wider than the eye separation: from both eyes only the front face shows, so the silhouette's
    # centroid is the projection of that face's centre.
    cube = Cube("cube", position=[0.0, 0.0, 0.0], size=[0.2])
    app, manager, colour, _ = build(cam, cube, width=width, height=height, visualization="stereo",
                                    eye_separation=separation)
    image = render_once(manager, colour)
    red = np.all(image.data == RED, axis=2)
    half = width // 2
    left, right = red[:, :half], red[:, half:]
    assert left.sum() > 100 and right.sum() > 100
    # The front face is at depth - size/2 from both eyes (parallel axes).
    z = depth - 0.1
    focal_px = (height / 2) / np.tan(np.radians(60.0) / 2)
    expected = focal_px * separation / z
    x_left = np.nonzero(left)[1].mean()
    x_right = np.nonzero(right)[1].mean()
    assert x_left - x_right == pytest.approx(expected, abs=0.75)
    # The centre of the view is between the two: the left eye sees the cube right of its centre.
    assert x_left > half / 2 > x_right


def test_2d_mode_draws_in_pixel_space_top_left_origin() -> None:
    # A cube of 40 px at (60, 30) px in the 2D view: x right, y down from the top-left corner.
    cube = Cube("cube", position=[60.0, 30.0, 0.0], size=[40.0, 40.0, 1.0])
    app, manager, colour, _ = build(cube, width=200, height=100, visualization="2d")
    image = render_once(manager, colour)
    red = np.all(image.data == RED, axis=2)
    ys, xs = np.nonzero(red)
    assert (xs.min(), xs.max(), ys.min(), ys.max()) == (40, 79, 10, 49)
    assert red.sum() == 40 * 40


def test_depth_output_is_metric_distance_along_the_view_axis() -> None:
    cam = camera(position=[0.0, -4.0, 0.0], look_at=[0.0, 0.0, 0.0], near=0.1, far=20.0)
    cube = Cube("cube", position=[0.0, 0.0, 0.0], size=[1.0])
    app, manager, colour, depth_reader = build(cam, cube, width=160, height=120, depth_output=True)
    assert manager.configure()
    try:
        manager.step()
        rgb, depth = colour.read_all()[0], depth_reader.read_all()[0]
    finally:
        manager.stop()
    assert depth.format is ImageFormat.DEPTH32F and depth.size == (160, 120)
    red = np.all(rgb.data == RED, axis=2)
    # Looking straight at the front face (y = -0.5): 3.5 m everywhere on it, unknown elsewhere.
    assert np.isnan(depth.data[~red]).all()
    assert np.nanmax(np.abs(depth.data[red] - 3.5)) < 3.5 * 1e-4
    # Depth images travel top row first, like the colour image.
    assert np.array_equal(~np.isnan(depth.data), red)


class Exploding(Cube):
    """A drawing peer that raises on every render after the first frame."""

    def render(self, ctx, view) -> None:  # noqa: ANN001 - the GLPeer signature
        if self.frames_drawn >= 1:
            raise RuntimeError("exploding peer")
        self.frames_drawn += 1
        super().render(ctx, view)

    def init(self) -> None:
        self.frames_drawn = 0


@pytest.mark.parametrize("policy", [ErrorPolicy.CONTINUE, ErrorPolicy.STOP_COMPONENT])
def test_a_peer_that_raises_does_not_stop_the_manager(policy: ErrorPolicy) -> None:
    cam = camera(position=[0.0, -4.0, 0.0], look_at=[0.0, 0.0, 0.0])
    bad = Exploding("bad", position=[-1.0, 0.0, 0.0], size=[0.5])
    bad.on_error = policy
    good = Cube("good", position=[1.0, 0.0, 0.0], size=[0.5], rgb=[0.0, 1.0, 0.0])
    app, manager, colour, _ = build(cam, bad, good, width=160, height=120)
    assert manager.configure()
    try:
        for _ in range(4):
            manager.step()
        frames = colour.read_all()
    finally:
        manager.stop()
    assert len(frames) == 4 and manager.enabled and manager.frames == 4
    assert bad.stats.errors == (3 if policy is ErrorPolicy.CONTINUE else 1)
    assert bad.enabled == (policy is ErrorPolicy.CONTINUE)
    for index, frame in enumerate(frames):
        green = np.all(frame.data == (0, 255, 0), axis=2).sum()
        red = np.all(frame.data == RED, axis=2).sum()
        assert green > 50, f"frame {index}: the peer after the failing one was not drawn"
        assert (red > 50) == (index == 0)


def test_two_managers_render_at_once_on_their_own_activities() -> None:
    app = Application("two-displays")
    sinks = []
    for index, (rgb, rate) in enumerate((([1.0, 0.0, 0.0], 0.02), ([0.0, 0.0, 1.0], 0.03))):
        manager = GLManager(f"display{index}", width=96, height=64)
        manager.add_peer(GLCameraManager(f"camera{index}", position=[0.0, -4.0, 0.0], look_at=[0.0, 0.0, 0.0]))
        manager.add_peer(Cube(f"cube{index}", rgb=rgb))
        sink = Frames(f"frames{index}")
        app.add(manager, PeriodicActivity(f"render{index}", rate))
        app.add(sink, PeriodicActivity(f"sink{index}", 0.01))
        app.connect(f"display{index}.color", f"frames{index}.image",
                    ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 16))
        sinks.append(sink)
    app.start()
    try:
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and min(len(s.images) for s in sinks) < 10:
            time.sleep(0.05)
    finally:
        assert app.stop()
    threads = {app.activity("render0").driver.thread, app.activity("render1").driver.thread}
    assert len(threads) == 2
    for sink, colour in zip(sinks, (RED, (0, 0, 255))):
        assert len(sink.images) >= 10
        for image in sink.images:
            assert image.size == (96, 64)
            covered = np.all(image.data == colour, axis=2).sum()
            assert covered > 200, "each manager draws its own cube in its own context"
    for index in range(2):
        manager = app.component(f"display{index}")
        assert manager.stats.errors == 0 and manager.surface is None  # released at stop, in its thread


def test_mono_without_a_camera_is_a_clear_error(caplog: pytest.LogCaptureFixture) -> None:
    app, manager, colour, _ = build(Cube("cube"), width=64, height=64)
    assert not manager.configure()
    assert "mono visualization needs a camera peer (GLCameraManager); peers: cube" in caplog.text


class BrokenShader(Cube):
    """A drawing peer whose GPU setup fails (a shader that does not compile)."""

    def gl_init(self, ctx) -> None:  # noqa: ANN001 - the GLPeer signature
        self.released = False
        ctx.program(vertex_shader="#version 330\nvoid main() { gl_Position = undefined_name; }")

    def gl_release(self) -> None:
        self.released = True


def test_a_peer_whose_gl_init_fails_is_disabled_and_the_others_draw(caplog: pytest.LogCaptureFixture) -> None:
    cam = camera(position=[0.0, -4.0, 0.0], look_at=[0.0, 0.0, 0.0])
    broken, good = BrokenShader("broken"), Cube("good", size=[0.5], rgb=[0.0, 1.0, 0.0])
    app, manager, colour, _ = build(cam, broken, good, width=96, height=64)
    image = render_once(manager, colour)
    assert "component broken raised in gl_init" in caplog.text and "undefined_name" in caplog.text
    assert not broken.enabled and not broken.released  # nothing to release: it never initialised
    assert manager.enabled and np.all(image.data == (0, 255, 0), axis=2).sum() > 50
