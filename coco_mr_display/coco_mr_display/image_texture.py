"""An OpenGL texture that shows a stream of :class:`~coco_mr_vision.image.Image` frames as RGB.

GLImage (the background) and GLRGBDImage (the colour of the RGB-D mesh) both need it. A new frame
costs one ``texture.write`` of the image's own buffer: byte orders the GPU can fix for free (BGR,
BGRA, grey replicated to RGB) are fixed by the texture's swizzle, 16-bit grey goes up as a normalised
16-bit texture; only the layouts a texture cannot sample directly (packed and planar YUV, depth)
go through :meth:`Image.to_rgb`, the conversion coco_mr_vision already has. The texture is created
again only when the size or the texel layout changes.

Rows: images are stored top row first and ``texture.write`` puts the first row at ``t = 0``, so a
sampler reads image row ``r`` of ``H`` at ``t = (r + 0.5) / H``; whoever maps the texture onto the
screen flips ``t`` (GL's window ``y`` grows upwards).
"""

from __future__ import annotations

from typing import NamedTuple

import moderngl
import numpy as np

from coco_mr_vision.image import Image, ImageFormat


class _Layout(NamedTuple):
    """How the bytes of one image format go into a texture."""

    components: int
    dtype: str
    swizzle: str


_DIRECT: dict[ImageFormat, _Layout] = {
    ImageFormat.RGB8: _Layout(3, "f1", "RGB1"),
    ImageFormat.BGR8: _Layout(3, "f1", "BGR1"),
    ImageFormat.RGBA8: _Layout(4, "f1", "RGB1"),
    ImageFormat.BGRA8: _Layout(4, "f1", "BGR1"),
    ImageFormat.GRAY8: _Layout(1, "f1", "RRR1"),
    ImageFormat.GRAY16: _Layout(1, "nu2", "RRR1"),
}
"""Formats uploaded as they are. Alpha is ignored (``1`` in the swizzle): a camera image is opaque."""

_CONVERTED = _Layout(3, "f1", "RGB1")
"""YUYV, I420 and depth: uploaded as the RGB of :meth:`Image.to_rgb`."""


class ImageTexture:
    """A texture holding the latest image written to it, in RGB whatever the image's format."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.texture: moderngl.Texture | None = None
        self._key: tuple[tuple[int, int], _Layout] | None = None

    @property
    def size(self) -> tuple[int, int] | None:
        """``(width, height)`` of the image last written, None before the first."""
        return None if self.texture is None else self.texture.size

    def write(self, image: Image) -> None:
        """Upload ``image`` (any :class:`ImageFormat`); reallocate only if its size or layout changed."""
        layout = _DIRECT.get(image.format)
        data = image.data if layout is not None else image.to_rgb()
        layout = layout or _CONVERTED
        key = (image.size, layout)
        if key != self._key:
            self.release()
            texture = self.ctx.texture(image.size, layout.components, dtype=layout.dtype, alignment=1)
            texture.swizzle = layout.swizzle
            texture.filter = (moderngl.LINEAR, moderngl.LINEAR)  # scaled to the viewport: bilinear
            texture.repeat_x = texture.repeat_y = False
            self.texture, self._key = texture, key
        assert self.texture is not None
        self.texture.write(np.ascontiguousarray(data), alignment=1)

    def use(self, location: int) -> None:
        """Bind to texture unit ``location`` (the caller checked that an image was written)."""
        assert self.texture is not None, "ImageTexture.use() before the first write()"
        self.texture.use(location)

    def release(self) -> None:
        if self.texture is not None:
            self.texture.release()
        self.texture, self._key = None, None
