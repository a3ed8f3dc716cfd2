"""What a GLEntity is about to draw this frame, handed to its peers' ``preRender`` operation.

The paper's entities let their peers change the colour, pose or shape of what they draw just before
drawing (UpdateColor colours the bowl by the end-effector distance). The entity rebuilds this state
every frame from its attributes and pose input, calls ``preRender(state)`` of each peer that has one,
in file order, then draws exactly what the state says. Nothing a peer does persists by itself: a
peer that stops changing the state leaves the entity as its attributes describe it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from coco_core.errors import AttributeValueError, GeometryError

from .mesh import MeshPart, with_positions


@dataclass
class DrawState:
    """Colour, pose, scale and shape of a GLEntity for the frame being drawn (mutable)."""

    color: tuple[float, float, float, float]
    """RGBA in 0..1, used for the parts that have no colour of their own."""
    pose: np.ndarray
    """4x4 pose of the entity in ``reference`` (its attributes' offset already applied)."""
    scale: np.ndarray
    """x y z scale factors, applied in the entity's own frame."""
    parts: list[MeshPart]
    """What is drawn, in mesh coordinates (scale not applied)."""
    reference: str | None = None
    """Transformation-graph frame ``pose`` is expressed in; None: the view's world frame."""
    override_color: bool = False
    """True: ``color`` also replaces the mesh's own colours and textures."""
    geometry_changed: bool = field(default=False, init=False)

    def set_color(self, color: Sequence[float], override: bool = True) -> None:
        """Draw with ``color`` (RGB or RGBA in 0..1); ``override`` also recolours coloured meshes."""
        values = [float(value) for value in color]
        if len(values) not in (3, 4):
            raise AttributeValueError(f"a colour is r g b or r g b a, got {list(color)}")
        self.color = (values[0], values[1], values[2], values[3] if len(values) == 4 else self.color[3])
        self.override_color = override

    @property
    def vertices(self) -> np.ndarray:
        """(n, 3) float32 positions of every part, concatenated in part order (a copy)."""
        return np.concatenate([part.positions for part in self.parts])

    def set_vertices(self, vertices: np.ndarray, faces: np.ndarray | None = None) -> None:
        """Replace the shape: new positions for the same vertices (split back over the parts), or,
        with ``faces`` ((m, 3) indices), a new mesh altogether (single-part entities only)."""
        vertices = np.asarray(vertices, dtype="f4").reshape(-1, 3)
        if faces is not None:
            if len(self.parts) != 1:
                raise GeometryError(f"new faces need a single-part entity; this one has {len(self.parts)} parts "
                                    "(give positions only, or use a mesh without textures)")
            self.parts = [with_positions(self.parts[0], vertices, faces)]
        else:
            total = sum(len(part.positions) for part in self.parts)
            if len(vertices) != total:
                raise GeometryError(f"expected {total} vertices, got {len(vertices)}")
            ends = np.cumsum([len(part.positions) for part in self.parts])[:-1]
            self.parts = [with_positions(part, chunk) for part, chunk in zip(self.parts, np.split(vertices, ends))]
        self.geometry_changed = True
