"""Implicit surfaces: the primitives and their combinations, as a tree the application describes.

A surface is a function ``f(p)``: negative inside the solid, zero on its surface, positive outside,
as in Salisbury and Tarr's implicit-surface haptics. The primitives are exact signed distances; the
combinations (union = min, intersection = max, difference = max(a, -b)) and rigid placements keep
``|f|`` a lower bound of the distance to the surface, which is what the proxy relies on: a point may
move by ``f(p)`` in any direction without crossing the surface (sphere tracing), so a fast device
never tunnels through a thin wall. The gradient has unit length almost everywhere (that of the active
branch; on an edge one of the faces' normals).

The tree is a *description*: :class:`coco_mr_haptics.scene.Scene` compiles it into the flat program
the haptic kernel evaluates (:mod:`coco_mr_haptics.kernel`), where the formulas live once.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from coco_core.errors import SurfaceExpressionError

from . import kernel


class Surface:
    """A node of an implicit-surface tree."""

    def children(self) -> Sequence[Surface]:
        return ()

    def walk(self) -> list[Surface]:
        """This node and every node below it, depth first."""
        found: list[Surface] = [self]
        for child in self.children():
            found.extend(child.walk())
        return found

    def count_primitives(self) -> int:
        return sum(1 for node in self.walk() if isinstance(node, Primitive))


class Primitive(Surface):
    """A leaf: a solid in its own canonical placement (centred at the origin, axis along z)."""

    code: int
    """The kernel's opcode."""

    def shape(self) -> list[float]:
        """The kernel's shape parameters."""
        raise NotImplementedError


class Sphere(Primitive):
    code = kernel.SPHERE

    def __init__(self, radius: float) -> None:
        _positive("sphere radius", radius)
        self.radius = float(radius)

    def shape(self) -> list[float]:
        return [self.radius]

    def __repr__(self) -> str:
        return f"sphere({self.radius:g})"


class Plane(Primitive):
    """The half-space ``n . p <= offset`` (solid below the plane, ``normal`` pointing out of it)."""

    code = kernel.PLANE

    def __init__(self, normal: Sequence[float] = (0.0, 0.0, 1.0), offset: float = 0.0) -> None:
        nx, ny, nz = (float(v) for v in normal)
        length = math.sqrt(nx * nx + ny * ny + nz * nz)
        if length < 1e-12:
            raise SurfaceExpressionError("plane normal must not be zero")
        self.nx, self.ny, self.nz = nx / length, ny / length, nz / length
        self.offset = float(offset)

    def shape(self) -> list[float]:
        return [self.nx, self.ny, self.nz, self.offset]

    def __repr__(self) -> str:
        return f"plane(normal=[{self.nx:g}, {self.ny:g}, {self.nz:g}], offset={self.offset:g})"


class Box(Primitive):
    """An axis-aligned box of full extents ``size``, centred at the origin."""

    code = kernel.BOX

    def __init__(self, size: Sequence[float]) -> None:
        sx, sy, sz = (float(v) for v in size)
        for value in (sx, sy, sz):
            _positive("box size", value)
        self.hx, self.hy, self.hz = sx / 2, sy / 2, sz / 2

    def shape(self) -> list[float]:
        return [self.hx, self.hy, self.hz]

    def __repr__(self) -> str:
        return f"box(size=[{2 * self.hx:g}, {2 * self.hy:g}, {2 * self.hz:g}])"


class Cylinder(Primitive):
    """A capped cylinder of ``radius`` and full ``height`` along z, centred at the origin."""

    code = kernel.CYLINDER

    def __init__(self, radius: float, height: float) -> None:
        _positive("cylinder radius", radius)
        _positive("cylinder height", height)
        self.radius, self.half = float(radius), float(height) / 2

    def shape(self) -> list[float]:
        return [self.radius, self.half]

    def __repr__(self) -> str:
        return f"cylinder(radius={self.radius:g}, height={2 * self.half:g})"


class Capsule(Primitive):
    """The points within ``radius`` of the segment of length ``height`` along z, centred."""

    code = kernel.CAPSULE

    def __init__(self, radius: float, height: float) -> None:
        _positive("capsule radius", radius)
        if height < 0:
            raise SurfaceExpressionError(f"capsule height must be >= 0, got {height}")
        self.radius, self.half = float(radius), float(height) / 2

    def shape(self) -> list[float]:
        return [self.radius, self.half]

    def __repr__(self) -> str:
        return f"capsule(radius={self.radius:g}, height={2 * self.half:g})"


class Torus(Primitive):
    """A torus around z: the tube of ``minor`` radius around the circle of ``major`` radius in z = 0."""

    code = kernel.TORUS

    def __init__(self, major: float, minor: float) -> None:
        _positive("torus major radius", major)
        _positive("torus minor radius", minor)
        if minor >= major:
            raise SurfaceExpressionError(f"torus minor radius ({minor}) must be smaller than the major radius "
                                         f"({major})")
        self.major, self.minor = float(major), float(minor)

    def shape(self) -> list[float]:
        return [self.major, self.minor]

    def __repr__(self) -> str:
        return f"torus(major={self.major:g}, minor={self.minor:g})"


class Union(Surface):
    """Solid where any child is: ``min`` of the children."""

    code = kernel.UNION

    def __init__(self, children: Sequence[Surface]) -> None:
        self.parts = _at_least_one("union", children)

    def children(self) -> Sequence[Surface]:
        return self.parts

    def __repr__(self) -> str:
        return f"union({', '.join(map(repr, self.parts))})"


class Intersection(Surface):
    """Solid where every child is: ``max`` of the children."""

    code = kernel.INTERSECTION

    def __init__(self, children: Sequence[Surface]) -> None:
        self.parts = _at_least_one("intersection", children)

    def children(self) -> Sequence[Surface]:
        return self.parts

    def __repr__(self) -> str:
        return f"intersection({', '.join(map(repr, self.parts))})"


class Difference(Surface):
    """The first child without the others: ``max(a, -b, -c, ...)``."""

    code = kernel.DIFFERENCE

    def __init__(self, base: Surface, removed: Sequence[Surface]) -> None:
        self.base = base
        self.removed = _at_least_one("difference (something to remove)", removed)

    def children(self) -> Sequence[Surface]:
        return (self.base, *self.removed)

    def __repr__(self) -> str:
        return f"difference({self.base!r}, {', '.join(map(repr, self.removed))})"


class Placed(Surface):
    """A child moved rigidly: ``pose`` is the child's frame in the parent's (a 4x4 or 3x4 matrix,
    nested sequences or numpy). :meth:`set_pose` changes it at run time (a pose read from the
    transformation graph each haptic cycle)."""

    def __init__(self, child: Surface, pose: Sequence[Sequence[float]], frame: str = "") -> None:
        self.child = child
        self.frame = frame
        """Name of the transformation-graph frame that drives this pose ("" for a fixed pose)."""
        self.set_pose(pose)

    def children(self) -> Sequence[Surface]:
        return (self.child,)

    def set_pose(self, pose: Sequence[Sequence[float]] | np.ndarray) -> None:
        matrix = np.eye(4)
        matrix[:3, :4] = np.asarray(pose, dtype=float)[:3, :4]
        self.matrix = matrix

    def pose(self) -> list[list[float]]:
        return self.matrix.tolist()

    def __repr__(self) -> str:
        if self.frame:
            return f"frame({self.frame!r}, {self.child!r})"
        return f"placed({self.pose()}, {self.child!r})"


def pose_from_xyz_rpy(xyz: Sequence[float] = (0.0, 0.0, 0.0),
                      rpy: Sequence[float] = (0.0, 0.0, 0.0)) -> list[list[float]]:
    """A 4x4 pose from a translation and roll-pitch-yaw angles in radians (URDF's convention:
    R = Rz(yaw) Ry(pitch) Rx(roll))."""
    roll, pitch, yaw = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    x, y, z = (float(v) for v in xyz)
    return [[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr, x],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr, y],
            [-sp, cp * sr, cp * cr, z],
            [0.0, 0.0, 0.0, 1.0]]


def _positive(what: str, value: float) -> None:
    if not float(value) > 0:
        raise SurfaceExpressionError(f"{what} must be > 0, got {value}")


def _at_least_one(what: str, children: Sequence[Surface]) -> tuple[Surface, ...]:
    parts = tuple(children)
    if not parts:
        raise SurfaceExpressionError(f"{what} needs at least one surface")
    for part in parts:
        if not isinstance(part, Surface):
            raise SurfaceExpressionError(f"{what} takes surfaces, got {part!r}")
    return parts
