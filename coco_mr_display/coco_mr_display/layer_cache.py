"""LayerCache: what a peer drew in a view, kept as colour and depth, and put back into later frames.

On a software renderer a frame costs its triangles (docs/display.md), and most of them belong to
the large, slowly changing things: an RGB-D surface changes when a camera frame arrives (30 Hz at
most), while the hand, the proxy and the force arrow over it move with every pose (100 Hz and more).
A display that draws whenever something new arrives would redraw the whole surface for every pose.

A peer that knows when its drawing changes paints it once into the cache's own framebuffer (a colour
and a depth texture the size of the view) and, in every frame, *composites* it: one full-screen
triangle whose fragments copy the cached colour and write the cached depth (``gl_FragDepth``),
depth-tested like any drawing, and discarded where the peer drew nothing. The frame's pixels and
depths are those of drawing the peer directly (8-bit colour and 24-bit depth round-trip exactly),
so the peers drawn after it are hidden behind it as before; the composite costs a few texel fetches
per pixel instead of the peer's triangles. When the peer is the first to draw in a view that fills
the framebuffer (the usual background surface), its layer is kept over the frame's background and
simply copied in, colour and depth (a blit): on llvmpipe a full-screen fragment pass costs 16-20 ms
at 640x480 under load, the copy half a millisecond. Views are cached apart (a stereo frame has two).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Callable, Hashable

import moderngl

if TYPE_CHECKING:
    from .view import RenderView

_NOTHING = object()
"""The key of a layer holding no drawing: equal to no peer's key."""

_VERTEX = """
#version 330
void main() {  // one triangle covering the viewport: (-1,-1), (3,-1), (-1,3)
    vec2 corner = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    gl_Position = vec4(corner, 0.0, 1.0);
}
"""

_FRAGMENT = """
#version 330
uniform sampler2D colors;
uniform sampler2D depths;
uniform ivec2 origin;  // the view's lower-left corner in the frame
out vec4 color;
void main() {
    ivec2 texel = ivec2(gl_FragCoord.xy) - origin;
    float depth = texelFetch(depths, texel, 0).r;
    if (depth >= 1.0) {  // the peer drew nothing here
        discard;
    }
    color = texelFetch(colors, texel, 0);
    gl_FragDepth = depth;
}
"""


class _Layer:
    """The cached colour and depth of one view, with the key of what they show."""

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int]) -> None:
        self.colors = ctx.texture(size, 4)
        self.depths = ctx.depth_texture(size)
        for texture in (self.colors, self.depths):
            texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.depths.compare_func = ""  # sampled as values, not as a shadow comparison
        self.fbo = ctx.framebuffer([self.colors], self.depths)
        self.key: Hashable = _NOTHING
        self.pending: Hashable = _NOTHING
        """The key of the last drawing made straight into a frame (composited layers only)."""

    def release(self) -> None:
        self.fbo.release()
        self.colors.release()
        self.depths.release()


class LayerCache:
    """One peer's drawing per view, repainted only when its key changes (see the module docstring)."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self._program = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        self._program["colors"] = 0
        self._program["depths"] = 1
        self._quad = ctx.vertex_array(self._program, [])
        self._layers: dict[tuple[int, int, int, int], _Layer] = {}
        self.repaints = 0
        """How many times a layer was painted (tools, tests and benchmarks: the cache's hit rate)."""

    def draw(self, ctx: moderngl.Context, view: RenderView, key: Hashable, paint: Callable[[], None]) -> None:
        """Put the peer's drawing of ``view`` into the current framebuffer; first call ``paint`` (it
        draws the peer in the current viewport) when ``key``, everything that the drawing depends on,
        differs from the key of the drawing kept for this view.

        When nothing was drawn in the view yet (``view.background`` is set) and the view is the whole
        framebuffer, the layer is kept over that background and copied in (a blit, ~0.5 ms at 640x480
        on llvmpipe); otherwise it is composited by the full-screen pass (~16-20 ms there: llvmpipe
        runs a fragment shader for every pixel)."""
        x, y, width, height = view.viewport
        target = ctx.fbo
        whole = view.background is not None and view.viewport == (0, 0, *target.size)
        layer = self._layers.get(view.viewport)
        if layer is None:
            layer = self._layers[view.viewport] = _Layer(ctx, (width, height))
        kept = (key, view.background if whole else None)
        if layer.key != kept and not whole and layer.pending != kept:
            # Changed since the last frame: drawn straight into the frame, as without a cache (content
            # that changes every frame pays nothing); kept from the second frame it stays the same.
            layer.pending = kept
            paint()
            self.repaints += 1
            return
        if layer.key != kept:
            layer.fbo.use()
            layer.fbo.clear(*(view.background if view.background is not None and whole else (0.0, 0.0, 0.0, 0.0)),
                            depth=1.0)
            ctx.viewport = (0, 0, width, height)
            paint()
            layer.key = kept
            self.repaints += 1
            target.use()
            ctx.viewport = view.viewport
        if whole:
            ctx.copy_framebuffer(target, layer.fbo)  # colour and depth
            return
        self._program["origin"] = (x, y)
        layer.colors.use(0)
        layer.depths.use(1)
        self._quad.render(moderngl.TRIANGLES, vertices=3)

    def release(self) -> None:
        for layer in self._layers.values():
            layer.release()
        self._layers = {}
        self._quad.release()
        self._program.release()
