"""A surface tree compiled for the haptic kernel: a flat postfix program and a table of primitives.

Each primitive's row holds its *composed* pose (the product of every placement above it) and its
shape parameters, so evaluating the scene never walks the tree. Placements driven by frames of the
transformation graph are re-composed when their pose changes (:meth:`Scene.set_frame_pose`), which
touches only the rows below them.
"""

from __future__ import annotations

import numpy as np
from coco_core.errors import WrongTypeError

from . import kernel
from .implicit import Difference, Intersection, Placed, Primitive, Surface, Union


class Scene:
    """The compiled form of ``surface``; ``evaluate`` for one point, ``ops``/``prm`` for the kernel."""

    def __init__(self, surface: Surface) -> None:
        self.surface = surface
        ops: list[tuple[int, int]] = []
        self._chains: list[tuple[Primitive, tuple[Placed, ...]]] = []
        depth = self._compile(surface, (), ops, 0)
        self.ops = np.array(ops, dtype=np.int64).reshape(-1, 2)
        self.prm = np.zeros((len(self._chains), kernel.PARAMS))
        self.stack = np.zeros((depth, 4))
        """Scratch for the kernel: one scene is evaluated by one thread at a time (its renderer's)."""
        for row in range(len(self._chains)):
            self._fill(row)
        self.frames: dict[str, list[Placed]] = {}
        """The placements driven by each frame of the transformation graph."""
        for node in surface.walk():
            if isinstance(node, Placed) and node.frame:
                self.frames.setdefault(node.frame, []).append(node)

    def _compile(self, node: Surface, chain: tuple[Placed, ...], ops: list[tuple[int, int]],
                 height: int) -> int:
        """Append ``node`` to the postfix program; the stack depth it needs above ``height``."""
        if isinstance(node, Primitive):
            ops.append((node.code, len(self._chains)))
            self._chains.append((node, chain))
            return height + 1
        if isinstance(node, Placed):
            return self._compile(node.child, chain + (node,), ops, height)
        if isinstance(node, (Union, Intersection, Difference)):
            deepest = height
            children = node.children()
            for index, child in enumerate(children):
                deepest = max(deepest, self._compile(child, chain, ops, height + index))
            ops.append((node.code, len(children)))
            return deepest
        raise WrongTypeError(f"cannot compile {node!r}: not a surface of coco_mr_haptics.implicit")

    def _fill(self, row: int) -> None:
        primitive, chain = self._chains[row]
        pose = np.eye(4)
        for placed in chain:
            pose = pose @ placed.matrix
        shape = primitive.shape()
        values = self.prm[row]
        values[:9] = pose[:3, :3].reshape(-1)
        values[9:12] = pose[:3, 3]
        values[kernel.SHAPE:kernel.SHAPE + len(shape)] = shape

    def set_frame_pose(self, frame: str, pose: np.ndarray) -> None:
        """Move every placement driven by ``frame`` to ``pose`` (4x4, the frame in the scene's frame)."""
        nodes = self.frames.get(frame, [])
        for node in nodes:
            node.set_pose(pose)
        for row, (_, chain) in enumerate(self._chains):
            if any(node in chain for node in nodes):
                self._fill(row)

    def evaluate(self, x: float, y: float, z: float) -> tuple[float, float, float, float]:
        """Signed distance and gradient at one point."""
        return kernel.evaluate(self.ops, self.prm, self.stack, float(x), float(y), float(z))

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance of each of N points (N x 3), for tests and sampling (a loop in the kernel)."""
        return kernel.distances(self.ops, self.prm, self.stack, np.ascontiguousarray(points, dtype=float))

    @property
    def primitives(self) -> int:
        return len(self._chains)
