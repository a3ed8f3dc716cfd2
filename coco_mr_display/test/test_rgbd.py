"""GLRGBDImage: real and synthetic RGB-D frames unprojected on the GPU, rendered headless, checked
against the input pixels and depths.

Rendered from the depth camera's own pose with its own intrinsics, the surface must land back on
the pixels it came from: colour equal to the colour image, depth equal to the depth image. The
rubber-sheet and averaging tests use synthetic depth whose answer is known.
"""

from __future__ import annotations

import logging
from pathlib import Path

import moderngl
import numpy as np
import pytest

from conftest import Frames, render_once
from coco_core.application import Application
from coco_core.attributes import AttributeValueError
from coco_core.component import Component
from coco_core.ports import OutputPort
from coco_core.transforms import se3
from coco_mr_display.camera import GLCameraManager
from coco_mr_display.image import GLImage
from coco_mr_display.manager import GLManager
from coco_mr_display.pinhole import optical_view, pinhole_projection
from coco_mr_display.rgbd import LOD_SAMPLE, MAX_STRIDE, GLRGBDImage, automatic_stride, sample_points
from coco_mr_display.surface_triangles import grid_indices, kept_triangles
from coco_mr_display.view import RenderView
from coco_mr_vision.image import CameraIntrinsics, Image, ImageFormat
from coco_mr_vision.rgbd import RGBDFrame

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
REDWOOD = DATA / "rgbd" / "redwood"
TUM = DATA / "rgbd" / "tum"
PRIMESENSE = (525.0, 525.0, 319.5, 239.5)
"""fx, fy, cx, cy of the Redwood data (and Open3D's default for the TUM pair)."""


def needs(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"{path} is absent (the shared data sets are not beside this checkout)")
    return path


def redwood(index: int = 0) -> RGBDFrame:
    intrinsics = CameraIntrinsics.from_json(needs(REDWOOD / "camera_primesense.json"))
    return RGBDFrame.load(REDWOOD / "color" / f"{index:05d}.jpg", REDWOOD / "depth" / f"{index:05d}.png", intrinsics)


class Sensor(Component):
    rgbd = OutputPort(RGBDFrame)
    color = OutputPort(Image)
    depth = OutputPort(Image)
    intrinsics = OutputPort(CameraIntrinsics)


class Stage:
    """A GLRGBDImage fed by a sensor component through the ``ports`` named, in its own framebuffer."""

    def __init__(self, ctx: moderngl.Context, fbo: moderngl.Framebuffer, ports: tuple[str, ...] = ("rgbd",),
                 **attributes: object) -> None:
        self.ctx, self.fbo = ctx, fbo
        self.app = Application("test_rgbd")
        self.sensor = self.app.add(Sensor("sensor"))
        self.peer = self.app.add(GLRGBDImage("surface", **attributes))
        for port in ports:
            self.app.connect(self.sensor.port(port), self.peer.port(port))
        self.peer.gl_init(ctx)

    def send(self, **values: object) -> None:
        for port, value in values.items():
            self.sensor.port(port).write(value)

    def frame(self, view: RenderView) -> tuple[np.ndarray, np.ndarray]:
        """One frame: (RGB top row first, depth along the view axis in metres, NaN where empty)."""
        self.peer.step()
        self.fbo.use()
        self.fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
        self.ctx.enable_only(moderngl.DEPTH_TEST)
        self.ctx.viewport = view.viewport
        self.peer.render(self.ctx, view)
        width, height = self.fbo.size
        rgb = np.frombuffer(self.fbo.read(components=3, alignment=1), np.uint8).reshape(height, width, 3)
        return rgb[::-1], GLManager.read_depth(self.fbo, [view])[::-1]


@pytest.fixture
def stage(gl_context, framebuffer):
    def make(width: int = 640, height: int = 480, ports: tuple[str, ...] = ("rgbd",), **attributes: object) -> Stage:
        return Stage(gl_context, framebuffer(width, height), ports, **attributes)

    return make


def camera_view(pose: np.ndarray, intrinsics: tuple[float, float, float, float], size: tuple[int, int]) -> RenderView:
    """The view of a pinhole camera with optical-frame pose ``pose`` in the world."""
    return RenderView(optical_view(pose), pinhole_projection(*intrinsics, *size, 0.1, 20.0), (0, 0, *size))


def interior(valid: np.ndarray) -> np.ndarray:
    """Pixels whose 3x3 neighbourhood is valid: every triangle around their vertex is drawn."""
    inner = valid.copy()
    inner[0, :] = inner[-1, :] = inner[:, 0] = inner[:, -1] = False
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            inner[1:-1, 1:-1] &= valid[1 + dy:valid.shape[0] - 1 + dy, 1 + dx:valid.shape[1] - 1 + dx]
    return inner


def assert_reproduces(rgb: np.ndarray, depth: np.ndarray, frame: RGBDFrame) -> None:
    """Colour and depth of the render equal the frame's where the frame has depth."""
    metres = frame.depth_metres()
    inner = interior(np.isfinite(metres) & (metres > 0))
    assert inner.mean() > 0.7
    colour_error = np.abs(rgb.astype(int) - frame.color.to_rgb()).max(axis=2)[inner]
    assert np.mean(colour_error <= 2) > 0.99
    depth_error = np.abs(depth - metres)[inner]
    assert np.median(depth_error) < 1e-4 and np.percentile(depth_error, 99) < 2e-3
    empty = interior(~(metres > 0))  # far from any valid pixel: nothing drawn
    assert np.isnan(depth[empty]).all() and rgb[empty].max() == 0


# --- real frames from their own camera ------------------------------------------------------------

def test_redwood_frame_seen_from_its_camera_is_its_colour_image(stage):
    frame = redwood()
    scene = stage()
    scene.send(rgbd=frame)
    rgb, depth = scene.frame(camera_view(np.eye(4), PRIMESENSE, (640, 480)))
    assert_reproduces(rgb, depth, frame)


@pytest.mark.parametrize("source", ["graph", "attributes"])
def test_camera_pose_from_the_graph_or_attributes(stage, source):
    """The surface moves with its camera: rendered from the moved camera it looks the same."""
    frame = redwood(1)
    xyz, rpy = (0.4, -1.2, 0.9), (-1.9, 0.1, 0.6)
    pose = se3.make(se3.rpy_to_matrix(*rpy), xyz)
    if source == "graph":
        scene = stage(frame="camera_optical")
        scene.app.transforms.add_static("world", "camera_optical", pose)
    else:
        scene = stage(xyz=xyz, rpy=rpy)
    scene.send(rgbd=frame)
    rgb, depth = scene.frame(camera_view(pose, PRIMESENSE, (640, 480)))
    assert_reproduces(rgb, depth, frame)
    moved, _ = scene.frame(camera_view(np.eye(4), PRIMESENSE, (640, 480)))  # from elsewhere: not the image
    assert np.abs(moved.astype(int) - rgb).mean() > 20


def test_tum_pair_on_separate_ports_with_attribute_intrinsics_and_scale(stage):
    color = needs(TUM / "color.png")
    frame = RGBDFrame.load(color, TUM / "depth.png", depth_scale=5000)
    fx, fy, cx, cy = PRIMESENSE
    scene = stage(ports=("color", "depth"), fx=fx, fy=fy, cx=cx, cy=cy, depth_scale=5000.0)
    scene.send(color=frame.color, depth=frame.depth)
    rgb, depth = scene.frame(camera_view(np.eye(4), PRIMESENSE, (640, 480)))
    assert_reproduces(rgb, depth, frame)


def test_colour_of_another_resolution_is_sampled_by_position(stage):
    """A colour camera of twice the depth resolution (registered): each vertex takes the colour at
    its relative position in the image."""
    cv2 = pytest.importorskip("cv2")
    frame = redwood()
    large = cv2.resize(frame.color.to_rgb(), (1280, 960), interpolation=cv2.INTER_LINEAR)
    scene = stage(ports=("color", "depth"))
    scene.send(color=Image(large, ImageFormat.RGB8), depth=frame.depth)  # the depth carries intrinsics
    rgb, depth = scene.frame(camera_view(np.eye(4), PRIMESENSE, (640, 480)))
    inner = interior(np.isfinite(frame.depth_metres()))
    expected = cv2.resize(large, (640, 480), interpolation=cv2.INTER_LINEAR)
    assert np.median(np.abs(rgb.astype(int) - expected).max(axis=2)[inner]) <= 2
    assert np.isfinite(depth[inner]).all()


def test_depth32f_metres_and_depth16_millimetres_give_the_same_surface(stage):
    frame = redwood()
    metres = RGBDFrame(frame.color, Image(np.nan_to_num(frame.depth_metres(), nan=0.0), ImageFormat.DEPTH32F),
                       frame.intrinsics)
    view = camera_view(np.eye(4), PRIMESENSE, (640, 480))
    scene = stage()
    scene.send(rgbd=frame)
    _, from_millimetres = scene.frame(view)
    scene.send(rgbd=metres)  # a format change restarts the depth texture
    rgb, from_metres = scene.frame(view)
    assert_reproduces(rgb, from_metres, frame)
    np.testing.assert_allclose(from_metres, from_millimetres, atol=1e-3, equal_nan=True)


def test_intrinsics_port_wins_over_the_frame(stage):
    frame = redwood()
    scene = stage(ports=("rgbd", "intrinsics"))
    wide = CameraIntrinsics(640, 480, 262.5, 262.5, 319.5, 239.5)  # half the focal length
    scene.send(rgbd=frame, intrinsics=wide)
    rgb, _ = scene.frame(camera_view(np.eye(4), PRIMESENSE, (640, 480)))
    # Unprojected with half the focal length, the surface is twice as wide: the real camera sees the
    # central half of the image magnified twice about the principal point.
    cv2 = pytest.importorskip("cv2")
    x = (319.5 + (np.arange(640) - 319.5) / 2).astype(np.float32)
    y = (239.5 + (np.arange(480) - 239.5) / 2).astype(np.float32)
    magnified = cv2.remap(frame.color.to_rgb(), *np.meshgrid(x, y), cv2.INTER_LINEAR)
    drawn = interior(rgb.any(axis=2))
    assert drawn.mean() > 0.8
    assert np.median(np.abs(rgb.astype(int) - magnified).max(axis=2)[drawn]) <= 3
    assert np.abs(rgb.astype(int) - frame.color.to_rgb())[drawn].mean() > 20


# --- rubber sheets, holes, stride -----------------------------------------------------------------

STEP_INTRINSICS = (300.0, 300.0, 159.5, 119.5)


def two_planes() -> RGBDFrame:
    """320x240: the left half 1 m away, the right half 2 m, uniform grey."""
    depth = np.full((240, 320), 2000, np.uint16)
    depth[:, :160] = 1000
    intrinsics = CameraIntrinsics(320, 240, *STEP_INTRINSICS)
    return RGBDFrame(Image(np.full((240, 320, 3), 128, np.uint8), ImageFormat.RGB8),
                     Image(depth, ImageFormat.DEPTH16), intrinsics)


@pytest.mark.parametrize("max_edge, filled", [(0.0, True), (0.1, False)])
def test_depth_step_makes_a_rubber_sheet_unless_max_edge_drops_it(stage, max_edge, filled):
    """Seen from 0.3 m to the right, the near plane's edge moves 90 px left, the far plane's 45 px:
    columns ~70..114 show what joins them, a stretched sheet, or the background with ``max_edge``."""
    scene = stage(320, 240, max_edge=max_edge)
    scene.send(rgbd=two_planes())
    rgb, depth = scene.frame(camera_view(se3.make(translation=(0.3, 0.0, 0.0)), STEP_INTRINSICS, (320, 240)))
    gap = (slice(20, 220), slice(75, 110))
    background = np.isnan(depth[gap]).mean()
    assert background == (0.0 if filled else 1.0)
    # the planes themselves are drawn either way
    assert np.isfinite(depth[20:220, 5:65]).all() and np.isfinite(depth[20:220, 120:270]).all()
    np.testing.assert_allclose(depth[20:220, 5:65], 1.0, atol=1e-3)
    np.testing.assert_allclose(depth[20:220, 120:270], 2.0, atol=2e-3)
    assert (rgb[20:220, 120:270] == 128).all()


def test_unknown_depth_leaves_a_hole_without_max_edge(stage):
    frame = two_planes()
    data = frame.depth.data.copy()
    data[100:140, 200:260] = 0
    scene = stage(320, 240)
    scene.send(rgbd=RGBDFrame(frame.color, Image(data, ImageFormat.DEPTH16), frame.intrinsics))
    _, depth = scene.frame(camera_view(np.eye(4), STEP_INTRINSICS, (320, 240)))
    assert np.isnan(depth[100:140, 200:260]).all()
    assert np.isfinite(depth[90:99, 200:260]).all() and np.isfinite(depth[141:150, 200:260]).all()


def test_stride_keeps_the_surface_with_fewer_vertices(stage):
    frame = redwood()
    view = camera_view(np.eye(4), PRIMESENSE, (640, 480))
    scene = stage(max_edge=0.05)
    scene.send(rgbd=frame)
    full_rgb, full_depth = scene.frame(view)
    scene.peer.set_attribute_now("stride", 2)
    assert scene.peer.last_stride == 1, "seen from its own camera the automatic stride keeps every pixel"
    rgb, depth = scene.frame(view)  # no new frame: the grid alone is rebuilt
    assert scene.peer.last_stride == 2 and 0 < scene.peer._grids[2][3] <= grid_indices(320, 240).size
    both = np.isfinite(full_depth) & np.isfinite(depth)
    assert both.mean() > 0.75
    assert np.median(np.abs(depth - full_depth)[both]) < 2e-3
    assert np.abs(rgb.astype(int) - full_rgb)[both].mean() < 3


def plane(distance: float, size: tuple[int, int] = (320, 240)) -> RGBDFrame:
    """A grey plane ``distance`` metres in front of the camera (STEP_INTRINSICS)."""
    width, height = size
    return RGBDFrame(Image(np.full((height, width, 3), 128, np.uint8), ImageFormat.RGB8),
                     Image(np.full((height, width), distance, np.float32), ImageFormat.DEPTH32F),
                     CameraIntrinsics(width, height, *STEP_INTRINSICS))


@pytest.mark.parametrize("spacing, expected", [(1.0, 4), (0.5, 2), (3.0, 12)])
def test_automatic_stride_from_the_size_on_screen(spacing, expected):
    """A plane 2 m away seen by the same camera 8.5 m away: a depth pixel spans 2 / 8.5 screen pixels,
    so about 4.25 of them make ``spacing`` 1 pixel."""
    frame = plane(2.0)
    samples = sample_points(frame.depth, 1.0, STEP_INTRINSICS)
    assert samples.shape[1] == (240 // LOD_SAMPLE) * (320 // LOD_SAMPLE)
    view = camera_view(se3.make(translation=(0.0, 0.0, -6.5)), STEP_INTRINSICS, (320, 240))
    model_view_projection = view.projection @ view.view
    assert automatic_stride(samples, model_view_projection, view.viewport, spacing) == expected
    behind = camera_view(se3.make(translation=(0.0, 0.0, 10.0)), STEP_INTRINSICS, (320, 240))
    assert automatic_stride(samples, behind.projection @ behind.view, behind.viewport, 1.0) == MAX_STRIDE
    assert automatic_stride(samples[:, :0], model_view_projection, view.viewport, 1.0) == MAX_STRIDE


def test_automatic_stride_draws_the_same_surface_from_afar(stage):
    """From 3 m behind the camera the surface covers a fraction of the screen: the automatic stride
    draws far fewer triangles and covers the same pixels with the same colours as every pixel would."""
    frame = redwood()
    view = camera_view(se3.make(translation=(0.3, -0.2, -3.0)), PRIMESENSE, (640, 480))
    scene = stage(max_edge=0.05, stride=1)
    scene.send(rgbd=frame)
    full_rgb, full_depth = scene.frame(view)
    scene.peer.set_attribute_now("stride", 0)
    rgb, depth = scene.frame(view)
    assert scene.peer.last_stride >= 2
    full, drawn = np.isfinite(full_depth), np.isfinite(depth)
    assert (full & drawn).sum() / (full | drawn).sum() > 0.9
    assert np.median(np.abs(rgb.astype(int) - full_rgb).max(axis=2)[full & drawn]) <= 8
    scene.peer.set_attribute_now("vertex_spacing", 2.0)
    scene.frame(view)
    assert scene.peer.last_stride >= 4


def test_kept_triangles_leave_out_unknown_vertices_and_long_edges():
    """A 3 x 3 grid (2 x 2 squares, 8 triangles) 1 m away, one depth pixel 1 m apart, one unknown."""
    z = np.ones((3, 3), np.float32)
    z[0, 2] = 2.0  # top right: the edges to it are ~1 m long
    z[2, 0] = np.nan  # bottom left: unknown
    all_of = grid_indices(3, 3).reshape(-1, 3).tolist()
    kept = kept_triangles(z, 1, (100.0, 100.0, 1.0, 1.0), 0.5).reshape(-1, 3).tolist()
    # Two triangles per square, squares row by row: the top right square's touch the far pixel, the
    # bottom left square's the unknown one.
    assert kept == [all_of[i] for i in (0, 1, 6, 7)]
    without_limit = kept_triangles(z, 1, (100.0, 100.0, 1.0, 1.0), 0.0).reshape(-1, 3).tolist()
    assert without_limit == [all_of[i] for i in (0, 1, 2, 3, 6, 7)], "no limit: only the unknown vertex drops"
    assert kept_triangles(z[:1], 1, (100.0, 100.0, 1.0, 1.0), 0.5).size == 0


def test_grid_triangles_are_counter_clockwise_from_the_camera():
    indices = grid_indices(3, 2).reshape(-1, 3)
    assert indices.tolist() == [[0, 3, 1], [1, 3, 4], [1, 4, 2], [2, 4, 5]]
    pixels = np.array([[i % 3, i // 3] for i in range(6)], float)
    window = pixels * [1, -1]  # GL's window y grows upwards
    a, b, c = (window[indices[:, k]] for k in range(3))
    cross = (b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]
    assert (cross > 0).all()


# --- temporal averaging ---------------------------------------------------------------------------

def noisy_planes(count: int, sigma: float, dropout: float, unknown: float = 0.0) -> list[RGBDFrame]:
    """``count`` frames of a plane 1.5 m away with Gaussian depth noise and random ``unknown`` pixels."""
    rng = np.random.default_rng(3)
    intrinsics = CameraIntrinsics(160, 120, 150.0, 150.0, 79.5, 59.5)
    color = Image(np.full((120, 160, 3), 200, np.uint8), ImageFormat.RGB8)
    frames = []
    for _ in range(count):
        metres = (1.5 + rng.normal(0.0, sigma, (120, 160))).astype(np.float32)
        metres[rng.random((120, 160)) < dropout] = unknown
        frames.append(RGBDFrame(color, Image(metres, ImageFormat.DEPTH32F), intrinsics))
    return frames


@pytest.mark.parametrize("average", [1, 8])
def test_averaging_over_n_frames_divides_the_depth_variance_by_n(stage, average):
    sigma = 0.02
    scene = stage(160, 120, average=average)
    view = camera_view(np.eye(4), (150.0, 150.0, 79.5, 59.5), (160, 120))
    for frame in noisy_planes(8, sigma, dropout=0.0):
        scene.send(rgbd=frame)
        _, depth = scene.frame(view)
    inner = depth[2:-2, 2:-2]
    assert np.isfinite(inner).all()
    variance = inner.var()
    assert variance == pytest.approx(sigma ** 2 / average, rel=0.2)
    assert inner.mean() == pytest.approx(1.5, abs=2e-3)


@pytest.mark.parametrize("unknown", [0.0, np.nan], ids=["zero", "nan"])
def test_averaging_ignores_unknown_depth(stage, unknown):
    """With 30% of the pixels unknown in each frame, the average of 8 frames has (almost) no holes and
    no bias towards zero; a single frame has holes."""
    scene = stage(160, 120, average=8)
    view = camera_view(np.eye(4), (150.0, 150.0, 79.5, 59.5), (160, 120))
    frames = noisy_planes(8, 0.005, dropout=0.3, unknown=unknown)
    scene.send(rgbd=frames[0])
    _, single = scene.frame(view)
    for frame in frames[1:]:
        scene.send(rgbd=frame)
        _, averaged = scene.frame(view)
    assert np.isnan(single[2:-2, 2:-2]).mean() > 0.5
    inner = averaged[2:-2, 2:-2]
    assert np.isfinite(inner).mean() > 0.999
    assert np.nanmean(inner) == pytest.approx(1.5, abs=1e-3)


def test_frames_of_a_new_size_are_not_averaged_with_old_ones(stage):
    scene = stage(160, 120, average=4)
    view = camera_view(np.eye(4), (150.0, 150.0, 79.5, 59.5), (160, 120))
    scene.send(rgbd=noisy_planes(1, 0.0, 0.0)[0])
    scene.frame(view)
    near = RGBDFrame(Image(np.full((60, 80, 3), 90, np.uint8), ImageFormat.RGB8),
                     Image(np.full((60, 80), 0.75, np.float32), ImageFormat.DEPTH32F),
                     CameraIntrinsics(80, 60, 75.0, 75.0, 39.5, 29.5))
    scene.send(rgbd=near)
    _, depth = scene.frame(view)
    np.testing.assert_allclose(depth[5:-5, 5:-5], 0.75, atol=1e-4)


# --- errors ---------------------------------------------------------------------------------------

def test_missing_intrinsics_are_reported_by_the_component(stage, caplog):
    frame = redwood()
    scene = stage(ports=("color", "depth"))
    scene.send(color=frame.color, depth=Image(frame.depth.data, ImageFormat.DEPTH16))  # no intrinsics
    with caplog.at_level(logging.ERROR, logger="coco"):
        rgb, _ = scene.frame(camera_view(np.eye(4), PRIMESENSE, (640, 480)))
    assert scene.peer.stats.errors == 1
    assert "surface: no intrinsics: connect the intrinsics port" in caplog.text and "fx, fy, cx, cy" in caplog.text
    assert rgb.max() == 0


def test_colour_on_the_depth_port_is_refused(stage, caplog):
    frame = redwood()
    scene = stage(ports=("depth",), fx=525.0, fy=525.0)
    scene.send(depth=frame.color)
    with caplog.at_level(logging.ERROR, logger="coco"):
        scene.frame(camera_view(np.eye(4), PRIMESENSE, (640, 480)))
    assert "surface.depth takes DEPTH16 or DEPTH32F images, got BGR8" in caplog.text


@pytest.mark.parametrize("attributes, message", [
    ({"average": 0}, "expected >= 1"), ({"xyz": (1.0, 2.0)}, "expected 3 numbers, got 2"),
    ({"max_edge": -0.1}, "expected >= 0"),
])
def test_bad_attributes_are_refused(attributes, message):
    with pytest.raises(AttributeValueError, match=message):
        GLRGBDImage("surface", **attributes)


# --- in a GLManager -------------------------------------------------------------------------------

def test_glmanager_draws_the_surface_over_a_glimage_background():
    """A video see-through frame end to end: GLImage background, then the RGB-D surface, seen by a
    GLCameraManager that follows the depth camera's frame with the same field of view (the Redwood
    principal point is the image centre, so a symmetric frustum is the pinhole camera)."""
    frame = redwood()
    app = Application("test_rgbd_manager")
    app.transforms.add_static("world", "camera_optical", se3.make(se3.rpy_to_matrix(0.3, -0.2, 1.0), (1.0, 2.0, 0.5)))
    manager = GLManager("display", width=640, height=480)
    manager.add_peer(GLCameraManager("camera", follow_frame="camera_optical", frame_convention="optical",
                                     fov_y=float(np.degrees(2 * np.arctan(240 / 525))), near=0.1, far=20.0))
    manager.add_peer(GLImage("background"))
    manager.add_peer(GLRGBDImage("surface", frame="camera_optical"))
    sensor, screen, backdrop = Sensor("sensor"), Frames("screen"), Sensor("backdrop")
    for component in (manager, sensor, screen, backdrop):
        app.add(component)
    app.connect(sensor.rgbd, "surface.rgbd")
    app.connect(backdrop.color, "background.image")
    app.connect(manager.color, screen.image)
    blue = np.zeros((48, 64, 3), np.uint8)
    blue[..., 2] = 255
    backdrop.color.write(Image(blue, ImageFormat.RGB8))
    sensor.rgbd.write(frame)
    shown = render_once(manager, screen.image)
    rgb = shown.data.astype(int)
    metres = frame.depth_metres()
    inner = interior(np.isfinite(metres))
    assert np.mean(np.abs(rgb - frame.color.to_rgb()).max(axis=2)[inner] <= 2) > 0.99
    empty = interior(np.isnan(metres))  # no surface: the background shows through
    assert empty.sum() > 1000 and (rgb[empty] == (0, 0, 255)).all()
