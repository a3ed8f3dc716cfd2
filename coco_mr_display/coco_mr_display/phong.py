"""The one lighting program of the mesh peers: Phong, flat normals, uniform/vertex/texture colour.

One directional light fixed to the eye (a headlight, tilted up and to the right by default so faces
facing different ways get different shades) lights every mesh; its direction and the ambient,
diffuse and specular weights are attributes of :class:`PhongPeer`, the base of GLEntity and GLUrdf.

The normal is the face normal, derived per fragment from screen-space derivatives of the eye-space
position: the meshes need no normal buffer (see :mod:`.mesh`) and it always faces the viewer, so
meshes with inconsistent winding (common in DAE files) are lit right on both sides. Back-face culling
is therefore only a speed option (``cull_back_faces``), for closed meshes wound outwards.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np

from coco_core.attributes import Attribute

from .mesh import GpuMesh
from .peer import GLPeer
from .uniforms import uniform

if TYPE_CHECKING:
    import moderngl

    from .view import RenderView

VERTEX_SHADER = """
#version 330
uniform mat4 u_projection;
uniform mat4 u_model_view;
in vec3 in_position;
in vec4 in_color;
in vec2 in_uv;
out vec3 v_eye;
out vec4 v_color;
out vec2 v_uv;
void main() {
    vec4 eye = u_model_view * vec4(in_position, 1.0);
    v_eye = eye.xyz;
    v_color = in_color;
    v_uv = in_uv;
    gl_Position = u_projection * eye;
}
"""

FRAGMENT_SHADER = """
#version 330
uniform vec4 u_color;
uniform int u_source;  // 0: u_color, 1: vertex colour, 2: texture
uniform sampler2D u_texture;
uniform vec3 u_light;  // unit direction towards the light, eye coordinates
uniform vec4 u_weights;  // ambient, diffuse, specular, shininess
in vec3 v_eye;
in vec4 v_color;
in vec2 v_uv;
out vec4 f_color;
void main() {
    vec4 base = u_source == 2 ? texture(u_texture, v_uv) : (u_source == 1 ? v_color : u_color);
    vec3 normal = normalize(cross(dFdx(v_eye), dFdy(v_eye)));
    vec3 to_eye = normalize(-v_eye);
    float diffuse = max(dot(normal, u_light), 0.0);
    float specular = diffuse > 0.0 ? pow(max(dot(reflect(-u_light, normal), to_eye), 0.0), u_weights.w) : 0.0;
    vec3 lit = base.rgb * (u_weights.x + u_weights.y * diffuse) + vec3(u_weights.z * specular);
    f_color = vec4(min(lit, vec3(1.0)), base.a);
}
"""

UNIFORM, VERTEX, TEXTURE = 0, 1, 2
"""Where a draw takes its colour from (``u_source``)."""


def _unit(vector: list[float]) -> str | None:
    if len(vector) != 3 or not any(vector):
        return f"expected a non-zero x y z direction, got {vector}"
    return None


class PhongPeer(GLPeer):
    """A drawing peer lit by :data:`FRAGMENT_SHADER`'s headlight; owns the program."""

    light = Attribute(list[float], [0.3, 0.5, 1.0], "direction towards the light in eye coordinates "
                      "(x right, y up, z towards the viewer)", check=_unit)
    ambient = Attribute(float, 0.35, "ambient weight", min=0.0)
    diffuse = Attribute(float, 0.65, "diffuse weight", min=0.0)
    specular = Attribute(float, 0.15, "specular weight (white highlights)", min=0.0)
    shininess = Attribute(float, 32.0, "specular exponent", min=1.0)
    cull_back_faces = Attribute(bool, False, "skip triangles facing away (closed, outward-wound meshes only: "
                                "about halves the cost of big meshes on a CPU renderer)")

    def gl_init(self, ctx: moderngl.Context) -> None:
        self._ctx = ctx
        self.program = ctx.program(vertex_shader=VERTEX_SHADER, fragment_shader=FRAGMENT_SHADER)
        self.program["u_texture"] = 0
        self._model_view = uniform(self.program, "u_model_view")
        self._color = uniform(self.program, "u_color")
        self._source = uniform(self.program, "u_source")

    def begin(self, ctx: moderngl.Context, view: RenderView) -> None:
        """Per-view state: viewport, depth test, face culling, projection and light."""
        import moderngl

        ctx.viewport = view.viewport
        ctx.enable(moderngl.DEPTH_TEST)
        if self.cull_back_faces:
            ctx.cull_face = "back"
            ctx.enable(moderngl.CULL_FACE)
        else:
            ctx.disable(moderngl.CULL_FACE)
        uniform(self.program, "u_projection").write(np.asarray(view.projection, dtype="f4").T.tobytes())
        light = np.asarray(self.light, dtype=float)
        self.program["u_light"] = tuple(light / np.linalg.norm(light))
        self.program["u_weights"] = (self.ambient, self.diffuse, self.specular, self.shininess)

    def draw(self, mesh: GpuMesh, model_view: np.ndarray, color: Sequence[float], override: bool = False) -> None:
        """Draw one part at ``model_view`` (4x4, mesh -> eye); ``color`` (RGBA in 0..1) is used when
        the part has none of its own, or for every part when ``override``."""
        if self.cull_back_faces:  # a mirroring scale turns counter-clockwise triangles clockwise
            self._ctx.front_face = "cw" if np.linalg.det(model_view[:3, :3]) < 0.0 else "ccw"
        self._model_view.write(np.asarray(model_view, dtype="f4").T.tobytes())
        if override or (mesh.texture is None and not mesh.has_colors):
            self._source.value = UNIFORM
            self._color.value = tuple(color)
        else:
            self._source.value = TEXTURE if mesh.texture is not None else VERTEX
        mesh.draw()

    def gl_release(self) -> None:
        program: moderngl.Program | None = getattr(self, "program", None)
        if program is not None:
            program.release()
            del self.program
