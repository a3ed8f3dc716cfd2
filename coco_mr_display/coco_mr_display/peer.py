"""The drawing peer: what GLManager calls on each of its peers, and when.

A drawing peer is an ordinary component nested in a GLManager (``<components>`` inside the manager's
component in the XML). GLManager sets ``manages_peers``, so it runs its peers itself, in the order the
file lists them (that is the drawing order: background images first, then opaque geometry):

1. ``on_config()`` of every peer (component life cycle), then, with the manager's OpenGL context
   current in the manager's activity thread, ``gl_init(ctx)`` once per peer: create buffers, textures
   and programs here, never at import or in ``init()`` (no context exists there).
2. Every frame: ``step()`` of every peer (its ``on_update``, profiled: read ports, update CPU-side
   state), then for each :class:`~coco_mr_display.view.RenderView` of the frame (one, or two in
   stereo) ``render(ctx, view)`` of every peer in order, into the framebuffer the manager bound.
3. At stop: ``gl_release()`` of every peer with the context current, then ``on_stop()``.

Keep heavy CPU work (mesh loading, decoding) out of ``render``: it is the frame rate's critical path.
Non-drawing peers (the camera, controllers, UpdateColor) are plain components; GLManager skips
``gl_init``/``render`` for peers that are not :class:`GLPeer`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from coco_core.component import Component

if TYPE_CHECKING:
    import moderngl

    from .view import RenderView


class GLPeer(Component):
    """Base class of the components GLManager draws."""

    def gl_init(self, ctx: moderngl.Context) -> None:
        """Create GPU resources; called once, in the render thread, with ``ctx`` current."""

    def render(self, ctx: moderngl.Context, view: RenderView) -> None:
        """Draw into the bound framebuffer for one view; called once per view per frame."""
        raise NotImplementedError(f"{type(self).__name__} must implement render()")

    def gl_release(self) -> None:
        """Release GPU resources; called once at stop with the context current."""
