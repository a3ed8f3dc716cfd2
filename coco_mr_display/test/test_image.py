"""GLImage: a camera image as the background, rendered headless for real and checked pixel by pixel.

The expected pictures are computed independently of OpenGL: an image shown 1:1 must come back
unchanged, a scaled one must equal OpenCV's bilinear resampling of the same pixel mapping, and every
image format must show the RGB that coco_mr_vision's own ``Image.to_rgb`` gives.
"""

from __future__ import annotations

from pathlib import Path

import moderngl
import numpy as np
import pytest

from conftest import Frames, render_once
from coco_core.application import Application
from coco_core.attributes import AttributeValueError
from coco_core.component import Component
from coco_core.ports import OutputPort
from coco_mr_display.image import GLImage, fit_scale
from coco_mr_display.image_texture import ImageTexture
from coco_mr_display.manager import GLManager
from coco_mr_display.view import RenderView
from coco_mr_vision.image import Image, ImageFormat

cv2 = pytest.importorskip("cv2")

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
REDWOOD_COLOR = DATA / "rgbd" / "redwood" / "color" / "00000.jpg"


def redwood_rgb() -> np.ndarray:
    if not REDWOOD_COLOR.exists():
        pytest.skip(f"{REDWOOD_COLOR} is absent (the shared data sets are not beside this checkout)")
    return cv2.cvtColor(cv2.imread(str(REDWOOD_COLOR), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


class Camera(Component):
    images = OutputPort(Image)


class Stage:
    """One GLImage fed by a camera component, drawn into a framebuffer of its own."""

    def __init__(self, ctx: moderngl.Context, fbo: moderngl.Framebuffer, fit: str = "contain") -> None:
        self.ctx, self.fbo = ctx, fbo
        self.app = Application("test_image")
        self.camera = self.app.add(Camera("camera"))
        self.peer = self.app.add(GLImage("background", fit=fit))
        self.app.connect(self.camera.images, self.peer.image)
        self.peer.gl_init(ctx)

    def frame(self, image: Image | None = None, viewport: tuple[int, int, int, int] | None = None) -> np.ndarray:
        """Send ``image`` (if any), run one frame and return the framebuffer's RGB, top row first."""
        if image is not None:
            self.camera.images.write(image)
        self.peer.step()
        self.fbo.use()
        self.fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
        viewport = viewport or (0, 0, *self.fbo.size)
        self.ctx.viewport = viewport
        self.peer.render(self.ctx, RenderView(np.eye(4), np.eye(4), viewport))
        width, height = self.fbo.size
        return np.frombuffer(self.fbo.read(components=3, alignment=1), np.uint8).reshape(height, width, 3)[::-1]


@pytest.fixture
def stage(gl_context, framebuffer):
    def make(width: int, height: int, fit: str = "contain") -> Stage:
        return Stage(gl_context, framebuffer(width, height), fit)

    return make


def resampled(rgb: np.ndarray, size: tuple[int, int], scale: tuple[float, float]) -> np.ndarray:
    """What a quad of half extent ``scale`` (NDC) showing ``rgb`` looks like in a ``size`` framebuffer,
    by OpenCV's bilinear remap of the same pixel mapping (border: black)."""
    width, height = size
    image_h, image_w = rgb.shape[:2]
    shown_w, shown_h = scale[0] * width, scale[1] * height
    x = (np.arange(width) + 0.5 - (width - shown_w) / 2) / shown_w * image_w - 0.5
    y = (np.arange(height) + 0.5 - (height - shown_h) / 2) / shown_h * image_h - 0.5
    map_x, map_y = np.meshgrid(x.astype(np.float32), y.astype(np.float32))
    return cv2.remap(rgb, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


# --- orientation and fit --------------------------------------------------------------------------

def test_top_row_of_the_image_is_the_top_of_the_view(stage):
    quadrants = np.zeros((48, 64, 3), np.uint8)
    quadrants[:24, :32] = (255, 0, 0)     # top left: red
    quadrants[:24, 32:] = (0, 255, 0)     # top right: green
    quadrants[24:, :32] = (0, 0, 255)     # bottom left: blue
    quadrants[24:, 32:] = (255, 255, 255)  # bottom right: white
    shown = stage(640, 480).frame(Image(quadrants, ImageFormat.RGB8))
    assert tuple(shown[60, 80]) == (255, 0, 0)
    assert tuple(shown[60, 560]) == (0, 255, 0)
    assert tuple(shown[420, 80]) == (0, 0, 255)
    assert tuple(shown[420, 560]) == (255, 255, 255)


def test_real_image_at_its_own_size_comes_back_unchanged(stage):
    rgb = redwood_rgb()
    shown = stage(640, 480).frame(Image(rgb, ImageFormat.RGB8))
    assert np.abs(shown.astype(int) - rgb).max() <= 1


@pytest.mark.parametrize("fit, scale", [("contain", (2 / 3, 1.0)), ("cover", (1.0, 1.5)), ("stretch", (1.0, 1.0))])
def test_fit_scales_a_4_3_image_into_a_2_1_viewport(stage, fit, scale):
    assert fit_scale((640, 480), (800, 400), fit) == pytest.approx(scale)
    rgb = redwood_rgb()
    shown = stage(800, 400, fit).frame(Image(rgb, ImageFormat.RGB8))
    expected = resampled(rgb, (800, 400), scale)
    if fit == "contain":  # bars left and right, the image between (133.3 .. 666.7 px)
        assert shown[:, :132].max() == 0 and shown[:, 669:].max() == 0
        shown, expected = shown[:, 136:664], expected[:, 136:664]
    difference = np.abs(shown.astype(int) - expected)
    assert difference.mean() < 0.5 and np.percentile(difference, 99.9) <= 3


def test_fit_in_a_tall_viewport_puts_the_bars_above_and_below(stage):
    assert fit_scale((640, 480), (300, 600), "contain") == pytest.approx((1.0, 0.375))
    assert fit_scale((640, 480), (300, 600), "cover") == pytest.approx((8 / 3, 1.0))
    shown = stage(300, 600).frame(Image(redwood_rgb(), ImageFormat.RGB8))
    assert shown[:185].max() == 0 and shown[415:].max() == 0 and shown[200:400].any(axis=2).mean() > 0.99


def test_image_fits_the_viewport_it_is_given(stage):
    """Stereo halves and other viewports: the image is scaled to the viewport, not the framebuffer."""
    rgb = redwood_rgb()
    shown = stage(1280, 480).frame(Image(rgb, ImageFormat.RGB8), viewport=(640, 0, 640, 480))
    assert shown[:, :640].max() == 0
    assert np.abs(shown[:, 640:].astype(int) - rgb).max() <= 1


def test_unknown_fit_is_refused_with_the_valid_ones():
    with pytest.raises(AttributeValueError, match="contain, cover, stretch"):
        GLImage("background", fit="zoom")


# --- formats --------------------------------------------------------------------------------------

def as_format(rgb: np.ndarray, image_format: ImageFormat) -> Image:
    """The same picture in ``image_format``, converted by OpenCV (grey keeps only luminance)."""
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    data = {
        ImageFormat.RGB8: rgb,
        ImageFormat.BGR8: np.ascontiguousarray(rgb[..., ::-1]),
        ImageFormat.RGBA8: cv2.cvtColor(rgb, cv2.COLOR_RGB2RGBA),
        ImageFormat.BGRA8: cv2.cvtColor(rgb, cv2.COLOR_RGB2BGRA),
        ImageFormat.GRAY8: grey,
        ImageFormat.GRAY16: grey.astype(np.uint16) * 257,
        ImageFormat.YUYV: cv2.cvtColor(rgb, cv2.COLOR_RGB2YUV_YUYV).reshape(rgb.shape[0], rgb.shape[1], 2),
        ImageFormat.I420: cv2.cvtColor(rgb, cv2.COLOR_RGB2YUV_I420),
        ImageFormat.DEPTH16: grey.astype(np.uint16) * 10,
    }[image_format]
    return Image(data, image_format)


@pytest.mark.parametrize("image_format", [f for f in ImageFormat if f is not ImageFormat.DEPTH32F],
                         ids=lambda f: f.name)
def test_every_format_shows_the_rgb_of_its_conversion(stage, image_format):
    rgb = redwood_rgb()
    image = as_format(rgb, image_format)
    shown = stage(640, 480).frame(image)
    assert np.abs(shown.astype(int) - image.to_rgb()).max() <= 1
    if image_format in (ImageFormat.RGB8, ImageFormat.BGR8, ImageFormat.RGBA8, ImageFormat.BGRA8):
        assert np.abs(shown.astype(int) - rgb).max() <= 1
    elif image_format in (ImageFormat.YUYV, ImageFormat.I420):  # chroma is subsampled: close, not equal
        assert np.abs(shown.astype(int) - rgb).mean() < 4


def test_depth32f_shows_as_grey(stage):
    metres = np.tile(np.linspace(0.0, 4.0, 64, dtype=np.float32), (48, 1))
    metres[:, :8] = np.nan
    image = Image(metres, ImageFormat.DEPTH32F)
    shown = stage(64, 48).frame(image)
    assert np.abs(shown.astype(int) - image.to_rgb()).max() <= 1
    assert shown[:, :8].max() == 0 and shown[10, 63, 0] == 255


def test_read_only_and_strided_images_are_uploaded(stage):
    """Images from ROS messages are read-only views; a crop is not contiguous."""
    rgb = redwood_rgb()
    crop = rgb[100:340, 200:520]
    crop.flags.writeable = False
    shown = stage(320, 240).frame(Image(crop, ImageFormat.RGB8))
    assert np.abs(shown.astype(int) - crop).max() <= 1


# --- uploads --------------------------------------------------------------------------------------

def test_upload_only_when_a_new_image_arrived(stage, monkeypatch):
    uploads: list[ImageFormat] = []
    real_write = ImageTexture.write
    monkeypatch.setattr(ImageTexture, "write", lambda self, image: (uploads.append(image.format),
                                                                    real_write(self, image)))
    rgb = redwood_rgb()
    scene = stage(640, 480)
    first = scene.frame(Image(rgb, ImageFormat.RGB8))
    texture = scene.peer._texture.texture
    again = [scene.frame() for _ in range(3)]
    assert uploads == [ImageFormat.RGB8]
    assert all(np.array_equal(frame, first) for frame in again)  # the last image stays on screen
    inverted = scene.frame(Image(255 - rgb, ImageFormat.RGB8))
    assert len(uploads) == 2 and scene.peer._texture.texture is texture  # same size: texture reused
    assert np.abs(inverted.astype(int) - (255 - rgb)).max() <= 1
    scene.frame(Image(rgb[:240, :320].copy(), ImageFormat.RGB8))
    assert scene.peer._texture.texture is not texture  # new size: new texture


def test_nothing_is_drawn_before_the_first_image(stage):
    assert stage(64, 48).frame().max() == 0


# --- in a GLManager -------------------------------------------------------------------------------

def test_background_of_a_headless_glmanager_in_2d():
    """The manager's 2D mode, its state reset between peers and its colour output, end to end."""
    rgb = redwood_rgb()
    app = Application("test_image_manager")
    manager = GLManager("display", width=320, height=240, visualization="2d")
    manager.add_peer(GLImage("background"))
    camera, recorder = Camera("camera"), Frames("recorder")
    for component in (manager, camera, recorder):
        app.add(component)
    app.connect(camera.images, "background.image")
    app.connect(manager.color, recorder.image)
    camera.images.write(Image(rgb, ImageFormat.RGB8))
    frame = render_once(manager, recorder.image)
    assert frame.format is ImageFormat.RGB8 and frame.size == (320, 240)
    difference = np.abs(frame.data.astype(int) - cv2.resize(rgb, (320, 240), interpolation=cv2.INTER_LINEAR))
    assert difference.mean() < 1.0
