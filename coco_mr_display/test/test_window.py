"""GLManager in window mode: a real GLFW window on a real (virtual) X server, Xvfb.

The window renders the same frames as headless mode, follows a resize made through X, delivers
cursor events to the peers, and closing it stops the application.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from typing import Iterator

import numpy as np
import pytest

from conftest import Cube, Frames
from coco_core import Application, PeriodicActivity
from coco_core.component import Component
from coco_core.policy import BufferPolicy, ConnectionPolicy, SyncPolicy
from coco_mr_display.camera import GLCameraManager
from coco_mr_display.events import EventHandler, EventKind, InputEvent
from coco_mr_display.manager import GLManager

RED = (255, 0, 0)


@pytest.fixture
def x_display(monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """A private Xvfb server on a free display number; DISPLAY points at it during the test."""
    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed (apt package xvfb)")
    read_end, write_end = os.pipe()
    server = subprocess.Popen(["Xvfb", "-displayfd", str(write_end), "-screen", "0", "800x600x24", "-nolisten", "tcp"],
                              pass_fds=(write_end,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(write_end)
    try:
        with os.fdopen(read_end) as stream:
            number = stream.readline().strip()
        if not number:
            pytest.skip("Xvfb did not start")
        monkeypatch.setenv("DISPLAY", f":{number}")
        monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
        yield f":{number}"
    finally:
        server.terminate()
        server.wait(timeout=10)


class EventLog(EventHandler, Component):
    """Records the events the window delivers."""

    def init(self) -> None:
        self.events: list[InputEvent] = []

    def handle_event(self, event: InputEvent) -> None:
        self.events.append(event)


def wait_for(predicate, timeout: float = 15.0) -> bool:  # noqa: ANN001
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return bool(predicate())


def test_window_renders_resizes_delivers_events_and_closing_stops(x_display: str) -> None:
    import glfw

    app = Application("window-test")
    manager = GLManager("display", mode="window", width=160, height=120, title="CoCo window test")
    manager.add_peer(GLCameraManager("camera", position=[0.0, -4.0, 0.0], look_at=[0.0, 0.0, 0.0]))
    manager.add_peer(Cube("cube"))
    log = manager.add_peer(EventLog("events"))
    frames = Frames("frames")
    app.add(manager, PeriodicActivity("render", 0.02))
    app.add(frames, PeriodicActivity("sink", 0.01))
    app.connect("display.color", "frames.image", ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 256))
    app.start()
    try:
        assert wait_for(lambda: len(frames.images) >= 3), f"no frames from the window (errors: {manager.stats.errors})"
        first = frames.images[0].data
        assert first.shape == (120, 160, 3)
        red = np.all(first == RED, axis=2)
        assert 500 < red.sum() < 160 * 120 and red[60, 80]  # the cube, in the middle, as headless draws it
        window = manager.surface.window
        assert glfw.get_window_size(window) == (160, 120)
        # A resize through the X server: the framebuffer and the output images follow.
        manager.activity.enqueue(lambda: glfw.set_window_size(window, 200, 100))
        assert wait_for(lambda: frames.images[-1].size == (200, 100)), "the framebuffer did not follow the window"
        # (X may report the new size before its ConfigureNotify event arrives: the event can come a frame later.)
        assert wait_for(lambda: any(e.kind is EventKind.RESIZE and e.size == (200, 100) for e in log.events))
        # Moving the pointer into the window (an X pointer warp) arrives as cursor events.
        manager.activity.enqueue(lambda: glfw.set_cursor_pos(window, 50.0, 40.0))
        assert wait_for(lambda: any(e.kind is EventKind.CURSOR for e in log.events)), "no cursor event"
        cursor = next(e for e in log.events if e.kind is EventKind.CURSOR)
        assert (cursor.x, cursor.y) == (50.0, 40.0) and cursor.size == (200, 100)
        # Closing the window (what its close button does) stops the application.
        manager.surface.request_close()
        assert app.wait(10.0), "closing the window did not stop the application"
        assert app.stop_reason == "window of display closed"
        assert any(e.kind is EventKind.CLOSE for e in log.events)
    finally:
        assert app.stop()
    assert manager.surface is None and manager.stats.errors == 0
