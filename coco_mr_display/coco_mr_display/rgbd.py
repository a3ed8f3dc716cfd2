"""GLRGBDImage: a colour + depth frame drawn as a textured surface, unprojected on the GPU.

The mesh is the pixel grid itself: vertex ``i`` is depth pixel ``(i % W, i // W)`` and the index
buffer (two triangles per grid square) is built once per resolution (and ``stride``). The vertex
shader reads the pixel's depth from a texture and back-projects it through the pinhole intrinsics, so
a new frame costs two texture writes (depth, colour) and no Python work proportional to the number of
vertices. That keeps the upload off the render loop's critical path: at 640x480 it is a copy of
1.5 MB (under a millisecond).

- **Temporal averaging** (``average`` = N): the depth texture is an array of N layers written in
  turn; the vertex shader averages a pixel's valid (non-zero, non-NaN) depths over the layers.
  Averaging depth along each pixel's ray is averaging the vertex positions, since x and y are
  proportional to depth.
- **Rubber-sheet removal** (``max_edge``, metres): between a foreground and a background surface the
  grid makes long, nearly edge-on triangles. A geometry shader drops every triangle with an edge
  longer than ``max_edge``, and always those with a vertex of unknown depth.
- **Stride** (``stride`` = s): one vertex every s depth pixels, s^2 times fewer triangles, the colour
  still sampled at full resolution. On a software rasteriser (Mesa llvmpipe) vertex and primitive
  processing run on the drawing thread at roughly 0.1-0.2 us per triangle, so the full 640x480 grid
  (612k triangles) alone takes longer than a 30 Hz frame there (see ``bench/bench_display.py``);
  ``stride`` 2 trades geometric detail for frame rate.

The camera is the depth camera's optical frame (x right, y down, z forward, as ROS ``*_optical_frame``
and OpenCV); its pose comes from the transformation graph (``frame``) or from ``xyz``/``rpy``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import moderngl
import numpy as np

from coco_core.attributes import Attribute
from coco_core.policy import NEW_DATA
from coco_core.ports import InputPort
from coco_core.transforms import se3
from coco_mr_vision.image import CameraIntrinsics, Image, ImageFormat
from coco_mr_vision.rgbd import RGBDFrame

from .image_texture import ImageTexture
from .peer import GLPeer

if TYPE_CHECKING:
    from .view import RenderView

MAX_AVERAGE = 32
"""Most frames ``average`` may span: each one is a texture fetch per vertex per view."""

_VERTEX = """
#version 330
uniform sampler2DArray depths;
uniform int layers;
uniform float depth_unit;   // metres per (normalised) texel value
uniform vec4 intrinsics;    // fx, fy, cx, cy of the depth image
uniform mat4 model_view;    // camera optical frame -> eye
uniform int stride;         // one vertex every `stride` pixels along x and y
out Vertex { vec3 eye; vec2 uv; float valid; } vertex;
void main() {
    ivec2 size = textureSize(depths, 0).xy;
    int columns = (size.x + stride - 1) / stride;
    ivec2 pixel = ivec2(gl_VertexID % columns, gl_VertexID / columns) * stride;
    float sum = 0.0;
    int count = 0;
    for (int layer = 0; layer < layers; ++layer) {
        float d = texelFetch(depths, ivec3(pixel, layer), 0).r;
        if (d > 0.0) {  // false for 0 (unknown) and NaN
            sum += d;
            count += 1;
        }
    }
    float z = count > 0 ? sum / float(count) * depth_unit : 0.0;
    vec3 point = vec3((vec2(pixel) - intrinsics.zw) / intrinsics.xy * z, z);
    vertex.eye = (model_view * vec4(point, 1.0)).xyz;
    vertex.uv = (vec2(pixel) + 0.5) / vec2(size);  // row 0 of the colour texture is the top row
    vertex.valid = count > 0 ? 1.0 : 0.0;
}
"""

_GEOMETRY = """
#version 330
layout(triangles) in;
layout(triangle_strip, max_vertices = 3) out;
uniform mat4 projection;
uniform float max_edge;  // metres; <= 0: keep every triangle of valid vertices
in Vertex { vec3 eye; vec2 uv; float valid; } vertex[];
out vec2 uv;
void main() {
    if (vertex[0].valid * vertex[1].valid * vertex[2].valid == 0.0) {
        return;
    }
    if (max_edge > 0.0) {
        vec3 a = vertex[1].eye - vertex[0].eye;
        vec3 b = vertex[2].eye - vertex[1].eye;
        vec3 c = vertex[0].eye - vertex[2].eye;
        float longest = max(dot(a, a), max(dot(b, b), dot(c, c)));
        if (longest > max_edge * max_edge) {
            return;
        }
    }
    for (int i = 0; i < 3; ++i) {
        gl_Position = projection * vec4(vertex[i].eye, 1.0);
        uv = vertex[i].uv;
        EmitVertex();
    }
    EndPrimitive();
}
"""

_FRAGMENT = """
#version 330
uniform sampler2D color_image;
in vec2 uv;
out vec4 color;
void main() {
    color = vec4(texture(color_image, uv).rgb, 1.0);
}
"""


def grid_indices(width: int, height: int) -> np.ndarray:
    """Triangle indices of a ``width`` x ``height`` vertex grid, counter-clockwise as the camera sees
    them: two triangles per square, ``(i, i+W, i+1)`` and ``(i+1, i+W, i+W+1)``."""
    top_left = (np.arange(height - 1, dtype=np.uint32)[:, None] * width
                + np.arange(width - 1, dtype=np.uint32)[None, :]).ravel()
    below, right = top_left + width, top_left + 1
    return np.stack([top_left, below, right, right, below, below + 1], axis=1).ravel()


def _three(value: tuple[float, ...]) -> str | None:
    return None if len(value) == 3 else f"expected 3 numbers, got {len(value)}"


class _DepthRing:
    """``layers`` depth frames in a texture array, the newest overwriting the oldest."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.texture: moderngl.TextureArray | None = None
        self.depth_unit = 1.0
        self._key: tuple[tuple[int, int], str, int] | None = None
        self._next = 0

    def write(self, depth: Image, depth_scale: float, layers: int) -> None:
        """Store ``depth`` (DEPTH16 as normalised 16 bit, DEPTH32F as float) as the newest layer.

        A change of size, format or number of layers starts the ring again (all layers unknown), so
        frames of different cameras are never averaged together.
        """
        dtype = "nu2" if depth.format is ImageFormat.DEPTH16 else "f4"
        key = (depth.size, dtype, layers)
        if key != self._key:
            self.release()
            width, height = depth.size
            self.texture = self.ctx.texture_array((width, height, layers), 1, dtype=dtype, alignment=1)
            self.texture.write(np.zeros((layers, height, width), depth.format.dtype), alignment=1)
            self.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._key, self._next = key, 0
        assert self.texture is not None
        self.depth_unit = 65535.0 / depth_scale if dtype == "nu2" else 1.0
        width, height = depth.size
        self.texture.write(np.ascontiguousarray(depth.data), viewport=(0, 0, self._next, width, height, 1),
                           alignment=1)
        self._next = (self._next + 1) % layers

    @property
    def layers(self) -> int:
        return 0 if self._key is None else self._key[2]

    @property
    def size(self) -> tuple[int, int] | None:
        return None if self._key is None else self._key[0]

    def release(self) -> None:
        if self.texture is not None:
            self.texture.release()
        self.texture, self._key = None, None


class GLRGBDImage(GLPeer):
    """Draws the latest RGB-D frame as a surface: from ``rgbd``, or from ``color`` + ``depth``.

    Intrinsics, first found wins: the ``intrinsics`` port, those the frame (or depth image) carries,
    the ``fx``/``fy``/``cx``/``cy`` attributes. Nothing is drawn until colour and depth have arrived.
    """

    rgbd = InputPort(RGBDFrame, doc="colour + depth frames (each carries its depth scale)")
    color = InputPort(Image, doc="colour images registered to the depth images (any non-depth format)")
    depth = InputPort(Image, doc="DEPTH16 (units of 1/depth_scale m) or DEPTH32F (m) images")
    intrinsics = InputPort(CameraIntrinsics, doc="intrinsics of the depth camera")

    fx = Attribute(float, 0.0, "focal length in pixels along x (0: take the intrinsics from the data)", min=0.0)
    fy = Attribute(float, 0.0, "focal length in pixels along y", min=0.0)
    cx = Attribute(float, 0.0, "principal point x in pixels")
    cy = Attribute(float, 0.0, "principal point y in pixels")
    depth_scale = Attribute(float, 1000.0, "DEPTH16 units per metre on the depth port (TUM: 5000)", min=1e-9)
    frame = Attribute(str, "", "transformation-graph frame of the depth camera's optical frame "
                      "(empty: use xyz and rpy)")
    xyz = Attribute(tuple[float, ...], (0.0, 0.0, 0.0), "camera position in the world frame (m)", check=_three)
    rpy = Attribute(tuple[float, ...], (0.0, 0.0, 0.0), "camera roll, pitch, yaw (rad, URDF convention)",
                    check=_three)
    stride = Attribute(int, 1, "one vertex every this many depth pixels (1: every pixel)", min=1, max=16)
    average = Attribute(int, 1, "average each pixel's valid depth over this many frames", min=1,
                        max=MAX_AVERAGE)
    max_edge = Attribute(float, 0.0, "drop triangles with an edge longer than this (m); 0: keep all",
                         min=0.0)

    def __init__(self, name: str | None = None, **attributes: object) -> None:
        super().__init__(name, **attributes)
        self._color: Image | None = None
        self._depth: tuple[Image, float] | None = None
        self._port_intrinsics: CameraIntrinsics | None = None
        self._data_intrinsics: CameraIntrinsics | None = None
        self._pinhole: tuple[float, float, float, float] | None = None
        self._program: moderngl.Program | None = None
        self._colors: ImageTexture | None = None
        self._depths: _DepthRing | None = None
        self._mesh: moderngl.VertexArray | None = None
        self._indices: moderngl.Buffer | None = None
        self._grid: tuple[tuple[int, int], int] | None = None
        self._ready = False

    # --- ports (step) -----------------------------------------------------------------------------
    def on_update(self) -> None:
        status, intrinsics = self.intrinsics.read()
        if status is NEW_DATA:
            self._port_intrinsics = intrinsics
        status, frame = self.rgbd.read()
        if status is NEW_DATA:
            self._color, self._depth = frame.color, (frame.depth, frame.depth_scale)
            self._data_intrinsics = frame.intrinsics
        status, color = self.color.read()
        if status is NEW_DATA:
            self._color = color
        status, depth = self.depth.read()
        if status is NEW_DATA:
            if not depth.format.is_depth:
                raise ValueError(f"{self.name}.depth takes DEPTH16 or DEPTH32F images, got {depth.format.name}")
            self._depth = (depth, self.depth_scale)
            self._data_intrinsics = depth.intrinsics
        if self._depth is not None or self._pinhole is not None:
            # Checked here, where an error is reported as this component's, and every frame: the
            # attributes may change at run time.
            self._pinhole = self.camera_intrinsics()

    def camera_intrinsics(self) -> tuple[float, float, float, float]:
        """``(fx, fy, cx, cy)`` in use; a clear error when no source gives them."""
        known = self._port_intrinsics or self._data_intrinsics
        if known is not None:
            return known.fx, known.fy, known.cx, known.cy
        if self.fx > 0 and self.fy > 0:
            return self.fx, self.fy, self.cx, self.cy
        raise ValueError(f"{self.name}: no intrinsics: connect the intrinsics port, send images or frames "
                         "that carry intrinsics, or set the attributes fx, fy, cx, cy")

    def camera_pose(self, world: str) -> np.ndarray:
        """4x4 pose of the camera's optical frame in ``world`` (the view's frame)."""
        if self.frame:
            return self.transform_graph.lookup(world, self.frame)
        return se3.make(se3.rpy_to_matrix(*self.rpy), self.xyz)

    # --- GL (render) ------------------------------------------------------------------------------
    def gl_init(self, ctx: moderngl.Context) -> None:
        self._program = ctx.program(vertex_shader=_VERTEX, geometry_shader=_GEOMETRY, fragment_shader=_FRAGMENT)
        self._program["depths"] = 0
        self._program["color_image"] = 1
        self._colors = ImageTexture(ctx)
        self._depths = _DepthRing(ctx)

    def upload(self, ctx: moderngl.Context) -> None:
        """Texture writes of what arrived since the last frame; the index buffer on a new resolution."""
        assert self._colors is not None and self._depths is not None and self._program is not None
        if self._color is not None:
            self._colors.write(self._color)
            self._color = None
        if self._depth is not None:
            depth, scale = self._depth
            self._depths.write(depth, scale, self.average)
            self._depth = None
        self._ensure_grid(ctx)
        self._ready = self._mesh is not None and self._colors.size is not None

    def _ensure_grid(self, ctx: moderngl.Context) -> None:
        """The index buffer of the current depth size and ``stride`` (built again only on a change)."""
        assert self._depths is not None and self._program is not None
        size = self._depths.size
        if size is None or (size, self.stride) == self._grid:
            return
        for resource in (self._mesh, self._indices):
            if resource is not None:
                resource.release()
        columns, rows = (-(-extent // self.stride) for extent in size)
        self._indices = ctx.buffer(grid_indices(columns, rows))
        self._mesh = ctx.vertex_array(self._program, [], index_buffer=self._indices, index_element_size=4)
        self._grid = (size, self.stride)

    def render(self, ctx: moderngl.Context, view: RenderView) -> None:
        assert self._program is not None, "GLRGBDImage.render() before gl_init()"
        if self._color is not None or self._depth is not None:
            self.upload(ctx)
        else:
            self._ensure_grid(ctx)  # stride may have changed at run time
        if not self._ready or self._pinhole is None:
            return
        assert self._mesh is not None and self._colors is not None and self._depths is not None
        program = self._program
        program["layers"] = self._depths.layers
        program["stride"] = self.stride
        program["depth_unit"] = self._depths.depth_unit
        program["intrinsics"] = self._pinhole
        program["max_edge"] = self.max_edge
        model_view = view.view @ self.camera_pose(view.frame)
        program["model_view"].write(model_view.T.astype("f4").tobytes())
        program["projection"].write(view.projection.T.astype("f4").tobytes())
        self._depths.texture.use(0)
        self._colors.use(1)
        self._mesh.render(moderngl.TRIANGLES)

    def gl_release(self) -> None:
        for resource in (self._mesh, self._indices, self._program):
            if resource is not None:
                resource.release()
        for textures in (self._colors, self._depths):
            if textures is not None:
                textures.release()
        self._mesh = self._indices = self._program = self._colors = self._depths = None
        self._grid, self._ready = None, False
