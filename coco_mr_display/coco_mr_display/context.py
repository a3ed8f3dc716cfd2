"""OpenGL 3.3 core contexts for GLManager: headless (EGL) and windowed (GLFW).

Both kinds render into the same thing, an offscreen framebuffer of the manager's size (colour and
depth renderbuffers): that is what the ``color`` and ``depth`` output ports read back, so headless and
windowed runs produce the same images. A window then copies that framebuffer to its screen and swaps.
This costs one blit per frame and buys a single render path.

Contexts are thread-bound: a surface is created, used and released in one thread, the manager's
activity thread (``on_config`` .. ``on_stop``). Each surface owns its own context, so several managers
on several activities render at once. GLFW's library-wide state (init/terminate, window creation,
event polling) is shared by every window of the process and is serialised by one lock here; GLFW
documents these calls as main-thread only, which X11 does not enforce (macOS does: windowed managers
there would need the main activity).
"""

from __future__ import annotations

import logging
import threading
from types import ModuleType

import moderngl
from coco_core.errors import DisplayError

from .events import Action, EventKind, InputEvent

log = logging.getLogger("coco.display")

GL_VERSION = 330


class Surface:
    """An OpenGL context and the framebuffer a manager renders into."""

    def __init__(self, ctx: moderngl.Context, width: int, height: int) -> None:
        self.ctx = ctx
        self.fbo: moderngl.Framebuffer = self._framebuffer(width, height)

    @property
    def size(self) -> tuple[int, int]:
        """Width and height of the framebuffer in pixels."""
        return self.fbo.size

    def _framebuffer(self, width: int, height: int) -> moderngl.Framebuffer:
        ctx = self.ctx
        return ctx.framebuffer(ctx.renderbuffer((width, height), 4), ctx.depth_renderbuffer((width, height)))

    def resize(self, width: int, height: int) -> None:
        """Reallocate the framebuffer (a window was resized)."""
        if (width, height) == self.size or width <= 0 or height <= 0:
            return
        self._release_framebuffer()
        self.fbo = self._framebuffer(width, height)

    def _release_framebuffer(self) -> None:
        for attachment in (*self.fbo.color_attachments, self.fbo.depth_attachment):
            if attachment is not None:
                attachment.release()
        self.fbo.release()

    def poll(self) -> list[InputEvent]:
        """Input events since the last call (none without a window)."""
        return []

    def present(self) -> None:
        """Show the rendered framebuffer (nothing to do without a window)."""

    def release(self) -> None:
        """Release the framebuffer and the context; call in the thread that created the surface."""
        self._release_framebuffer()
        self.ctx.release()


class HeadlessSurface(Surface):
    """An EGL context without any window (Mesa's llvmpipe on a machine without GPU or display)."""

    def __init__(self, width: int, height: int) -> None:
        # moderngl's stub types each keyword as a dict; the function takes these plain values
        context = moderngl.create_standalone_context(backend="egl", require=GL_VERSION)  # type: ignore[arg-type]
        super().__init__(context, width, height)


class _Glfw:
    """The process-wide GLFW library: initialised by the first window, terminated with the last."""

    lock = threading.RLock()
    windows = 0

    @classmethod
    def acquire(cls) -> ModuleType:
        import glfw  # only windowed managers need GLFW (and a display)

        with cls.lock:
            if cls.windows == 0 and not glfw.init():
                raise DisplayError(f"GLFW could not be initialised (a window needs a display, DISPLAY or "
                                   f"WAYLAND_DISPLAY; use mode headless without one): {glfw.get_error()[1]!r}")
            cls.windows += 1
        return glfw

    @classmethod
    def release(cls) -> None:
        import glfw

        with cls.lock:
            cls.windows -= 1
            if cls.windows == 0:
                glfw.terminate()


_ACTIONS = {0: Action.RELEASE, 1: Action.PRESS, 2: Action.REPEAT}


class WindowSurface(Surface):
    """A GLFW window with an OpenGL 3.3 core context; its input arrives as :class:`InputEvent`."""

    def __init__(self, width: int, height: int, title: str, vsync: bool = False) -> None:
        glfw = _Glfw.acquire()
        self._glfw = glfw
        try:
            with _Glfw.lock:
                glfw.default_window_hints()
                glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, GL_VERSION // 100)
                glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, GL_VERSION % 100 // 10)
                glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
                glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
                window = glfw.create_window(width, height, title, None, None)
            if not window:
                raise DisplayError(f"GLFW could not create a {width}x{height} OpenGL {GL_VERSION // 100}."
                                   f"{GL_VERSION % 100 // 10} core window")
        except BaseException:
            _Glfw.release()
            raise
        self.window = window
        glfw.make_context_current(window)
        glfw.swap_interval(1 if vsync else 0)
        self._events: list[InputEvent] = []
        self._keys = {getattr(glfw, name): name[4:] for name in dir(glfw) if name.startswith("KEY_")}
        self._install_callbacks()
        super().__init__(moderngl.create_context(require=GL_VERSION), *glfw.get_framebuffer_size(window))

    def _window_size(self) -> tuple[int, int]:
        width, height = self._glfw.get_window_size(self.window)
        return width, height

    def _install_callbacks(self) -> None:
        glfw, window, push = self._glfw, self.window, self._events.append

        def on_key(_w: object, key: int, _scancode: int, action: int, mods: int) -> None:
            push(InputEvent(EventKind.KEY, self._window_size(), key=self._keys.get(key, str(key)),
                            action=_ACTIONS[action], mods=mods))

        def on_button(_w: object, button: int, action: int, mods: int) -> None:
            x, y = glfw.get_cursor_pos(window)
            push(InputEvent(EventKind.MOUSE_BUTTON, self._window_size(), action=_ACTIONS[action], button=button,
                            mods=mods, x=x, y=y))

        def on_cursor(_w: object, x: float, y: float) -> None:
            push(InputEvent(EventKind.CURSOR, self._window_size(), x=x, y=y))

        def on_scroll(_w: object, dx: float, dy: float) -> None:
            push(InputEvent(EventKind.SCROLL, self._window_size(), x=dx, y=dy))

        def on_resize(_w: object, width: int, height: int) -> None:
            push(InputEvent(EventKind.RESIZE, (width, height)))

        glfw.set_key_callback(window, on_key)
        glfw.set_mouse_button_callback(window, on_button)
        glfw.set_cursor_pos_callback(window, on_cursor)
        glfw.set_scroll_callback(window, on_scroll)
        glfw.set_window_size_callback(window, on_resize)

    def poll(self) -> list[InputEvent]:
        """Pump GLFW's queue; the framebuffer follows the window's size; a close request ends the list."""
        glfw = self._glfw
        with _Glfw.lock:
            glfw.poll_events()
        self.resize(*glfw.get_framebuffer_size(self.window))
        if glfw.window_should_close(self.window):
            self._events.append(InputEvent(EventKind.CLOSE, self._window_size()))
        events, self._events[:] = list(self._events), []
        return events

    def request_close(self) -> None:
        """Ask the window to close, as its close button does (thread-safe in GLFW)."""
        self._glfw.set_window_should_close(self.window, True)

    def present(self) -> None:
        self.ctx.copy_framebuffer(self.ctx.screen, self.fbo)
        self._glfw.swap_buffers(self.window)

    def release(self) -> None:
        super().release()
        with _Glfw.lock:
            self._glfw.destroy_window(self.window)
        _Glfw.release()
