"""Edges of the transformation graph: what joins a parent frame to a child frame.

Three kinds, as in the paper: *static* (a fixed transform, e.g. a calibration), *dynamic* (a
timestamped history, e.g. a tracked object) and *axis* (a single-axis joint: fixed origin, unit axis
and one value, e.g. a robot joint driven by a JointState). Every edge carries a version counter that
any change bumps, which is what lets queries cache their result until an edge on their path changes.
An edge's value is ``T_parent_child``; values handed out are read-only and shared.
"""

from __future__ import annotations

import bisect
import enum
from collections import deque
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from . import se3
from ..errors import EdgeError, ExtrapolationError

if TYPE_CHECKING:
    from ..stamps import Stamp
    from .graph import Query


class EdgeKind(enum.Enum):
    STATIC = "static"
    DYNAMIC = "dynamic"
    AXIS = "axis"


class JointType(enum.Enum):
    """The single-axis joint types of URDF."""

    REVOLUTE = "revolute"
    CONTINUOUS = "continuous"
    PRISMATIC = "prismatic"


class Dependency:
    """Something a query's value depends on: a version counter and the queries that watch it."""

    __slots__ = ("version", "watchers", "cause", "__weakref__")

    def __init__(self) -> None:
        self.version = 0
        self.watchers: set[Query] = set()
        self.cause: Stamp | None = None
        """The :class:`~coco_core.stamps.Stamp` of the input that made the current value, when its
        writer knew it (``cause=`` of the graph's writes): a display that draws the value measures
        its sensor-to-display latency from it."""


class Edge(Dependency):
    """Base of the edge kinds; ``transform()`` is ``T_parent_child`` now."""

    kind: EdgeKind
    __slots__ = ("parent", "child", "_inverse", "_inverse_version")

    def __init__(self, parent: str, child: str) -> None:
        super().__init__()
        if parent == child:
            raise EdgeError(f"an edge needs two different frames, got {parent!r} twice")
        self.parent = parent
        self.child = child
        self._inverse: np.ndarray | None = None
        self._inverse_version = -1

    @property
    def name(self) -> str:
        return f"{self.parent}->{self.child}"

    def transform(self) -> np.ndarray:
        raise NotImplementedError

    def transform_at(self, time: float) -> np.ndarray:
        """``T_parent_child`` at ``time``; only dynamic edges depend on time."""
        return self.transform()

    def inverse(self) -> np.ndarray:
        """``T_child_parent``, cached per version (paths walk edges both ways)."""
        if self._inverse_version != self.version:
            self._inverse = se3.frozen(se3.inverse(self.transform()))
            self._inverse_version = self.version
        assert self._inverse is not None
        return self._inverse

    def describe(self) -> dict[str, Any]:
        """JSON-ready description: kind, frames, current value and what defines it."""
        return {"parent": self.parent, "child": self.child, "kind": self.kind.value, "version": self.version,
                "transform": self.transform().tolist()}

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name} v{self.version}>"


class StaticEdge(Edge):
    """A fixed transform; may still be replaced (a new calibration), which bumps its version."""

    kind = EdgeKind.STATIC
    __slots__ = ("_value",)

    def __init__(self, parent: str, child: str, transform: np.ndarray = se3.IDENTITY) -> None:
        super().__init__(parent, child)
        self._value = se3.frozen(se3.as_transform(transform))

    def assign(self, transform: np.ndarray, checked: bool = False) -> bool:
        self._value = transform if checked else se3.frozen(se3.as_transform(transform))
        self.version += 1
        return True

    def transform(self) -> np.ndarray:
        return self._value


class DynamicEdge(Edge):
    """A bounded, timestamped history of transforms; ``transform()`` is the newest sample."""

    kind = EdgeKind.DYNAMIC
    __slots__ = ("_stamps", "_values", "capacity")

    def __init__(self, parent: str, child: str, capacity: int = 100) -> None:
        super().__init__(parent, child)
        if capacity < 1:
            raise EdgeError(f"edge {parent}->{child}: history capacity must be >= 1, got {capacity}")
        self.capacity = capacity
        self._stamps: deque[float] = deque(maxlen=capacity)
        self._values: deque[np.ndarray] = deque(maxlen=capacity)

    def assign(self, transform: np.ndarray, stamp: float, checked: bool = False) -> bool:
        """Add a sample; samples may arrive out of order (they are kept sorted by stamp), and a sample
        with the stamp of one already kept replaces it. Returns False when the sample was dropped
        (older than a full history). ``checked``: the matrix is already validated and read-only."""
        value = transform if checked else se3.frozen(se3.as_transform(transform))
        stamps = self._stamps
        if not stamps or stamp > stamps[-1]:  # the usual case: a newer sample
            stamps.append(stamp)
            self._values.append(value)
            self.version += 1
            return True
        index = bisect.bisect_left(stamps, stamp)
        if index < len(stamps) and stamps[index] == stamp:
            self._values[index] = value
        elif index == len(stamps):
            stamps.append(stamp)
            self._values.append(value)
        else:
            if len(stamps) == self.capacity:
                if index == 0:
                    return False  # older than everything kept: it would be evicted at once
                stamps.popleft()
                self._values.popleft()
                index -= 1
            stamps.insert(index, stamp)
            self._values.insert(index, value)
        self.version += 1
        return True

    @property
    def time_range(self) -> tuple[float, float] | None:
        return (self._stamps[0], self._stamps[-1]) if self._stamps else None

    def transform(self) -> np.ndarray:
        if not self._values:
            raise ExtrapolationError(f"edge {self.name} has no sample yet")
        return self._values[-1]

    def transform_at(self, time: float) -> np.ndarray:
        """Interpolated at ``time`` (linear translation, slerp rotation) inside the history."""
        stamps = self._stamps
        if not stamps:
            raise ExtrapolationError(f"edge {self.name} has no sample yet")
        if time < stamps[0] or time > stamps[-1]:
            raise ExtrapolationError(
                f"time {time:.6f} is outside the history of edge {self.name}: it holds "
                f"{stamps[0]:.6f} .. {stamps[-1]:.6f} ({len(stamps)} samples)")
        index = bisect.bisect_left(stamps, time)
        if stamps[index] == time:
            return self._values[index]
        before, after = stamps[index - 1], stamps[index]
        return se3.frozen(se3.interpolate(self._values[index - 1], self._values[index],
                                          (time - before) / (after - before)))

    def describe(self) -> dict[str, Any]:
        described: dict[str, Any] = super().describe() if self._values else {
            "parent": self.parent, "child": self.child, "kind": self.kind.value, "version": self.version,
            "transform": None}
        described.update(stamp=self._stamps[-1] if self._stamps else None, samples=len(self._stamps),
                         capacity=self.capacity)
        return described


class AxisEdge(Edge):
    """A single-axis joint: ``T_parent_child = origin * motion(value) * suffix`` about/along a unit
    ``axis``. URDF joints have no suffix (identity); Denavit-Hartenberg joints need one."""

    kind = EdgeKind.AXIS
    __slots__ = ("joint", "joint_type", "origin", "axis", "suffix", "_value", "_cached", "_cached_version")

    def __init__(self, parent: str, child: str, joint: str, joint_type: JointType | str,
                 origin: np.ndarray = se3.IDENTITY, axis: Sequence[float] = (0.0, 0.0, 1.0),
                 value: float = 0.0, suffix: np.ndarray | None = None) -> None:
        super().__init__(parent, child)
        self.joint = joint
        self.joint_type = JointType(joint_type)
        self.origin = se3.frozen(se3.as_transform(origin))
        self.suffix = None if suffix is None else se3.frozen(se3.as_transform(suffix))
        norm = float(np.linalg.norm(axis))
        if norm == 0.0:
            raise EdgeError(f"joint {joint} ({parent}->{child}): the axis must not be zero")
        self.axis = tuple(float(a) / norm for a in axis)
        self._value = float(value)
        self._cached: np.ndarray | None = None
        self._cached_version = -1

    @classmethod
    def from_dh(cls, parent: str, child: str, joint: str, joint_type: JointType | str,
                d: float, theta: float, r: float, alpha: float, value: float = 0.0) -> AxisEdge:
        """A joint given by classic Denavit-Hartenberg parameters: a revolute joint's value adds to
        theta, a prismatic joint's to d. Since rotation about z and translation along z commute,
        ``Rz(theta+q) Tz(d) Tx(r) Rx(alpha)`` = ``[Rz(theta) Tz(d)]`` * motion_z(q) * ``[Tx(r) Rx(alpha)]``:
        an origin, the joint motion about/along z, and a fixed suffix."""
        origin = se3.denavit_hartenberg(d, theta, 0.0, 0.0)
        suffix = se3.denavit_hartenberg(0.0, 0.0, r, alpha)
        return cls(parent, child, joint, joint_type, origin, (0.0, 0.0, 1.0), value, suffix)

    @property
    def value(self) -> float:
        return self._value

    def assign(self, value: float) -> None:
        self._value = float(value)
        self.version += 1

    def motion(self, value: float) -> np.ndarray:
        """The joint's own motion for ``value``: rotation about or translation along the axis."""
        if self.joint_type is JointType.PRISMATIC:
            return se3.make(None, [a * value for a in self.axis])
        return se3.make(se3.axis_angle(self.axis, value))

    def transform(self) -> np.ndarray:
        if self._cached_version != self.version:
            transform = self.origin @ self.motion(self._value)
            if self.suffix is not None:
                transform = transform @ self.suffix
            self._cached = se3.frozen(transform)
            self._cached_version = self.version
        assert self._cached is not None
        return self._cached

    def describe(self) -> dict[str, Any]:
        described = super().describe()
        described.update(joint=self.joint, joint_type=self.joint_type.value, value=self._value,
                         axis=list(self.axis), origin=self.origin.tolist())
        return described
