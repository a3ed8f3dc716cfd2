"""Which transforms of the transformation graph a TF bridge broadcasts, and with which stamps.

Two sets, as tf2 splits them:

- *moving* transforms go to /tf, each cycle in which they changed: chosen lookups (``parent:child``
  pairs, ``T_parent_child`` along whatever path the graph has) and, with a ``root``, every dynamic,
  axis and moving URDF edge reachable from that root, in its own direction (as
  robot_state_publisher broadcasts a robot's joints);
- *static* transforms go to /tf_static, all in one message, re-sent whenever one is added or
  changes (tf2's static broadcaster keeps one latched message per publisher, so every message must
  carry the whole set): static edges and fixed URDF joints (those reachable from ``root`` when
  one is given).

Edges that came *from* ROS (ingested, see :mod:`.ingest`) are never part of either set: they are
someone else's to broadcast, and sending them back would start an echo loop.

Stamps follow the graph's time base: a transform made only of static and dynamic edges carries
the newest sample stamp of its dynamic edges (the time the measurement is valid, as it came in);
one that moves with joint values (axis or URDF edges, whose values carry no stamp in the graph)
or holds only static edges carries the clock's time at publication (the ROS clock of the node,
simulated time under ``use_sim_time``). Two messages never repeat a stamp for the same changed
transform, which tf2 would reject as redundant.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
from coco_core.errors import AttributeValueError, did_you_mean
from coco_core.transforms.edges import AxisEdge, DynamicEdge, Edge, EdgeKind, StaticEdge
from coco_core.transforms.graph import ModelEdge, TransformError, TransformGraph
from coco_core.transforms.samples import TransformSample

Pair = tuple[str, str]
"""(parent, child) frame names: an edge's direction, or a lookup T_parent_child."""


def parse_pair(text: str) -> Pair:
    """``"base:left_gripper"`` -> ``("base", "left_gripper")``."""
    parent, colon, child = text.partition(":")
    parent, child = parent.strip(), child.strip()
    if not colon or not parent or not child or ":" in child:
        raise AttributeValueError(f"frame pair {text!r} must look like parent:child (e.g. base:left_gripper)")
    if parent == child:
        raise AttributeValueError(f"frame pair {text!r} names the same frame twice")
    return parent, child


def check_pairs(texts: Iterable[str]) -> str | None:
    """An attribute ``check``: the first malformed pair, or None."""
    for text in texts:
        try:
            parse_pair(text)
        except ValueError as error:
            return str(error)
    return None


def is_static(edge: Edge) -> bool:
    """Static edges and fixed URDF joints: their value never changes with data."""
    return isinstance(edge, StaticEdge) or (isinstance(edge, ModelEdge) and edge.kind is EdgeKind.STATIC)


SAME = 1e-12
"""Transforms closer than this (in every matrix element) are the same: a URDF edge recomputed by
Pinocchio after another joint moved may differ in the last bits, which is no motion to broadcast."""


def _same(value: np.ndarray, sent: np.ndarray) -> bool:
    return value is sent or bool(np.max(np.abs(value - sent)) <= SAME)


@dataclass
class _Sent:
    """What was last broadcast for one pair, to send it again only when it changed."""

    value: np.ndarray | None = None
    stamp: float | None = None


class TFSelection:
    """The /tf and /tf_static content of one bridge: ``moving()`` and ``static()`` each return what
    is due now (only what changed), ``children`` the frames the bridge broadcasts (the echo rule).

    Not thread-safe by itself: one activity calls it (the graph it reads is thread-safe).
    """

    def __init__(self, graph: TransformGraph, pairs: Iterable[Pair] = (), root: str = "",
                 static: bool = True, ingested: Callable[[Pair], bool] = lambda pair: False,
                 clock: Callable[[], float] = lambda: 0.0) -> None:
        self.graph = graph
        self.pairs = list(dict.fromkeys(pairs))
        self.root = root
        self.with_static = static
        self.ingested = ingested
        """Whether an edge came from ROS: those are neither broadcast nor counted as ours."""
        self.clock = clock
        self._structure = -1
        self._moving: list[Pair] = []
        self._static_edges: list[Edge] = []
        self._stamp_edges: dict[Pair, list[DynamicEdge] | None] = {}
        """Per pair: the dynamic edges whose newest stamp it carries, or None for the clock's time."""
        self._sent: dict[Pair, _Sent] = {}
        self._static_sent: tuple | None = None
        self.children: frozenset[str] = frozenset()

    # --- checks -------------------------------------------------------------------------------------
    def check(self) -> None:
        """Raise :class:`TransformError` naming the known frames when a pair or the root is unknown."""
        known = set(self.graph.frames)
        named = [frame for pair in self.pairs for frame in pair] + ([self.root] if self.root else [])
        unknown = [frame for frame in dict.fromkeys(named) if frame not in known]
        if unknown:
            raise TransformError(f"unknown frame(s) {', '.join(map(repr, unknown))} in the transformation graph; "
                                 f"{did_you_mean(unknown[0], known)}")

    # --- what is broadcast ----------------------------------------------------------------------------
    def _refresh(self) -> None:
        """Recompute the edge sets after a structure change (an edge added or removed)."""
        graph = self.graph
        if graph.structure_version == self._structure:
            return
        self._structure = graph.structure_version
        edges = [edge for edge in self._reachable() if not self.ingested((edge.parent, edge.child))]
        root_moving = [(edge.parent, edge.child) for edge in edges if not is_static(edge)] if self.root else []
        self._moving = list(dict.fromkeys(self.pairs + root_moving))
        self._static_edges = [edge for edge in edges if is_static(edge)] if self.with_static else []
        self._stamp_edges = {}
        children = {child for _, child in self._moving}
        children.update(edge.child for edge in self._static_edges)
        self.children = frozenset(children)

    def _reachable(self) -> list[Edge]:
        """The edges connected to the root (undirected), or every edge of the graph without root."""
        edges = self.graph.edges
        if not self.root:
            return edges
        touching: dict[str, list[Edge]] = {}
        for edge in edges:
            touching.setdefault(edge.parent, []).append(edge)
            touching.setdefault(edge.child, []).append(edge)
        seen, found, frontier = {self.root}, [], deque([self.root])
        while frontier:
            frame = frontier.popleft()
            for edge in touching.get(frame, ()):
                other = edge.child if edge.parent == frame else edge.parent
                if other not in seen:
                    seen.add(other)
                    found.append(edge)
                    frontier.append(other)
        return found

    def _stamp_rule(self, pair: Pair) -> list[DynamicEdge] | None:
        """The dynamic edges on the pair's path whose newest stamp it carries; None: the clock's time."""
        if pair not in self._stamp_edges:
            frames = self.graph.path(*pair)
            edges = [self.graph.edge(a, b) for a, b in zip(frames, frames[1:])]
            moves_with_joints = any(isinstance(edge, (AxisEdge, ModelEdge)) and not is_static(edge)
                                    for edge in edges)
            dynamic = [edge for edge in edges if isinstance(edge, DynamicEdge)]
            self._stamp_edges[pair] = None if moves_with_joints or not dynamic else dynamic
        return self._stamp_edges[pair]

    def _stamp(self, pair: Pair) -> float:
        rule = self._stamp_rule(pair)
        if rule is None:
            return self.clock()
        return max(edge.time_range[1] for edge in rule if edge.time_range is not None)

    def moving(self) -> list[TransformSample]:
        """The /tf transforms that changed since the last call (all of them at the first call).

        A pair without a path or a sample yet is left out until it has one.
        """
        self._refresh()
        due = []
        for pair in self._moving:
            try:
                with self.graph.reading():
                    value = self.graph.lookup(*pair)
                    stamp = self._stamp(pair)
            except LookupError:
                continue
            sent = self._sent.setdefault(pair, _Sent())
            if sent.value is not None and _same(value, sent.value) \
                    and (stamp == sent.stamp or self._stamp_rule(pair) is None):
                continue
            sent.value, sent.stamp = value, stamp
            due.append(TransformSample(pair[0], pair[1], value, stamp))
        return due

    def static(self) -> list[TransformSample] | None:
        """All static transforms when one was added or changed since the last call, else None."""
        self._refresh()
        signature = tuple((edge.parent, edge.child, edge.version) for edge in self._static_edges)
        if signature == self._static_sent or not signature:
            return None
        self._static_sent = signature
        stamp = self.clock()
        return [TransformSample(edge.parent, edge.child, edge.transform(), stamp) for edge in self._static_edges]

    @property
    def broadcast(self) -> list[str]:
        """``parent:child`` of every transform broadcast on /tf, then on /tf_static."""
        self._refresh()
        return [f"{p}:{c}" for p, c in self._moving] + [f"{e.parent}:{e.child}" for e in self._static_edges]
