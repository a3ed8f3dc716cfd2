"""UpdateVector: a peer of a GLEntity that points it along a vector and stretches it to its length.

A haptic display shows the force on the device as an arrow at the proxy (the paper's palpation
view): the entity (``mesh="arrow"``, which runs from its origin along +z) is placed by its own
``pose`` input (the proxy), and this peer turns its z axis along the newest ``vector`` (a force, a
velocity: 3 numbers or a ``Stamped`` one, in the same frame as the entity's pose) and scales it
along z by ``scale`` times the vector's norm, so the arrow's length reads as the magnitude. Until a
vector arrives, and while it is shorter than ``min_norm`` (no contact: zero force), the entity is
hidden (drawn at zero scale): an arrow is only seen while there is something to show. A vector with
a NaN or infinite component, or not of 3 numbers, is refused (the last good one stays) and counted
in the profile.
"""

from __future__ import annotations

import math

import numpy as np

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import WrongTypeError
from coco_core.operations import operation
from coco_core.policy import NEW_DATA
from coco_core.ports import InputPort
from coco_core.stamps import Stamped, unstamped
from coco_core.transforms import se3

from .draw_state import DrawState
from .shown import ShownInputs

_Z = np.array([0.0, 0.0, 1.0])


def rotation_to(direction: np.ndarray) -> np.ndarray:
    """3x3 rotation taking +z onto the unit ``direction`` (about the axis normal to both)."""
    cosine = float(np.clip(direction @ _Z, -1.0, 1.0))
    axis = np.cross(_Z, direction)
    norm = float(np.linalg.norm(axis))
    if norm < 1e-12:  # along z already, or opposite it: any normal axis turns it by pi
        return np.eye(3) if cosine > 0 else se3.axis_angle((1.0, 0.0, 0.0), math.pi)
    return se3.axis_angle(axis / norm, math.atan2(norm, cosine))


class UpdateVector(Component):
    """Peer of a GLEntity: turns its z axis along ``vector`` and scales it by the vector's length."""

    scale = Attribute(float, 0.01, "length along z per unit of the vector (m per N for a force)", min=0.0)
    min_norm = Attribute(float, 1e-3, "vectors shorter than this hide the entity (e.g. zero force out of "
                         "contact); it is hidden until a vector arrives", min=0.0)

    vector = InputPort(tuple | list | np.ndarray | Stamped,
                       doc="x y z in the frame of the entity's pose (tuple, array or Stamped one)")

    def on_config(self) -> None:
        self.current: np.ndarray | None = None
        """The vector preRender applies; None until one arrived."""
        self.shown = ShownInputs()
        """The origin of the vector the next frame shows first (its GLManager stamps the frame with it)."""

    def on_update(self) -> None:
        status, value = self.vector.read_newest()  # a display shows the newest; skipped ones count as dropped
        if status is not NEW_DATA:
            return
        vector, stamp = unstamped(value)[0], self.vector.origin
        try:
            values = np.asarray(vector, dtype=float).reshape(-1)
            if values.shape != (3,) or not np.isfinite(values).all():
                raise WrongTypeError(f"a vector is 3 finite numbers, got {vector!r}")
        except (TypeError, ValueError) as error:  # WrongTypeError is a TypeError
            self.record_refusal("a vector", error)
            return
        self.current = values
        self.shown.add(stamp)
        if stamp is not None:
            self.record_latency(stamp)

    @operation(name="preRender")
    def pre_render(self, state: DrawState) -> None:
        """Point the entity's z axis along the current vector and stretch it to ``scale`` x its norm."""
        norm = 0.0 if self.current is None else float(np.linalg.norm(self.current))
        if self.current is None or norm < self.min_norm:
            state.scale = np.zeros(3)
            return
        rotation = state.pose[:3, :3]
        turn = rotation_to(rotation.T @ (self.current / norm))  # the vector in the entity's own axes
        state.pose = state.pose @ se3.make(turn)
        state.scale = state.scale * np.array([1.0, 1.0, self.scale * norm])
