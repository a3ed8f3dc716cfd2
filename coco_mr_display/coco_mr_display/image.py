"""GLImage: a camera image as the background of the view, scaled to the viewport.

The first peer of a video see-through display: the camera frame fills the view and the virtual
objects drawn after it land on top. It is drawn with the depth test off, so it writes no depth and
never occludes them (GLManager resets the GL state before each peer, so this does not leak).

Uploads happen only when a new image arrived, at the first ``render`` after it (once per frame, also
in stereo), as one texture write of the image's buffer (see :mod:`.image_texture`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import moderngl

from coco_core.attributes import Attribute
from coco_core.policy import NEW_DATA
from coco_core.ports import InputPort
from coco_core.stamps import Stamped, unstamped
from coco_mr_vision.image import Image

from .image_texture import ImageTexture
from .peer import GLPeer
from .shown import ShownInputs

if TYPE_CHECKING:
    from .view import RenderView

FITS = ("contain", "cover", "stretch")

_VERTEX = """
#version 330
uniform vec2 scale;  // half extent of the image quad in NDC (1 = the viewport's edge)
out vec2 uv;
void main() {
    vec2 corner = vec2(gl_VertexID & 1, gl_VertexID >> 1);  // (0,0) (1,0) (0,1) (1,1): a strip
    uv = vec2(corner.x, 1.0 - corner.y);  // texture row 0 is the image's top row: top of the quad
    gl_Position = vec4((corner * 2.0 - 1.0) * scale, 0.0, 1.0);
}
"""

_FRAGMENT = """
#version 330
uniform sampler2D image;
in vec2 uv;
out vec4 color;
void main() {
    color = vec4(texture(image, uv).rgb, 1.0);
}
"""


def fit_scale(image_size: tuple[int, int], viewport_size: tuple[int, int], fit: str) -> tuple[float, float]:
    """Half extent in NDC of a quad showing ``image_size`` in ``viewport_size`` without distortion.

    ``contain`` shows the whole image (bars on two sides), ``cover`` fills the viewport (the image
    overflows, and is cut, on two sides), ``stretch`` fills it by distorting the image.
    """
    if fit == "stretch":
        return 1.0, 1.0
    ratio = (image_size[0] / image_size[1]) / (viewport_size[0] / viewport_size[1])
    wider = ratio > 1.0
    if (fit == "contain") == wider:
        return 1.0, 1.0 / ratio
    return ratio, 1.0


class GLImage(GLPeer):
    """Draws the latest image of its ``image`` input over the whole viewport, behind everything."""

    image = InputPort(Image | Stamped, doc="camera images, any coco_mr_vision format (depth shows as grey), "
                      "optionally Stamped (a stamped BagReplay's or ROSInterface's)")
    fit = Attribute(str, "contain", "how the image meets the viewport: contain | cover | stretch",
                    choices=FITS)

    def __init__(self, name: str | None = None, **attributes: object) -> None:
        super().__init__(name, **attributes)
        self._pending: Image | None = None
        self.shown = ShownInputs()
        """The origin of the image the next frame shows first (its GLManager stamps the frame with it)."""
        self._texture: ImageTexture | None = None
        self._program: moderngl.Program | None = None
        self._quad: moderngl.VertexArray | None = None

    def on_update(self) -> None:
        status, value = self.image.read_newest()  # the newest image is drawn; skipped ones count as dropped
        if status is NEW_DATA:
            image, stamp = unstamped(value)[0], self.image.origin
            self._pending = image
            self.shown.add(stamp)
            if stamp is not None:
                self.record_latency(stamp)  # drawn this frame

    def gl_init(self, ctx: moderngl.Context) -> None:
        self._program = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        self._program["image"] = 0
        self._quad = ctx.vertex_array(self._program, [])
        self._texture = ImageTexture(ctx)

    def render(self, ctx: moderngl.Context, view: RenderView) -> None:
        assert self._texture is not None and self._program is not None and self._quad is not None, \
            "GLImage.render() before gl_init()"
        if self._pending is not None:
            self._texture.write(self._pending)
            self._pending = None
        if self._texture.size is None:
            return
        self._program["scale"] = fit_scale(self._texture.size, view.viewport[2:], self.fit)
        ctx.disable(moderngl.DEPTH_TEST)
        self._texture.use(0)
        self._quad.render(moderngl.TRIANGLE_STRIP, vertices=4)

    def gl_release(self) -> None:
        for resource in (self._quad, self._program):
            if resource is not None:
                resource.release()
        if self._texture is not None:
            self._texture.release()
        self._quad = self._program = self._texture = None

