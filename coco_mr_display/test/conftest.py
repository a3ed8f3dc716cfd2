"""Shared fixtures of the display tests: a real headless OpenGL context and framebuffer read-back.

Everything renders for real (Mesa's llvmpipe through EGL on a machine without GPU); the tests skip
with the reason when no OpenGL 3.3 context can be created. ``Cube`` is a minimal real drawing peer
(flat colour, no lighting) whose pixels tests can predict analytically with ``project``; ``Frames``
collects a GLManager's output images and ``render_once`` draws one frame of a manager in the test's
thread.

When pytest runs from the source tree, the workspace's sibling packages are put on the path here.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from typing import Callable, Iterator

import pytest

_WORKSPACE = Path(__file__).resolve().parents[2]
for _package in sorted(_WORKSPACE.glob("*/package.xml")):
    _name = _package.parent.name
    if (_package.parent / _name / "__init__.py").is_file() and importlib.util.find_spec(_name) is None:
        sys.path.insert(0, str(_package.parent))

import moderngl  # noqa: E402
import numpy as np  # noqa: E402

from coco_core.attributes import Attribute  # noqa: E402
from coco_core.component import Component  # noqa: E402
from coco_core.ports import InputPort  # noqa: E402
from coco_mr_display.manager import GLManager  # noqa: E402
from coco_mr_display.peer import GLPeer  # noqa: E402
from coco_mr_display.view import RenderView  # noqa: E402
from coco_mr_vision.image import Image  # noqa: E402

CUBE_CORNERS = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
"""The 8 corners of the unit cube centred on the origin (index = 4 * (x > 0) + 2 * (y > 0) + (z > 0))."""

_CUBE_TRIANGLES = np.array([
    [0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5],  # x = -0.5, x = +0.5
    [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],  # y = -0.5, y = +0.5
    [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3],  # z = -0.5, z = +0.5
], dtype="i4")


def _create_context() -> moderngl.Context:
    try:
        return moderngl.create_standalone_context(backend="egl", require=330)
    except Exception as error:  # no EGL / no Mesa: the tests cannot run here
        pytest.skip(f"no headless OpenGL 3.3 context (EGL): {error}")


@pytest.fixture
def gl_context() -> Iterator[moderngl.Context]:
    """A headless OpenGL 3.3 core context, current in the test's thread, released afterwards."""
    ctx = _create_context()
    yield ctx
    ctx.release()


@pytest.fixture
def framebuffer(gl_context: moderngl.Context) -> Callable[[int, int], moderngl.Framebuffer]:
    """``framebuffer(width, height)``: a colour + depth framebuffer of ``gl_context``, bound and cleared."""

    def make(width: int, height: int) -> moderngl.Framebuffer:
        fbo = gl_context.framebuffer(gl_context.renderbuffer((width, height), 4),
                                     gl_context.depth_renderbuffer((width, height)))
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
        return fbo

    return make


def read_rgb(fbo: moderngl.Framebuffer) -> np.ndarray:
    """The framebuffer's colour as an HxWx3 uint8 array, top row first (like a camera image)."""
    width, height = fbo.size
    return np.frombuffer(fbo.read(components=3, alignment=1), np.uint8).reshape(height, width, 3)[::-1]


def project(view: RenderView, points: np.ndarray, height: int) -> np.ndarray:
    """Pixel coordinates (x right, y down from the top of a framebuffer ``height`` pixels high) of
    world points, by the textbook pipeline: clip space, perspective divide, viewport transform."""
    homogeneous = np.c_[points, np.ones(len(points))] @ view.view_projection.T
    ndc = homogeneous[:, :3] / homogeneous[:, 3:]
    x, y, w, h = view.viewport
    return np.c_[x + (ndc[:, 0] + 1) * w / 2, height - (y + (ndc[:, 1] + 1) * h / 2)]


class Cube(GLPeer):
    """A flat-coloured box (edges ``size``, one number for a cube, centred at ``position``), the simplest
    real drawing peer."""

    position = Attribute(list[float], [0.0, 0.0, 0.0], "centre in the world frame")
    size = Attribute(list[float], [1.0], "edge length, or x y z edge lengths (m)")
    rgb = Attribute(list[float], [1.0, 0.0, 0.0], "colour")

    def gl_init(self, ctx: moderngl.Context) -> None:
        self.program = ctx.program(
            vertex_shader="""#version 330
                uniform mat4 mvp; in vec3 in_position;
                void main() { gl_Position = mvp * vec4(in_position, 1.0); }""",
            fragment_shader="""#version 330
                uniform vec3 rgb; out vec4 colour;
                void main() { colour = vec4(rgb, 1.0); }""")
        self.vbo = ctx.buffer(CUBE_CORNERS.astype("f4").tobytes())
        self.ibo = ctx.buffer(_CUBE_TRIANGLES.tobytes())
        self.vao = ctx.vertex_array(self.program, [(self.vbo, "3f", "in_position")], self.ibo)

    def model(self) -> np.ndarray:
        model = np.diag([*np.broadcast_to(self.size, 3), 1.0])
        model[:3, 3] = self.position
        return model

    def render(self, ctx: moderngl.Context, view: RenderView) -> None:
        self.program["mvp"].write((view.view_projection @ self.model()).astype("f4").T.tobytes())
        self.program["rgb"].value = tuple(self.rgb)
        self.vao.render()

    def gl_release(self) -> None:
        for resource in (self.vao, self.ibo, self.vbo, self.program):
            resource.release()


class Frames(Component):
    """Keeps every image it receives (the test reads ``images`` after the run)."""

    image = InputPort(Image)

    def init(self) -> None:
        self.images: list[Image] = []

    def on_update(self) -> None:
        self.images.extend(self.image.read_all())


def render_once(manager: GLManager, reader: InputPort) -> Image:
    """Configure the manager in this thread (the context is bound to it), draw one frame, stop."""
    assert manager.configure(), "GLManager failed to configure (see the log)"
    try:
        manager.step()
        frames = reader.read_all()
        assert len(frames) == 1
        return frames[-1]
    finally:
        manager.stop()
