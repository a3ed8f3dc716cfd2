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
  grid makes long, nearly edge-on triangles. Every triangle with an edge longer than ``max_edge`` is
  left out of the index buffer, and always those with a vertex of unknown depth
  (:mod:`.surface_triangles`: on the CPU, once per new depth frame and stride; edge lengths do not
  depend on the view). The limit is the same at every stride: scaling it with the stride (edges of a
  sloped surface grow with it) fills walls seen at a grazing angle that full detail leaves open,
  which differed more from the full-detail picture than the few sloped triangles a fixed limit drops.
  (Measured on llvmpipe: the same test in a geometry shader, run for every triangle of every frame,
  made the draw call about twice as long; done per vertex, fetching the neighbours' depths in the
  vertex shader and discarding by ``gl_PrimitiveID`` in the fragment shader, slower still.)
- **Kept drawings**: the surface as drawn in each view is kept (:mod:`.layer_cache`) and put back
  into frames that bring it nothing new (no new frame, the same view), so a display redrawn for
  every pose of a hand draws the surface's triangles only when a camera frame arrives.
- **Stride** (``stride`` = s): one vertex every s depth pixels, s^2 times fewer triangles, the colour
  still sampled at full resolution. On a software rasteriser (Mesa llvmpipe) vertex and primitive
  processing run on the drawing thread at roughly 0.1-0.2 us per triangle, so the full 640x480 grid
  (612k triangles) alone takes longer than a 30 Hz frame there (see ``bench/bench_display.py``).
- **Automatic stride** (``stride`` 0, the default): a level of detail chosen per view from the
  surface's size on screen. Seen from across a room, a 640x480 frame covers a few ten thousand pixels
  and most of its 612k triangles are smaller than a pixel: drawing them costs the whole frame and
  shows nothing more. Each view takes the largest stride that keeps neighbouring vertices at most
  ``vertex_spacing`` pixels apart on screen (measured on a sparse sample of the newest depth frame);
  seen from its own camera the surface keeps every pixel.

The camera is the depth camera's optical frame (x right, y down, z forward, as ROS ``*_optical_frame``
and OpenCV); its pose comes from the transformation graph (``frame``) or from ``xyz``/``rpy``.
"""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING, Hashable

import moderngl
import numpy as np

from coco_core.attributes import Attribute
from coco_core.errors import ImageError
from coco_core.policy import NEW_DATA
from coco_core.ports import InputPort
from coco_core.stamps import Stamped, unstamped
from coco_core.transforms import se3
from coco_mr_vision.image import CameraIntrinsics, Image, ImageFormat
from coco_mr_vision.rgbd import RGBDFrame

from .image_texture import ImageTexture
from .layer_cache import LayerCache
from .peer import GLPeer
from .shown import ShownInputs
from .surface_triangles import kept_triangles
from .uniforms import uniform

if TYPE_CHECKING:
    from .view import RenderView

MAX_AVERAGE = 32
"""Most frames ``average`` may span: each one is a texture fetch per vertex per view."""
MAX_STRIDE = 16
"""Coarsest grid: one vertex every 16 depth pixels (1,200 triangles at 640x480)."""
LOD_SAMPLE = 16
"""The automatic stride measures the surface's size on screen at one depth pixel in LOD_SAMPLE^2."""

_VERTEX = """
#version 330
uniform sampler2DArray depths;
uniform int layers;
uniform float depth_unit;   // metres per (normalised) texel value
uniform vec4 intrinsics;    // fx, fy, cx, cy of the depth image
uniform mat4 model_view;    // camera optical frame -> eye
uniform mat4 projection;
uniform int stride;         // one vertex every `stride` pixels along x and y
out vec2 uv;
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
    gl_Position = projection * (model_view * vec4(point, 1.0));
    uv = (vec2(pixel) + 0.5) / vec2(size);  // row 0 of the colour texture is the top row
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


def sample_points(depth: Image, depth_scale: float, intrinsics: tuple[float, float, float, float]) -> np.ndarray:
    """(3, n, 3): points of every LOD_SAMPLE-th valid depth pixel in the optical frame (metres), and the
    same points moved by one depth pixel along x and along y: what the automatic stride projects."""
    fx, fy, cx, cy = intrinsics
    z = depth.data[::LOD_SAMPLE, ::LOD_SAMPLE].astype(np.float32)
    if depth.format is ImageFormat.DEPTH16:
        z /= depth_scale
    v, u = np.nonzero(z > 0.0)  # False for 0 (unknown) and NaN
    z = z[v, u]
    x, y = (u * LOD_SAMPLE - cx) / fx * z, (v * LOD_SAMPLE - cy) / fy * z
    points = np.stack([x, y, z], axis=1)
    zero = np.zeros_like(z)
    return np.stack([points, points + np.c_[z / fx, zero, zero], points + np.c_[zero, z / fy, zero]])


def automatic_stride(samples: np.ndarray, model_view_projection: np.ndarray, viewport: tuple[int, int, int, int],
                     spacing: float) -> int:
    """The largest stride keeping neighbouring grid vertices at most ``spacing`` pixels apart on screen.

    The screen distance of one depth pixel is the median, over the samples in the view, of the longer
    of its two projected steps (the longer one: a surface seen at a grazing angle keeps its detail
    along the direction that is stretched). Nothing in the view (nothing drawn): the largest stride.
    """
    if samples.shape[1] == 0:
        return MAX_STRIDE
    clip = np.concatenate([samples, np.ones((*samples.shape[:2], 1), np.float32)], axis=2) @ model_view_projection.T
    w = clip[..., 3]
    in_front = (w > 1e-6).all(axis=0)
    if not in_front.any():
        return MAX_STRIDE
    ndc = clip[:, in_front, :2] / w[:, in_front, None]
    inside = (np.abs(ndc[0]) <= 1.0).all(axis=1)
    if inside.any():
        ndc = ndc[:, inside]
    half = np.array(viewport[2:], np.float32) / 2.0
    steps = np.maximum(np.linalg.norm((ndc[1] - ndc[0]) * half, axis=1),
                       np.linalg.norm((ndc[2] - ndc[0]) * half, axis=1))
    pixel = float(np.median(steps))
    return int(np.clip(np.floor(spacing / max(pixel, 1e-9)), 1, MAX_STRIDE))


def _three(value: tuple[float, ...]) -> str | None:
    return None if len(value) == 3 else f"expected 3 numbers, got {len(value)}"


class _DepthRing:
    """``layers`` depth frames in a texture array, the newest overwriting the oldest, and their copies
    on the CPU (which triangles to draw is decided there: :mod:`.surface_triangles`)."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.texture: moderngl.TextureArray | None = None
        self.depth_unit = 1.0
        self._key: tuple[tuple[int, int], str, int] | None = None
        self._next = 0
        self._frames: list[np.ndarray | None] = []
        self._metres_per_unit = 1.0

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
            self._key, self._next, self._frames = key, 0, [None] * layers
        assert self.texture is not None
        self.depth_unit = 65535.0 / depth_scale if dtype == "nu2" else 1.0
        self._metres_per_unit = 1.0 / depth_scale if dtype == "nu2" else 1.0
        width, height = depth.size
        data = np.array(depth.data)  # a copy: a pooled frame may be reused once read
        self.texture.write(data, viewport=(0, 0, self._next, width, height, 1), alignment=1)
        self._frames[self._next] = data
        self._next = (self._next + 1) % layers

    def metres(self, stride: int) -> np.ndarray:
        """The depth every ``stride`` pixels, in metres, averaged over the layers' known values (0:
        unknown in every layer), as the vertex shader computes it."""
        frames = [frame[::stride, ::stride] for frame in self._frames if frame is not None]
        if len(frames) == 1:
            return frames[0].astype(np.float32) * np.float32(self._metres_per_unit)
        stack = np.stack(frames).astype(np.float32)
        known = stack > 0.0  # False for 0 and NaN
        count = known.sum(axis=0)
        total = np.where(known, stack, 0.0).sum(axis=0)
        return np.where(count > 0, total / np.maximum(count, 1), 0.0).astype(np.float32) * np.float32(
            self._metres_per_unit)

    @property
    def layers(self) -> int:
        return 0 if self._key is None else self._key[2]

    @property
    def size(self) -> tuple[int, int] | None:
        return None if self._key is None else self._key[0]

    def release(self) -> None:
        if self.texture is not None:
            self.texture.release()
        self.texture, self._key, self._frames = None, None, []


class GLRGBDImage(GLPeer):
    """Draws the latest RGB-D frame as a surface: from ``rgbd``, or from ``color`` + ``depth``.

    Intrinsics, first found wins: the ``intrinsics`` port, those the frame (or depth image) carries,
    the ``fx``/``fy``/``cx``/``cy`` attributes. Nothing is drawn until colour and depth have arrived.
    """

    rgbd = InputPort(RGBDFrame | Stamped, doc="colour + depth frames (each carries its depth scale), optionally Stamped")
    color = InputPort(Image | Stamped, doc="colour images registered to the depth images (any non-depth format), "
                      "optionally Stamped")
    depth = InputPort(Image | Stamped, doc="DEPTH16 (units of 1/depth_scale m) or DEPTH32F (m) images, optionally Stamped")
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
    stride = Attribute(int, 0, "one vertex every this many depth pixels (1: every pixel; 0: automatic, from "
                       "the surface's size on screen, see vertex_spacing)", min=0, max=MAX_STRIDE)
    vertex_spacing = Attribute(float, 1.0, "with stride 0: most screen pixels between neighbouring vertices "
                               "(1: about a vertex per pixel, as much detail as the screen shows; 2: about 4x "
                               "fewer triangles)", min=0.1)
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
        self._grids: dict[int, tuple[Hashable, moderngl.Buffer, moderngl.VertexArray, int]] = {}
        """Per stride drawn: what its triangles were chosen for (frame, intrinsics, max_edge), the index
        buffer, its vertex array and how many indices it holds."""
        self._samples = np.zeros((3, 0, 3), np.float32)
        self._layers: LayerCache | None = None
        """The surface as last drawn in each view: repainted when a frame arrives or the view moves."""
        self._version = 0
        """Counts the uploads: part of the layers' key."""
        self._ready = False
        self.shown = ShownInputs()
        """The origins of the (Stamped) frames and images the next frame shows first."""
        self.last_stride = 0
        """Stride of the last view drawn (what the automatic stride chose; tools and benchmarks)."""

    # --- ports (step) -----------------------------------------------------------------------------
    def on_update(self) -> None:
        # Only the newest of each input is drawn; the ones skipped count as dropped on their connections.
        status, intrinsics = self.intrinsics.read_newest()
        if status is NEW_DATA:
            self._port_intrinsics = intrinsics
        status, value = self.rgbd.read_newest()
        if status is NEW_DATA:
            frame = unstamped(value)[0]
            self._color, self._depth = frame.color, (frame.depth, frame.depth_scale)
            self._data_intrinsics = frame.intrinsics
            self.shown.add(self.rgbd.origin)
        status, value = self.color.read_newest()
        if status is NEW_DATA:
            self._color = unstamped(value)[0]
            self.shown.add(self.color.origin)
        status, value = self.depth.read_newest()
        if status is NEW_DATA:
            depth = unstamped(value)[0]
            self.shown.add(self.depth.origin)
            if not depth.format.is_depth:
                raise ImageError(f"{self.name}.depth takes DEPTH16 or DEPTH32F images, got {depth.format.name}")
            self._depth = (depth, self.depth_scale)
            self._data_intrinsics = depth.intrinsics
        if self._depth is not None or self._pinhole is not None:
            # Checked here, where an error is reported as this component's, and every frame: the
            # attributes may change at run time.
            self._pinhole = self.camera_intrinsics()

    @property
    def repaints(self) -> int:
        """How many times the surface was drawn: a frame that brings it nothing new (no new depth or
        colour, the same view) puts back its last drawing instead."""
        return 0 if self._layers is None else self._layers.repaints

    def camera_intrinsics(self) -> tuple[float, float, float, float]:
        """``(fx, fy, cx, cy)`` in use; a clear error when no source gives them."""
        known = self._port_intrinsics or self._data_intrinsics
        if known is not None:
            return known.fx, known.fy, known.cx, known.cy
        if self.fx > 0 and self.fy > 0:
            return self.fx, self.fy, self.cx, self.cy
        raise ImageError(f"{self.name}: no intrinsics: connect the intrinsics port, send images or frames "
                         "that carry intrinsics, or set the attributes fx, fy, cx, cy")

    def camera_pose(self, world: str) -> np.ndarray:
        """4x4 pose of the camera's optical frame in ``world`` (the view's frame)."""
        if self.frame:
            return self.transform_graph.lookup(world, self.frame)
        return se3.make(se3.rpy_to_matrix(*self.rpy), self.xyz)

    # --- GL (render) ------------------------------------------------------------------------------
    def gl_init(self, ctx: moderngl.Context) -> None:
        self._program = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        self._program["depths"] = 0
        self._program["color_image"] = 1
        self._colors = ImageTexture(ctx)
        self._depths = _DepthRing(ctx)
        self._layers = LayerCache(ctx)

    def upload(self, ctx: moderngl.Context) -> None:
        """Texture writes of what arrived since the last frame, and the sparse sample of the new depth
        frame that the automatic stride projects (a few hundred points)."""
        assert self._colors is not None and self._depths is not None and self._program is not None
        if self._color is not None:
            self._colors.write(self._color)
            self._color = None
        if self._depth is not None:
            depth, scale = self._depth
            self._depths.write(depth, scale, self.average)
            if self._pinhole is not None:
                self._samples = sample_points(depth, scale, self._pinhole)
            self._depth = None
        self._version += 1
        self._ready = self._depths.size is not None and self._colors.size is not None

    def _triangles(self, ctx: moderngl.Context, stride: int) -> tuple[moderngl.VertexArray, int]:
        """The vertex array drawing the grid at ``stride`` and its number of indices: the triangles
        kept for the newest depth (:func:`.surface_triangles.kept_triangles`), chosen once per frame and
        stride (each stride keeps its index buffer: the automatic stride moves between a few values)."""
        assert self._depths is not None and self._program is not None and self._pinhole is not None
        key = (self._version, self._pinhole, self.max_edge)
        grid = self._grids.get(stride)
        if grid is None or grid[0] != key:
            indices = kept_triangles(self._depths.metres(stride), stride, self._pinhole, self.max_edge)
            if grid is None or grid[1].size < max(indices.nbytes, 4):
                if grid is not None:
                    grid[2].release()
                    grid[1].release()
                buffer = ctx.buffer(reserve=max(indices.nbytes, 4))
                mesh = ctx.vertex_array(self._program, [], index_buffer=buffer, index_element_size=4)
            else:
                buffer, mesh = grid[1], grid[2]
            buffer.write(indices)
            grid = self._grids[stride] = (key, buffer, mesh, indices.size)
        return grid[2], grid[3]

    def _release_grids(self) -> None:
        for _, indices, mesh, _ in self._grids.values():
            mesh.release()
            indices.release()
        self._grids = {}

    def render(self, ctx: moderngl.Context, view: RenderView) -> None:
        assert self._program is not None, "GLRGBDImage.render() before gl_init()"
        if self._color is not None or self._depth is not None:
            self.upload(ctx)
        if not self._ready or self._pinhole is None:
            return
        assert self._layers is not None
        model_view = view.view @ self.camera_pose(view.frame)
        stride = self.stride or automatic_stride(self._samples, view.projection @ model_view, view.viewport,
                                                 self.vertex_spacing)
        # Everything the drawing depends on: the surface is repainted only when one of them changed.
        key = (self._version, self._pinhole, model_view.tobytes(), view.projection.tobytes(), stride, self.max_edge)
        self._layers.draw(ctx, view, key, partial(self._paint, ctx, model_view, view.projection, stride))
        self.last_stride = stride

    def _paint(self, ctx: moderngl.Context, model_view: np.ndarray, projection: np.ndarray, stride: int) -> None:
        """Draw the surface: the grid at ``stride``, unprojected and filtered in the shaders."""
        assert self._program is not None and self._colors is not None and self._depths is not None
        assert self._depths.texture is not None
        program = self._program
        program["layers"] = self._depths.layers
        program["stride"] = stride
        program["depth_unit"] = self._depths.depth_unit
        program["intrinsics"] = self._pinhole
        uniform(program, "model_view").write(model_view.T.astype("f4").tobytes())
        uniform(program, "projection").write(projection.T.astype("f4").tobytes())
        self._depths.texture.use(0)
        self._colors.use(1)
        mesh, count = self._triangles(ctx, stride)
        if count:
            mesh.render(moderngl.TRIANGLES, vertices=count)

    def gl_release(self) -> None:
        self._release_grids()
        if self._program is not None:
            self._program.release()
        for textures in (self._colors, self._depths):
            if textures is not None:
                textures.release()
        if self._layers is not None:
            self._layers.release()
        self._program = self._colors = self._depths = self._layers = None
        self._ready = False
