"""TriangleMesh: an organised RGB-D mesh laid out in one preallocated buffer, and its PLY export.

A mesh travels through a pooled port (:class:`coco_core.PooledOutputPort`): the slot's one uint8
array holds, at fixed offsets, room for the most vertices and triangles a grid can have (vertex
positions, normals and colours, triangle indices), and the slot's ``stamp`` holds a
:class:`MeshInfo` with the counts actually used. A reader gets numpy views into the slot, no copy,
and a steady stream of frames of one size allocates nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from coco_core.errors import WrongTypeError
from coco_core.stamps import Stamp
from coco_core.wire import value_type


@value_type
@dataclass(frozen=True)
class MeshLayout:
    """Offsets in the slot buffer for a ``rows`` x ``cols`` vertex grid."""

    rows: int
    cols: int

    @property
    def max_vertices(self) -> int:
        return self.rows * self.cols

    @property
    def max_triangles(self) -> int:
        return 2 * max(self.rows - 1, 0) * max(self.cols - 1, 0)

    @property
    def offsets(self) -> tuple[int, int, int, int, int]:
        """Byte offsets of vertices, normals, colours, triangles, and the total size."""
        n, m = self.max_vertices, self.max_triangles
        vertices = 0
        normals = vertices + 12 * n
        triangles = normals + 12 * n          # 4-byte aligned before the uint8 colours
        colors = triangles + 12 * m
        return vertices, normals, colors, triangles, colors + 3 * n


@value_type
@dataclass(frozen=True)
class MeshInfo:
    """What a mesh slot holds: counts, grid, the source frame's stamps and camera frame."""

    layout: MeshLayout
    vertex_count: int
    triangle_count: int
    stamp: Stamp | None
    image_stamp: float | None
    frame_id: str


class TriangleMesh:
    """Views of a mesh: ``vertices`` (Nx3 float32, metres, camera frame), ``normals`` (Nx3 float32,
    unit, facing the camera), ``colors`` (Nx3 uint8 RGB), ``triangles`` (Mx3 int32, counter-clockwise
    seen from the camera)."""

    def __init__(self, buffer: np.ndarray, info: MeshInfo) -> None:
        self.info = info
        v, n, c, t, _ = info.layout.offsets
        count, faces = info.vertex_count, info.triangle_count
        self.vertices = buffer[v:v + 12 * count].view(np.float32).reshape(count, 3)
        self.normals = buffer[n:n + 12 * count].view(np.float32).reshape(count, 3)
        self.colors = buffer[c:c + 3 * count].reshape(count, 3)
        self.triangles = buffer[t:t + 12 * faces].view(np.int32).reshape(faces, 3)

    @classmethod
    def from_slot(cls, slot) -> TriangleMesh:  # noqa: ANN001 - a coco_core Slot
        """The mesh a MeshReconstructor published in ``slot`` (valid while the slot is held)."""
        if not isinstance(slot.stamp, MeshInfo):
            raise WrongTypeError(f"slot {slot!r} does not hold a mesh (its stamp is {type(slot.stamp).__name__})")
        return cls(slot.array, slot.stamp)

    @staticmethod
    def writable(buffer: np.ndarray, layout: MeshLayout) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Full-size views (max counts) of a slot buffer, for the writer to fill."""
        v, n, c, t, _ = layout.offsets
        count, faces = layout.max_vertices, layout.max_triangles
        return (buffer[v:v + 12 * count].view(np.float32).reshape(count, 3),
                buffer[n:n + 12 * count].view(np.float32).reshape(count, 3),
                buffer[c:c + 3 * count].reshape(count, 3),
                buffer[t:t + 12 * faces].view(np.int32).reshape(faces, 3))


def write_ply(path: str | Path, vertices: np.ndarray, triangles: np.ndarray, normals: np.ndarray | None = None,
              colors: np.ndarray | None = None) -> Path:
    """A binary little-endian PLY (what MeshLab, Open3D, trimesh and Blender read)."""
    path = Path(path)
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if normals is not None:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    if colors is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    vertex = np.empty(len(vertices), dtype=fields)
    vertex["x"], vertex["y"], vertex["z"] = vertices.T
    if normals is not None:
        vertex["nx"], vertex["ny"], vertex["nz"] = normals.T
    if colors is not None:
        vertex["red"], vertex["green"], vertex["blue"] = colors.T
    face = np.empty(len(triangles), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    face["n"], face["v"] = 3, triangles
    names = {"<f4": "float", "u1": "uchar"}
    header = ["ply", "format binary_little_endian 1.0", "comment written by coco_mr_vision",
              f"element vertex {len(vertices)}", *(f"property {names[t]} {n}" for n, t in fields),
              f"element face {len(triangles)}", "property list uchar int vertex_indices", "end_header", ""]
    with open(path, "wb") as stream:
        stream.write("\n".join(header).encode("ascii"))
        stream.write(vertex.tobytes())
        stream.write(face.tobytes())
    return path
