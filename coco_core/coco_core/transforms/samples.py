"""What flows on ports into and out of the transformation graph.

Plain frozen dataclasses with numpy payloads, so that vision, haptics and ROS bridges can all feed the
graph without knowing each other; conversions from ROS messages live in ``coco_ros``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import EdgeError
from ..wire import value_type


@value_type
@dataclass(frozen=True, slots=True)
class TransformSample:
    """``T_parent_child`` measured at ``stamp`` (seconds; the graph's time base, e.g. ROS time).

    ``static``: a fixed transform (what /tf_static carries): it becomes a static edge, and its stamp
    (usually 0) is no sample time.
    """

    parent: str
    child: str
    transform: np.ndarray
    stamp: float | None = None
    static: bool = False


@value_type
@dataclass(frozen=True, slots=True)
class JointSample:
    """Joint values by name, as in a sensor_msgs/JointState."""

    names: tuple[str, ...]
    positions: np.ndarray
    stamp: float | None = None

    def as_mapping(self) -> dict[str, float]:
        """Values by name; a sample whose positions do not match its names one to one is refused
        (zip would silently drop the extra names or values)."""
        self.check()
        return dict(zip(self.names, self.positions.tolist()))

    def check(self) -> None:
        """Raise ``ValueError`` naming both lengths when positions and names differ in length."""
        count = len(self.positions)
        if count != len(self.names):
            raise EdgeError(f"joint sample with {len(self.names)} names but {count} positions: refused")


@value_type
@dataclass(frozen=True, slots=True)
class FramePose:
    """The result of a lookup: ``T_target_source`` (the pose of ``source`` in ``target``)."""

    target: str
    source: str
    transform: np.ndarray
    stamp: float | None = None
