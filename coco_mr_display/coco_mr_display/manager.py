"""GLManager: one OpenGL output (a window or an offscreen framebuffer) rendering its peers each frame.

The paper's display module puts performance before visual effects: one context per manager, owned
by the manager's activity thread (its period is the frame rate; in a triggered activity, woken by
its peers' event inputs, a frame starts when an input arrives, at most every ``min_period`` of the
activity's schedule), peers drawn in file order, and the frame read back once into a fresh array
that goes out on the ``color`` port as an image (so it can be streamed, recorded or fed to vision
code without further copies). Several managers run at once, each
on its own activity.

Each update is one frame: window events go to the controller peers, every peer steps (reads its
ports), the camera peer provides the views (one, or a left and a right half in stereo; in 2D the
manager's own pixel-space view), the framebuffer is cleared and every drawing peer renders each view,
then the outputs are read back and, in a window, the frame is shown.

Sensor-to-display latency (:mod:`.shown`): once a frame is drawn, the manager takes from every peer
the origins of the inputs it shows for the first time (a ``Stamped`` input's own stamp, a plain
input's message stamp: its write) and stamps the frame with the oldest (seq: the
frame's number); a frame that shows nothing new is stamped at its own render time with the manager's
name as source. When the frame is read back (the pixels exist), the manager records the frame's
latency (``record_latency``: the ``display`` row of ``--profile``) and writes it on ``latency``
(``Stamped[float]`` seconds, with the frame's stamp; only for frames that showed a new input). With
``stamped``, ``color`` and ``depth`` carry ``Stamped(Image, frame stamp)``. The frame's stamp keeps
the input's ``steps`` (its way to the display) and adds the frame's own: ``frame_start`` (the
update began: the peers then read their inputs), ``drawn`` (every peer drew and the context finished
the drawing) and ``read_back`` (the pixels copied out), so that the latency splits by step.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace
from functools import partial

import moderngl
import numpy as np

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import SetupError
from coco_core.ports import OutputPort
from coco_core.stamps import Stamp, Stamped
from coco_mr_vision.image import Image, ImageFormat

from . import projection as proj
from .context import HeadlessSurface, Surface, WindowSurface
from .events import EventKind, dispatch
from .peer import GLPeer
from .shown import ShownInputs
from .view import Eye, RenderView

log = logging.getLogger("coco.display")


def _colour(value: list[float]) -> str | None:
    return None if len(value) in (3, 4) else f"expected 3 or 4 numbers (r g b [a], 0..1), got {len(value)}"


def pixel_view(width: int, height: int, frame: str) -> RenderView:
    """The 2D view: world units are pixels, origin at the top-left corner, y down like an image."""
    return RenderView(np.eye(4), proj.orthographic(0.0, width, height, 0.0, -1.0, 1.0), (0, 0, width, height),
                      Eye.MONO, frame)


class GLManager(Component):
    """An OpenGL 3.3 core output rendering its peers; the rendered frame goes out as an image."""

    manages_peers = True
    thread_bound = True  # its OpenGL context is current in the activity thread that created it

    width = Attribute(int, 640, "framebuffer (window) width in pixels", min=1)
    height = Attribute(int, 480, "framebuffer (window) height in pixels", min=1)
    mode = Attribute(str, "headless", "headless (EGL, no display) or window (GLFW)", choices=("headless", "window"))
    visualization = Attribute(str, "mono", "2d (pixel space), mono (3D) or stereo (side by side)",
                              choices=("2d", "mono", "stereo"))
    eye_separation = Attribute(float, 0.064, "stereo: distance between the eyes (m)", min=0.0)
    background = Attribute(list[float], [0.0, 0.0, 0.0, 1.0], "clear colour r g b [a], 0..1", check=_colour)
    world = Attribute(str, "world", "transformation-graph frame the views are expressed in")
    title = Attribute(str, "CoCo", "window title")
    depth_output = Attribute(bool, False, "also read back the depth buffer to the depth port (metres)")
    vsync = Attribute(bool, False, "window: wait for the display's refresh (off: the activity sets the rate)")
    stamped = Attribute(bool, False, "write the images as Stamped(Image, frame stamp): the oldest input the "
                        "frame is the first to show (sensor-to-display latency downstream)")

    color = OutputPort(Image, doc="the rendered frame, RGB8, top row first (like a camera image)")
    depth = OutputPort(Image, doc="with depth_output: distance along the view axis, DEPTH32F metres, NaN "
                       "where nothing was drawn")
    latency = OutputPort(Stamped, doc="per frame that shows a new input: seconds from that input's origin (the "
                         "frame's stamp) to the frame read back")

    def init(self) -> None:
        if self.stamped:  # this instance's images go out wrapped: its bound ports say so, for the wiring check
            self.color.type = self.depth.type = Stamped
        self.surface: Surface | None = None
        self.frames = 0
        self.last_stamp: Stamp | None = None
        """The stamp of the last frame rendered (see the module docstring)."""
        self._drawing: list[GLPeer] = []
        """The drawing peers whose gl_init succeeded, in drawing order: only these render and release."""

    # --- life cycle -----------------------------------------------------------------------------
    def on_config(self) -> None:
        if self.visualization != "2d" and self.camera is None:
            raise SetupError(f"GLManager {self.name}: {self.visualization} visualization needs a camera peer "
                             f"(GLCameraManager); peers: {', '.join(p.name for p in self.peers) or 'none'}")
        if self.depth.connected and not self.depth_output:
            log.warning("GLManager %s: its depth port is connected but depth_output is false: no depth images "
                        "will be sent", self.name)
        if self.mode == "window":
            self.surface = WindowSurface(self.width, self.height, self.title, self.vsync)
        else:
            self.surface = HeadlessSurface(self.width, self.height)
        ctx = self.surface.ctx
        log.info("GLManager %s: %s %dx%d, %s", self.name, self.mode, *self.surface.size, ctx.info["GL_RENDERER"])
        # A peer whose on_config failed (already reported, and disabled) gets no gl_init: it has nothing
        # to upload. A peer whose gl_init fails is reported and disabled (its error policy cannot make
        # it draw).
        self._drawing = [peer for peer in self.walk()[1:]
                         if isinstance(peer, GLPeer) and peer.enabled
                         and peer.run_guarded("gl_init", partial(peer.gl_init, ctx))]

    def on_update(self) -> None:
        surface = self.surface
        assert surface is not None, "on_update before a successful on_config"
        events = surface.poll()
        if events:
            dispatch(events, self.walk()[1:])
            if any(event.kind is EventKind.CLOSE for event in events):
                self._close()
        started = time.perf_counter()
        for peer in self.peers:
            peer.step()
        self.render_frame(started)
        surface.present()
        self.frames += 1

    def on_stop(self) -> None:
        if self.surface is None:
            return
        for peer in self._drawing:
            peer.run_guarded("gl_release", peer.gl_release, count_only=True)
        self._drawing = []
        self.surface.release()
        self.surface = None

    # --- one frame ------------------------------------------------------------------------------
    @property
    def camera(self) -> Component | None:
        """The first peer that provides views (a GLCameraManager), or None."""
        return next((peer for peer in self.peers if hasattr(peer, "render_views")), None)

    def views(self) -> list[RenderView]:
        """The views of this frame, in the framebuffer's current size."""
        assert self.surface is not None
        size = self.surface.size
        if self.visualization == "2d":
            return [pixel_view(*size, self.world)]
        return self.camera.render_views(size, self.visualization == "stereo",  # type: ignore[union-attr]
                                        self.eye_separation, self.world)

    def render_frame(self, started: float | None = None) -> list[RenderView]:
        """Clear, draw every enabled peer per view, and write the output ports; the views drawn.
        ``started``: when the frame's update began (default: now), its stamp's ``frame_start``."""
        if started is None:
            started = time.perf_counter()
        surface = self.surface
        assert surface is not None
        ctx, fbo = surface.ctx, surface.fbo
        views = self.views()
        fbo.use()
        ctx.viewport = (0, 0, *surface.size)
        red, green, blue = self.background[:3]
        background = (red, green, blue, self.background[3] if len(self.background) == 4 else 1.0)
        fbo.clear(*background, depth=1.0)
        for view in views:
            blank = replace(view, background=background)  # for the first peer: nothing drawn there yet
            for peer in self._drawing:
                if not peer.enabled:  # stopped by its error policy (or the application)
                    continue
                # Each peer starts from the same state: one peer's settings never leak into the next.
                ctx.enable_only(moderngl.DEPTH_TEST)
                ctx.viewport = view.viewport
                try:
                    peer.render(ctx, blank)
                except Exception:
                    peer.report_error("render")
                blank = view
        origin = self._frame_origin()
        if origin is not None:  # a frame to time: the drawing finished apart from its read-back
            ctx.finish()
            origin = origin.step("frame_start", started).step("drawn")
        self._write_outputs(fbo, views, origin)
        return views

    def _frame_origin(self) -> Stamp | None:
        """The oldest origin among the inputs this frame is the first to show (every peer's ``shown``)."""
        oldest: Stamp | None = None
        for peer in self.walk()[1:]:
            shown = getattr(peer, "shown", None)
            origin = shown.take() if isinstance(shown, ShownInputs) else None
            if origin is not None and (oldest is None or origin.time < oldest.time):
                oldest = origin
        return oldest

    def _write_outputs(self, fbo: moderngl.Framebuffer, views: list[RenderView], origin: Stamp | None) -> None:
        width, height = fbo.size
        seq = self.frames + 1
        frame = (Stamp(origin.time, seq, origin.source, origin.steps) if origin is not None
                 else Stamp.now(seq, self.name))
        self.last_stamp = frame
        stamp = time.time()
        if self.color.connected:
            rgb = np.empty((height, width, 3), np.uint8)
            fbo.read_into(rgb, components=3, alignment=1)
            # GL's rows go bottom-up; the flipped view is free, images are read top row first.
            self._write_image(self.color, Image(rgb[::-1], ImageFormat.RGB8, stamp, self.world), frame)
        if self.depth_output and self.depth.connected:
            depth = Image(self.read_depth(fbo, views)[::-1], ImageFormat.DEPTH32F, stamp, self.world)
            self._write_image(self.depth, depth, frame)
        if origin is not None:  # the pixels exist now: read back (or finished in render_frame)
            frame = frame.step("read_back")
            self.record_latency(frame)
            self.latency.write(Stamped(frame.age(), frame))

    def _write_image(self, port: OutputPort, image: Image, frame: Stamp) -> None:
        port.write(Stamped(image, frame) if self.stamped else image)

    @staticmethod
    def read_depth(fbo: moderngl.Framebuffer, views: list[RenderView]) -> np.ndarray:
        """Metres along the view axis, bottom row first (GL's order), NaN where the far plane was kept."""
        width, height = fbo.size
        window = np.empty((height, width), np.float32)
        fbo.read_into(window, attachment=-1, dtype="f4", alignment=1)
        background = window >= 1.0
        metres = window  # linearised in place, one viewport at a time (each eye has its own projection)
        for view in views:
            x, y, w, h = view.viewport
            region = metres[y:y + h, x:x + w]
            region[...] = proj.linear_depth(region * 2.0 - 1.0, view.projection)
        metres[background] = np.nan
        return metres

    def _close(self) -> None:
        """The window was closed: stop the application (or this manager's activity when standalone)."""
        log.info("GLManager %s: window closed, stopping", self.name)
        if self.app is not None:
            self.app.request_stop(f"window of {self.name} closed")
        elif self.activity is not None:
            self.activity.stop()
