"""GLEntity: one mesh (a file trimesh reads, or a primitive) drawn at a pose, lit by Phong.

Where it is drawn, every frame: ``reference @ offset @ scale``, where

- ``offset`` is the pose of the ``position`` / ``rpy`` (or ``quaternion``) attributes;
- ``reference`` is the last value of the ``pose`` input when one arrived (a FramePose, a
  TransformSample or a 4x4 matrix in the world frame), else ``lookup(world, frame)`` when the
  ``frame`` attribute names a transformation-graph frame, else the identity (the world frame).
  FramePoses and TransformSamples expressed in another frame than the view's world frame are
  brought into it through the graph.

Before drawing, the entity runs its peers (``manages_peers``: their ``on_update`` first, so they see
this frame's inputs), then calls the ``preRender`` operation of each peer that has one with a
:class:`~.draw_state.DrawState`: colour, pose, scale and shape can all be changed (UpdateColor).

Loading (file, ``subdivide``, ``simplify``) happens in ``on_config``, before the first frame and off
the render loop; ``gl_init`` uploads. A bad path or format fails ``on_config`` with the file named.
A shape changed by a preRender peer is uploaded at the next render: in place when only the vertex
positions changed, as new buffers when the topology did.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Callable

import numpy as np

from coco_core.attributes import Attribute
from coco_core.errors import ExtrapolationError, GeometryError
from coco_core.policy import NEW_DATA
from coco_core.ports import InputPort
from coco_core.transforms import se3
from coco_core.transforms.graph import TransformError

from .draw_state import DrawState
from .mesh import PRIMITIVES, GpuMesh, MeshPart, color_problem, load_parts, merge_parts, parts_of, primitive
from .phong import PhongPeer
from .poses import reference_of
from .shown import ShownInputs

log = logging.getLogger("coco")

if TYPE_CHECKING:
    import moderngl

    from .view import RenderView


def _length_check(*lengths: int) -> Callable[[list[float]], str | None]:
    def check(value: list[float]) -> str | None:
        if len(value) not in lengths:
            return f"expected {' or '.join(map(str, lengths))} numbers, got {len(value)}: {value}"
        return None
    return check


def offset_pose(position: list[float], rpy: list[float], quaternion: list[float]) -> np.ndarray:
    """4x4 pose of ``position`` and either ``rpy`` (URDF's fixed axes) or ``quaternion`` (x y z w)."""
    if quaternion and any(rpy):
        raise GeometryError("give the orientation as rpy or as quaternion, not both")
    rotation = se3.quaternion_to_matrix(quaternion) if quaternion else se3.rpy_to_matrix(*rpy)
    return se3.make(rotation, position)


class GLEntity(PhongPeer):
    """A mesh or primitive at a pose, with colour, texture, Phong lighting and preRender peers."""

    manages_peers = True

    mesh = Attribute(str, "box", "mesh file or package:// URL (OBJ, STL, PLY, DAE, GLB ...), or a primitive: "
                     + ", ".join(PRIMITIVES))
    size: Attribute[list[float]] = Attribute(list[float], [], "primitive size: box x y z, sphere radius, cylinder radius length "
                     "(empty: unit box, sphere of radius 0.5, cylinder 0.5 x 1)")
    color = Attribute(list[float], [0.7, 0.7, 0.7], "r g b [a] in 0..1 for meshes without colour",
                      check=color_problem)
    position = Attribute(list[float], [0.0, 0.0, 0.0], "x y z offset in the reference frame",
                         check=_length_check(3))
    rpy = Attribute(list[float], [0.0, 0.0, 0.0], "roll pitch yaw (rad, URDF's fixed axes)", check=_length_check(3))
    quaternion: Attribute[list[float]] = Attribute(list[float], [], "x y z w, instead of rpy", check=_length_check(0, 4))
    scale = Attribute(list[float], [1.0], "uniform or x y z scale", check=_length_check(1, 3))
    frame = Attribute(str, "", "transformation-graph frame the entity is attached to (empty: the world frame)")
    subdivide = Attribute(int, 0, "times each triangle is split in four at load", min=0, max=6)
    simplify = Attribute(float, 1.0, "fraction of the triangles kept at load (quadric decimation of each "
                         "single-coloured mesh; 1: all)", min=0.01, max=1.0)

    pose = InputPort(object, doc="pose of the entity: FramePose, TransformSample (optionally Stamped) or 4x4 "
                     "in the view's world frame; replaces the frame attribute once a value arrived")

    def on_config(self) -> None:
        offset_pose(self.position, self.rpy, self.quaternion)  # fail now on both rpy and quaternion
        if self.mesh in PRIMITIVES:
            parts = parts_of(primitive(self.mesh, self.size), subdivide=self.subdivide, keep=self.simplify,
                             label=self.mesh)
        else:
            parts = load_parts(self.mesh, subdivide=self.subdivide, keep=self.simplify)
        self.parts: list[MeshPart] = merge_parts(parts)
        self._pre_render = [peer.operations["preRender"].function for peer in self.peers
                            if "preRender" in peer.operations]
        self._state: DrawState | None = None
        self._received: tuple[str | None, np.ndarray] | None = None
        self.shown = ShownInputs()
        """The origins of the poses the next frame shows first (a stamped pose input, or the graph's)."""
        self._meshes: list[GpuMesh] = []
        self._drawn: list[MeshPart] = []
        self._unplaced = False
        """Whether the graph could not place the entity at the last frame (warned once until it can)."""

    def gl_init(self, ctx: moderngl.Context) -> None:
        super().gl_init(ctx)
        self._upload(ctx, self.parts)

    def on_update(self) -> None:
        for peer in self.peers:
            peer.step()
        status, value = self.pose.read_newest()  # a display shows the newest pose; skipped ones count as dropped
        if status is NEW_DATA:
            self._received = reference_of(value)  # a bad value raises here once; the last good one stays
            self.shown.add(self.pose.origin)
        state = self.base_state()
        for pre_render in self._pre_render:
            pre_render(state)
        self._state = state

    def base_state(self) -> DrawState:
        """This frame's state before the peers change it: attributes and the last pose received."""
        reference: str | None = self.frame or None
        pose = offset_pose(self.position, self.rpy, self.quaternion)
        if self._received is not None:
            reference, received = self._received
            pose = received @ pose
        color = tuple(self.color) + ((1.0,) if len(self.color) == 3 else ())
        scale = np.broadcast_to(np.asarray(self.scale, dtype=float), 3).copy()
        return DrawState(color, pose, scale, list(self.parts), reference)

    def render(self, ctx: moderngl.Context, view: RenderView) -> None:
        state = self._state or self.base_state()
        if state.parts != self._drawn:
            self._upload(ctx, state.parts)
        model = state.pose @ np.diag([*state.scale, 1.0])
        if state.reference is not None and state.reference != view.frame:
            graph = self.transform_graph
            try:
                model = graph.lookup(view.frame, state.reference) @ model
            except (TransformError, ExtrapolationError) as error:  # no path yet, or an edge on it without a
                # value yet: its frame comes with its first pose, not drawn until then
                if not self._unplaced:
                    log.warning("%s: not drawn until the transformation graph can place %s in %s (%s)",
                                self.name, state.reference, view.frame, error)
                    self._unplaced = True
                return
            self._unplaced = False
            self.shown.add_graph(graph.query(view.frame, state.reference).dependencies)
        model_view = view.view @ model
        self.begin(ctx, view)
        for mesh in self._meshes:
            self.draw(mesh, model_view, state.color, state.override_color)

    def _upload(self, ctx: moderngl.Context, parts: list[MeshPart]) -> None:
        """Bring the GPU meshes to ``parts``: positions are rewritten in place when only they changed."""
        if len(parts) == len(self._meshes) and all(
                new.indices is mesh.part.indices and len(new.positions) == len(mesh.part.positions)
                for new, mesh in zip(parts, self._meshes)):
            for new, mesh in zip(parts, self._meshes):
                if new.positions is not mesh.part.positions:
                    mesh.write_positions(new.positions)
                    mesh.part = new
        else:
            self._release_meshes()
            self._meshes = [GpuMesh(ctx, self.program, part) for part in parts]
        self._drawn = list(parts)

    def _release_meshes(self) -> None:
        for mesh in self._meshes:
            mesh.release()
        self._meshes = []

    def gl_release(self) -> None:
        self._release_meshes()
        self._drawn = []
        super().gl_release()
