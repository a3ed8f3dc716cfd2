"""Meshes on the GPU: trimesh geometry -> float32/uint8 numpy arrays -> one VAO and one draw call.

Shared by GLEntity and GLUrdf. Performance over visual effects: a part carries positions, indices,
optionally per-vertex RGBA colours (bytes, normalised in the shader) and texture coordinates with
its image, and no normals at all: the Phong program derives a flat normal per fragment from screen
derivatives (see :mod:`.phong`). That saves a buffer, the normal computation at load time, and
vertex splitting at sharp edges that smooth normals would need; the meshes worth drawing here
(Baxter: ~412k triangles) are dense enough that flat shading is indistinguishable.

CPU-side work (:func:`load_parts`, :func:`parts_of`, :func:`merge_parts`) needs no OpenGL context
and runs off the render loop (``on_config`` or a loader thread); :class:`GpuMesh` only uploads.
"""

from __future__ import annotations

import io
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from coco_core.errors import GeometryError, MeshLoadError
from coco_core.files import MESH_LIMIT, FileReadError, read_regular_file
from coco_core.transforms.resources import resolve
from coco_core.wire import value_type

if TYPE_CHECKING:
    import moderngl
    import trimesh

PRIMITIVES = ("box", "sphere", "cylinder", "arrow")
"""Shapes that need no file: ``mesh="box"`` etc., sized by a component's ``size`` attribute."""


@value_type
@dataclass(frozen=True, eq=False)
class MeshPart:
    """One drawable piece: what a single draw call needs (compared by identity: arrays are large).

    ``colors`` None means "draw with the uniform colour the owner chooses" (the mesh has none);
    ``texture`` is RGBA rows bottom first (OpenGL's texture origin), with ``uvs``.
    """

    positions: np.ndarray
    """(n, 3) float32."""
    indices: np.ndarray
    """(m, 3) uint32 triangles."""
    colors: np.ndarray | None = None
    """(n, 4) uint8 RGBA per vertex, or None."""
    uvs: np.ndarray | None = None
    """(n, 2) float32 texture coordinates, present with ``texture``."""
    texture: np.ndarray | None = None
    """(h, w, 4) uint8 RGBA image, bottom row first."""

    @property
    def triangles(self) -> int:
        return len(self.indices)

    def arrays(self) -> dict[str, np.ndarray]:
        """The arrays it holds (those that are not None), by field name."""
        return {name: array for name, array in (("positions", self.positions), ("indices", self.indices),
                                                ("colors", self.colors), ("uvs", self.uvs),
                                                ("texture", self.texture)) if array is not None}

    @property
    def nbytes(self) -> int:
        """The memory its arrays hold."""
        return sum(array.nbytes for array in self.arrays().values())


def primitive(kind: str, size: Sequence[float] = ()) -> trimesh.Trimesh:
    """A box (``size`` = x y z extents, default 1 1 1), sphere (radius, default 0.5) or cylinder
    (radius length along z, default 0.5 1), centred on the origin; or an arrow (shaft radius and
    length, default 0.02 1) from the origin along +z, its tip at ``length``: scaled along z it shows
    a vector's magnitude (UpdateVector), so it starts where the vector applies."""
    import trimesh

    size = [float(value) for value in size]
    expected = {"box": (3, "x y z extents"), "sphere": (1, "a radius"), "cylinder": (2, "radius length"),
                "arrow": (2, "shaft radius and length")}
    if kind not in expected:
        raise MeshLoadError(f"unknown primitive {kind!r}; valid: {', '.join(PRIMITIVES)}")
    count, meaning = expected[kind]
    if size and (len(size) != count or min(size) <= 0):
        raise MeshLoadError(f"a {kind} takes size = {meaning} ({count} positive number"
                            f"{'s' if count > 1 else ''}), got {size}")
    if kind == "box":
        return trimesh.creation.box(extents=size or (1.0, 1.0, 1.0))
    if kind == "sphere":
        return trimesh.creation.icosphere(subdivisions=3, radius=size[0] if size else 0.5)
    if kind == "arrow":
        return _arrow(*(size or (0.02, 1.0)))
    radius, length = size or (0.5, 1.0)
    return trimesh.creation.cylinder(radius=radius, height=length, sections=48)


def _arrow(radius: float, length: float) -> trimesh.Trimesh:
    """A shaft of ``radius`` and a cone twice as wide, from z = 0 to the tip at z = ``length``; the
    head is a fifth of the length (a short arrow keeps its proportions when scaled along z)."""
    import trimesh

    head = length / 5
    segment = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, length - head]])
    shaft = trimesh.creation.cylinder(radius=radius, segment=segment, sections=24)
    cone = trimesh.creation.cone(radius=2 * radius, height=head, sections=24)
    cone.apply_translation([0.0, 0.0, length - head])
    return trimesh.Trimesh(np.vstack([shaft.vertices, cone.vertices]),
                           np.vstack([shaft.faces, cone.faces + len(shaft.vertices)]), process=False)


def load_geometry(source: str | Path, relative_to: str | Path | None = None) -> Any:
    """What trimesh reads from a file, ``file://`` or ``package://`` URL (a Trimesh or a Scene), with
    an error naming the file and the formats trimesh can read when it cannot."""
    import trimesh

    path = resolve(source, relative_to)  # a clear ResourceNotFoundError for a missing file
    try:
        data = read_regular_file(path, MESH_LIMIT, "mesh")
    except FileReadError as error:
        raise MeshLoadError(str(error)) from None
    try:
        # From the bytes read (a regular file, bounded); the resolver finds the files the mesh names
        # (an OBJ's materials, a COLLADA's textures) next to it.
        return trimesh.load(io.BytesIO(data), file_type=path.suffix.lstrip(".").lower(),
                            resolver=trimesh.resolvers.FilePathResolver(str(path)))
    except Exception as error:  # trimesh raises ValueError, KeyError, XML errors ... per format
        formats = ", ".join(sorted(trimesh.available_formats()))
        raise MeshLoadError(f"cannot load mesh {path}: {type(error).__name__}: {error} "
                            f"(trimesh reads: {formats})") from None


def load_parts(source: str | Path, relative_to: str | Path | None = None, transform: np.ndarray | None = None,
               scale: Sequence[float] | None = None, color: Sequence[float] | None = None,
               subdivide: int = 0, keep: float = 1.0) -> list[MeshPart]:
    """The parts of a mesh file: :func:`load_geometry` then :func:`parts_of`."""
    return parts_of(load_geometry(source, relative_to), transform, scale, color, subdivide, keep,
                    label=str(source))


def parts_of(geometry: Any, transform: np.ndarray | None = None, scale: Sequence[float] | None = None,
             color: Sequence[float] | None = None, subdivide: int = 0, keep: float = 1.0,
             label: str = "mesh") -> list[MeshPart]:
    """Every triangle mesh of a Trimesh or Scene (scene graph transforms applied) as parts.

    Vertices become ``transform @ diag(scale) @ v``. A mesh keeps its own colour (vertex/face
    colours, or its material's colour) and texture; one without colour gets ``color`` (RGB or RGBA in
    0..1) baked in when given, else none (the owner's uniform colour). ``subdivide`` splits each
    triangle into four that many times (trimesh's ``subdivide``, uvs and vertex colours follow);
    ``keep`` < 1 simplifies each mesh of one colour to about that fraction of its triangles
    (:func:`decimate`; textured and multi-coloured meshes are kept whole).
    """
    import trimesh

    if isinstance(geometry, trimesh.Scene):
        meshes = [mesh for mesh in geometry.dump(concatenate=False) if isinstance(mesh, trimesh.Trimesh)]
    elif isinstance(geometry, trimesh.Trimesh):
        meshes = [geometry]
    else:
        raise MeshLoadError(f"{label} holds no triangles (trimesh read a {type(geometry).__name__})")
    meshes = [mesh for mesh in meshes if len(mesh.faces)]
    if not meshes:
        raise MeshLoadError(f"{label} holds no triangles")
    matrix = np.eye(4) if transform is None else np.asarray(transform, dtype=float)
    if scale is not None:
        matrix = matrix @ np.diag([*np.broadcast_to(np.asarray(scale, dtype=float), 3), 1.0])
    parts = []
    for mesh in meshes:
        for _ in range(subdivide):
            mesh = mesh.subdivide()
        parts.append(_part(mesh, matrix, color, keep))
    return parts


def _part(mesh: trimesh.Trimesh, matrix: np.ndarray, fallback: Sequence[float] | None, keep: float) -> MeshPart:
    positions = mesh.vertices @ matrix[:3, :3].T + matrix[:3, 3]
    count = len(positions)
    from trimesh.visual import ColorVisuals, TextureVisuals

    colors: np.ndarray | None = None
    uvs: np.ndarray | None = None
    texture: np.ndarray | None = None
    visual = mesh.visual
    faces: np.ndarray = np.asarray(mesh.faces)
    if isinstance(visual, TextureVisuals):
        material = visual.material
        image = getattr(material, "baseColorTexture", None) or getattr(material, "image", None)
        if image is not None and visual.uv is not None and len(visual.uv) == count:
            uvs = np.ascontiguousarray(visual.uv, dtype="f4")
            texture = np.ascontiguousarray(np.asarray(image.convert("RGBA"))[::-1])
        else:
            colors = np.tile(np.asarray(material.main_color, dtype="u1"), (count, 1))
    elif isinstance(visual, ColorVisuals) and visual.kind == "vertex":
        colors = np.ascontiguousarray(visual.vertex_colors, dtype="u1")
    elif isinstance(visual, ColorVisuals) and visual.kind == "face":  # one vertex per face corner, so that no colour is averaged across faces
        positions, faces = positions[faces].reshape(-1, 3), np.arange(3 * len(faces)).reshape(-1, 3)
        colors = np.repeat(np.asarray(visual.face_colors, dtype="u1"), 3, axis=0)
    if np.linalg.det(matrix[:3, :3]) < 0.0:  # mirrored: keep the triangles wound outwards (for culling)
        faces = faces[:, ::-1]
    if keep < 1.0 and texture is None and (colors is None or (colors == colors[0]).all()):
        positions, faces = decimate(positions, faces, keep)
        if colors is not None:
            colors = np.tile(colors[0], (len(positions), 1))
    if colors is None and texture is None and fallback is not None:
        colors = np.tile(rgba_bytes(fallback), (len(positions), 1))
    return weld(MeshPart(np.ascontiguousarray(positions, dtype="f4"), np.ascontiguousarray(faces, dtype="u4"),
                         colors, uvs, texture))


def weld(part: MeshPart) -> MeshPart:
    """``part`` with its identical vertices (same position, colour and texture coordinates) shared.

    Why: mesh files often repeat a vertex for every face around it (DAE exports; face colours become
    one vertex per face corner), and a renderer shades each distinct index of a draw once; on a CPU
    renderer that vertex work is most of a frame (Baxter's meshes: 541k vertices, 236k distinct).
    """
    columns = [part.positions.view("u4")]  # bit patterns: exact equality, no float rounding
    columns += [] if part.colors is None else [part.colors.astype("u4")]
    columns += [] if part.uvs is None else [part.uvs.view("u4")]
    _, first, inverse = np.unique(np.concatenate(columns, axis=1), axis=0, return_index=True, return_inverse=True)
    if len(first) == len(part.positions):
        return part
    order = np.argsort(first)  # distinct vertices in the file's order: the index buffer keeps its locality
    rank = np.empty(len(first), "u4")
    rank[order] = np.arange(len(first), dtype="u4")
    kept = first[order]
    return MeshPart(part.positions[kept], np.ascontiguousarray(rank[inverse.reshape(-1)][part.indices]),
                    None if part.colors is None else part.colors[kept],
                    None if part.uvs is None else part.uvs[kept], part.texture)


def decimate(positions: np.ndarray, faces: np.ndarray, keep: float) -> tuple[np.ndarray, np.ndarray]:
    """About ``keep`` of the triangles, by quadric edge collapses (fast-simplification).

    Why: a CPU renderer's cost is per triangle, and most of a detailed CAD mesh's triangles cover less
    than a pixel at display distance. Vertices are first welded by position (mesh files often repeat
    them per face, which leaves no edge to collapse).
    """
    try:
        import fast_simplification
    except ImportError:
        raise MeshLoadError("simplifying meshes needs fast-simplification (pip install fast-simplification)") from None
    welded, inverse = np.unique(np.asarray(positions, dtype=float), axis=0, return_inverse=True)
    faces = inverse.reshape(-1)[faces]
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])]
    if len(faces) < 8:
        return welded, faces
    points, simplified = fast_simplification.simplify(welded, faces, target_reduction=1.0 - keep)
    return (points, simplified) if len(simplified) else (welded, faces)  # a tiny mesh stays whole


def color_problem(value: Sequence[float]) -> str | None:
    """Why ``value`` is not an r g b [a] colour in 0..1 (an attribute ``check``), or None."""
    if len(value) not in (3, 4) or min(value, default=0.0) < 0.0 or max(value, default=0.0) > 1.0:
        return f"expected r g b or r g b a in 0..1, got {list(value)}"
    return None


def rgba_bytes(color: Sequence[float]) -> np.ndarray:
    """RGB or RGBA in 0..1 -> 4 uint8 (alpha 1 when not given)."""
    values = list(color) + [1.0] * (4 - len(color))
    return np.clip(np.round(np.asarray(values[:4], dtype=float) * 255.0), 0, 255).astype("u1")


def merge_parts(parts: Sequence[MeshPart]) -> list[MeshPart]:
    """As few parts as possible for the same picture: every part with per-vertex colours in one,
    every part without colour in another; textured parts stay alone (one texture per draw)."""
    coloured = [part for part in parts if part.texture is None and part.colors is not None]
    plain = [part for part in parts if part.texture is None and part.colors is None]
    merged = [part for part in parts if part.texture is not None]
    for group in (coloured, plain):
        if len(group) == 1:
            merged.append(group[0])
        elif group:
            offsets = np.cumsum([0] + [len(part.positions) for part in group[:-1]]).astype("u4")
            merged.append(MeshPart(
                np.concatenate([part.positions for part in group]),
                np.concatenate([part.indices + offset for part, offset in zip(group, offsets)]),
                np.concatenate([part.colors for part in group]) if group[0].colors is not None else None))
    return merged


def with_positions(part: MeshPart, positions: np.ndarray, indices: np.ndarray | None = None) -> MeshPart:
    """``part`` with new vertex positions (same count, unless new ``indices`` come with them)."""
    positions = np.ascontiguousarray(positions, dtype="f4").reshape(-1, 3)
    if indices is None:
        if len(positions) != len(part.positions):
            raise GeometryError(f"expected {len(part.positions)} vertices (or new faces with them), "
                                f"got {len(positions)}")
        return replace(part, positions=positions)
    indices = np.ascontiguousarray(indices, dtype="u4").reshape(-1, 3)
    if len(indices) and int(indices.max()) >= len(positions):
        raise GeometryError(f"a face uses vertex {int(indices.max())} of {len(positions)}")
    keep = len(positions) == len(part.positions)
    return MeshPart(positions, indices, part.colors if keep else None, part.uvs if keep else None,
                    part.texture if keep else None)


class GpuMesh:
    """One part on the GPU: vertex buffers, an index buffer, its texture, and a VAO for ``program``."""

    def __init__(self, ctx: moderngl.Context, program: moderngl.Program, part: MeshPart) -> None:
        import moderngl

        self.part = part
        self._positions = ctx.buffer(part.positions.tobytes())
        self._indices = ctx.buffer(part.indices.tobytes())
        self._buffers = [self._positions, self._indices]
        content: list[tuple[Any, ...]] = [(self._positions, "3f", "in_position")]
        if part.colors is not None:
            colors = ctx.buffer(part.colors.tobytes())
            self._buffers.append(colors)
            content.append((colors, "4f1", "in_color"))
        self.texture: moderngl.Texture | None = None
        if part.texture is not None and part.uvs is not None:
            uvs = ctx.buffer(part.uvs.tobytes())
            self._buffers.append(uvs)
            content.append((uvs, "2f", "in_uv"))
            height, width = part.texture.shape[:2]
            self.texture = ctx.texture((width, height), 4, part.texture.tobytes())
            self.texture.build_mipmaps()
            self.texture.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        self.vao = ctx.vertex_array(program, content, self._indices, index_element_size=4)

    @property
    def has_colors(self) -> bool:
        return self.part.colors is not None

    def write_positions(self, positions: np.ndarray) -> None:
        """Replace the vertex positions in place (same vertex count), e.g. after a preRender."""
        self._positions.orphan()
        self._positions.write(np.ascontiguousarray(positions, dtype="f4").tobytes())

    def draw(self) -> None:
        if self.texture is not None:
            self.texture.use(0)
        self.vao.render()

    def release(self) -> None:
        self.vao.release()
        if self.texture is not None:
            self.texture.release()
        for buffer in self._buffers:
            buffer.release()
