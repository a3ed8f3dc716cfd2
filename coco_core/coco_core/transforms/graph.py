"""The transformation graph: reference frames joined by static, dynamic and axis edges.

A lookup ``(target, source)`` resolves its path once (breadth-first, fewest hops, any graph shape,
edges walked in either direction) and caches it with its value. The cached value is returned as long
as no edge on the path changed: each edge (and each kinematic model) has a version counter, and the
graph a global one so that the common case — nothing changed since the last lookup — costs one
dictionary access and one comparison, without a lock. Queries may have callbacks, which run after any
edge on their path changes, with the new value, in the thread that made the change.

Consecutive edges of one :class:`KinematicModel` (a URDF robot) are evaluated together by the model
(Pinocchio computes all joint placements in one call), not edge by edge.
"""

from __future__ import annotations

import logging
import math
import time as _time
from collections import deque
from typing import Any, Callable, ContextManager, Iterable, Mapping

import numpy as np

from ..errors import EdgeError, TransformError, did_you_mean
from ..stamps import Stamp
from . import se3
from .edges import AxisEdge, Dependency, DynamicEdge, Edge, EdgeKind, StaticEdge
from .rwlock import ReadWriteLock

log = logging.getLogger("coco.transforms")

Callback = Callable[[np.ndarray], None]


def _finite_time(value: Any, what: str) -> float:
    """``value`` as seconds; NaN and infinities are refused (they compare false with every stamp, so
    they would silently break the order of a history or return a NaN pose)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) or not math.isfinite(value):
        raise EdgeError(f"{what} must be a finite number of seconds, got {value!r}")
    return float(value)


class KinematicModel(Dependency):
    """Frames whose relative transforms an external kinematics library computes in bulk.

    Subclasses (e.g. :class:`~coco_core.transforms.urdf.UrdfModel`) implement :meth:`relative` and
    :meth:`set_positions`, and bump ``version`` when their joint values change.
    """

    __slots__ = ("name",)

    def __init__(self, name: str) -> None:
        super().__init__()
        self.name = name

    def relative(self, a: str, b: str) -> np.ndarray:
        """``T_a_b`` for two frames of the model, with the current joint values."""
        raise NotImplementedError

    def set_positions(self, values: Mapping[str, float]) -> list[str]:
        """Set joint values by name in one bulk update; return the names the model does not have."""
        raise NotImplementedError

    def set_array(self, names: tuple[str, ...], positions: np.ndarray) -> tuple[str, ...]:
        """Set joint values given as names and a (checked, finite) array; return the names the model
        does not have. This default goes through :meth:`set_positions`; a model that can take the
        array as it is overrides it."""
        return tuple(self.set_positions(dict(zip(names, positions.tolist()))))

    @property
    def joint_names(self) -> list[str]:
        raise NotImplementedError

    @property
    def positions(self) -> dict[str, float]:
        """Current value of every moving joint, by name."""
        raise NotImplementedError


class ModelEdge(Edge):
    """An edge whose value comes from a :class:`KinematicModel` (a URDF joint, fixed or moving)."""

    __slots__ = ("model", "joint", "kind")

    def __init__(self, parent: str, child: str, model: KinematicModel, kind: EdgeKind, joint: str = "") -> None:
        super().__init__(parent, child)
        self.model = model
        self.kind = kind
        self.joint = joint

    def transform(self) -> np.ndarray:
        return self.model.relative(self.parent, self.child)

    def inverse(self) -> np.ndarray:
        return self.model.relative(self.child, self.parent)

    def describe(self) -> dict[str, Any]:
        described = super().describe()
        described.update(version=self.model.version, joint=self.joint, model=self.model.name)
        if self.kind is EdgeKind.AXIS:
            described["value"] = self.model.positions.get(self.joint)
        return described


class _Step:
    """One factor of a path's product: the transform from one frame to the next."""

    __slots__ = ("dependency",)

    def __init__(self, dependency: Dependency) -> None:
        self.dependency = dependency

    def value(self, time: float | None) -> np.ndarray:
        raise NotImplementedError


class _Forward(_Step):
    __slots__ = ("edge",)

    def __init__(self, edge: Edge) -> None:
        super().__init__(edge)
        self.edge = edge

    def value(self, time: float | None) -> np.ndarray:
        return self.edge.transform() if time is None else self.edge.transform_at(time)


class _Backward(_Forward):
    __slots__ = ()

    def value(self, time: float | None) -> np.ndarray:
        return self.edge.inverse() if time is None else se3.frozen(se3.inverse(self.edge.transform_at(time)))


class _Segment(_Step):
    __slots__ = ("model", "a", "b")

    def __init__(self, model: KinematicModel, a: str, b: str) -> None:
        super().__init__(model)
        self.model, self.a, self.b = model, a, b

    def value(self, time: float | None) -> np.ndarray:
        return self.model.relative(self.a, self.b)


class Query:
    """A cached lookup of ``T_target_source``; get one from :meth:`TransformGraph.query`."""

    __slots__ = ("graph", "target", "source", "steps", "dependencies", "versions", "graph_version",
                 "structure_version", "value", "callbacks", "notified", "step_versions", "prefix", "suffix",
                 "prefix_valid", "suffix_valid", "positions", "__weakref__")

    def __init__(self, graph: TransformGraph, target: str, source: str) -> None:
        self.graph = graph
        self.target = target
        self.source = source
        self.steps: list[_Step] = []
        self.dependencies: tuple[Dependency, ...] = ()
        self.versions: tuple[int, ...] | None = ()
        self.graph_version = -1
        self.structure_version = -1
        self.value: np.ndarray = se3.IDENTITY
        self.callbacks: list[Callback] = []
        self.notified: np.ndarray | None = None
        """The value callbacks saw last: a structure change elsewhere that leaves it equal is silent."""
        self.step_versions: list[int] = []
        """The version of each step's dependency when the value was computed."""
        self.prefix: list[np.ndarray] = []
        """``prefix[k]``: the product of steps ``0..k-1`` (``prefix[0]`` the identity)."""
        self.suffix: list[np.ndarray] = []
        """``suffix[k]``: the product of steps ``k..n-1`` (``suffix[n]`` the identity)."""
        self.prefix_valid = -1
        """``prefix[0..prefix_valid]`` hold the current values; the later ones are stale."""
        self.suffix_valid = 1 << 30
        """``suffix[suffix_valid..n]`` hold the current values; the earlier ones are stale."""
        self.positions: dict[Dependency, int] = {}
        """Dependency -> index of its step (empty when a dependency has several steps)."""

    @property
    def path(self) -> list[str]:
        """The frames the query walks, target first."""
        self.graph.lookup(self.target, self.source)
        return self.graph.path(self.target, self.source)

    def current(self) -> np.ndarray:
        """``T_target_source`` now (the cached value when nothing on the path changed)."""
        return self.graph.lookup(self.target, self.source)

    def on_change(self, callback: Callback) -> Callable[[], None]:
        """Call ``callback(T_target_source)`` after any change on the path; returns an unsubscribe.

        The path need not exist yet, nor have a value: the callback first runs once it has one.
        """
        try:
            self.notified = self.graph.lookup(self.target, self.source)
        except LookupError:  # no path or no sample yet: structure changes are re-checked for us
            pass
        with self.graph._lock.write():
            self.callbacks.append(callback)
            for dependency in self.dependencies:
                dependency.watchers.add(self)

        def unsubscribe() -> None:
            with self.graph._lock.write():
                if callback in self.callbacks:
                    self.callbacks.remove(callback)
                if not self.callbacks:
                    for dependency in self.dependencies:
                        dependency.watchers.discard(self)

        return unsubscribe

    def __repr__(self) -> str:
        return f"<Query {self.target} <- {self.source}>"


class TransformGraph:
    """Frames and edges, with cached, versioned lookups. Safe to use from any number of threads."""

    def __init__(self, history: int = 100, strict: bool = False) -> None:
        self.history = history
        """Capacity of a dynamic edge created on first write."""
        self.strict = strict
        """When True (the structure was declared), writing an undeclared edge is an error."""
        self._lock = ReadWriteLock()
        self._adjacent: dict[str, list[Edge]] = {}
        self._edges: dict[tuple[str, str], Edge] = {}
        self._joints: dict[str, AxisEdge] = {}
        self._models: dict[str, KinematicModel] = {}
        self._queries: dict[tuple[str, str], Query] = {}
        self.version = 0
        self.structure_version = 0
        self._reported_unknown_joints: set[str] = set()
        self._last_change: tuple[int, Dependency | None] = (-1, None)
        """(graph version, the edge) of the last write that changed exactly one edge: a query one
        version behind knows what changed without comparing every version on its path."""

    # --- structure ------------------------------------------------------------------------------
    @property
    def frames(self) -> list[str]:
        return list(self._adjacent)

    @property
    def edges(self) -> list[Edge]:
        return list(self._edges.values())

    @property
    def models(self) -> dict[str, KinematicModel]:
        return dict(self._models)

    def add_frame(self, name: str) -> None:
        with self._lock.write():
            self._add_frame(name)

    def _add_frame(self, name: str) -> None:
        if name not in self._adjacent:
            self._adjacent[name] = []
            self.structure_version += 1
            self.version += 1

    def add_edge(self, edge: Edge) -> Edge:
        """Add an edge of any kind (its frames are created as needed)."""
        with self._lock.write():
            key = (edge.parent, edge.child)
            if key in self._edges or (edge.child, edge.parent) in self._edges:
                raise TransformError(f"frames {edge.parent} and {edge.child} are already joined by "
                                     f"{self._edges.get(key) or self._edges[(edge.child, edge.parent)]!r}")
            if isinstance(edge, AxisEdge) and edge.joint in self._joints:
                raise TransformError(f"joint {edge.joint} already drives edge {self._joints[edge.joint].name}")
            self._add_frame(edge.parent)
            self._add_frame(edge.child)
            self._edges[key] = edge
            self._adjacent[edge.parent].append(edge)
            self._adjacent[edge.child].append(edge)
            if isinstance(edge, AxisEdge):
                self._joints[edge.joint] = edge
            if isinstance(edge, ModelEdge):
                self._models[edge.model.name] = edge.model
            self.structure_version += 1
            self.version += 1
        self._notify([], structure_changed=True)
        return edge

    def add_single_link_model(self, model: KinematicModel, frame: str) -> None:
        """A model with one link and no joint (no edge names it): its frame, and the model by name, so
        that what looks the model up (a display drawing it) finds it as it finds the others."""
        with self._lock.write():
            if model.name in self._models:
                raise TransformError(f"the graph already has a model named {model.name!r}")
            self._add_frame(frame)
            self._models[model.name] = model
        self._notify([], structure_changed=True)

    def add_static(self, parent: str, child: str, transform: np.ndarray = se3.IDENTITY) -> StaticEdge:
        edge = self.add_edge(StaticEdge(parent, child, transform))
        assert isinstance(edge, StaticEdge)
        return edge

    def add_dynamic(self, parent: str, child: str, capacity: int | None = None) -> DynamicEdge:
        edge = self.add_edge(DynamicEdge(parent, child, capacity or self.history))
        assert isinstance(edge, DynamicEdge)
        return edge

    def add_axis(self, parent: str, child: str, joint: str, joint_type: str, origin: np.ndarray = se3.IDENTITY,
                 axis: Iterable[float] = (0.0, 0.0, 1.0), value: float = 0.0) -> AxisEdge:
        edge = self.add_edge(AxisEdge(parent, child, joint, joint_type, origin, tuple(axis), value))
        assert isinstance(edge, AxisEdge)
        return edge

    def remove_edge(self, parent: str, child: str) -> None:
        """Remove an edge (e.g. a temporary registration path); frames stay."""
        with self._lock.write():
            edge = self.edge(parent, child)
            del self._edges[(edge.parent, edge.child)]
            self._adjacent[edge.parent].remove(edge)
            self._adjacent[edge.child].remove(edge)
            if isinstance(edge, AxisEdge):
                self._joints.pop(edge.joint, None)
            self.structure_version += 1
            self.version += 1
        self._notify([edge], structure_changed=True)

    def edge(self, parent: str, child: str) -> Edge:
        """The edge between two frames, in either direction."""
        edge = self._edges.get((parent, child)) or self._edges.get((child, parent))
        if edge is None:
            for frame in (parent, child):
                self._check_frame(frame)
            raise TransformError(f"no edge joins {parent} and {child}")
        return edge

    def _check_frame(self, frame: str) -> None:
        if frame not in self._adjacent:
            raise TransformError(f"unknown frame {frame!r}; {did_you_mean(frame, self._adjacent)}")

    # --- writes ---------------------------------------------------------------------------------
    def set_transform(self, parent: str, child: str, transform: np.ndarray, stamp: float | None = None,
                      cause: Stamp | None = None) -> None:
        """Write ``T_parent_child``: a sample of a dynamic edge (created on first write unless the
        structure is strict) or, when not strict, a new value of a static edge. ``cause``: the stamp
        of the input it came from, kept on the edge (:attr:`Dependency.cause`) for latency."""
        matrix = se3.frozen(se3.as_transform(transform))  # a bad matrix changes nothing
        if stamp is not None:
            stamp = _finite_time(stamp, "stamp")  # a NaN stamp would break the history's order
        with self._lock.write():
            edge = self._edges.get((parent, child))
            if edge is None:
                if (child, parent) in self._edges:
                    raise TransformError(f"edge {parent}->{child} is declared as {child}->{parent}; "
                                         "write it in that direction")
                if self.strict:
                    raise TransformError(f"edge {parent}->{child} is not declared; declared edges: "
                                         f"{', '.join(sorted(e.name for e in self._edges.values())) or 'none'}")
            created = edge is None
            if edge is None:
                edge = DynamicEdge(parent, child, self.history)
                self._add_frame(parent)
                self._add_frame(child)
                self._edges[(parent, child)] = edge
                self._adjacent[parent].append(edge)
                self._adjacent[child].append(edge)
                self.structure_version += 1
            if isinstance(edge, DynamicEdge):
                changed = edge.assign(matrix, _time.time() if stamp is None else stamp, checked=True)
            elif isinstance(edge, StaticEdge) and not self.strict:
                changed = edge.assign(matrix, checked=True)
            elif isinstance(edge, StaticEdge):
                raise TransformError(f"edge {edge.name} is declared static: a new calibration goes through "
                                     "set_static(), samples only to dynamic edges")
            elif isinstance(edge, ModelEdge):
                raise TransformError(f"edge {edge.name} belongs to kinematic model {edge.model.name}"
                                     f"{f' (joint {edge.joint})' if edge.joint else ''}: it moves with the "
                                     "model's joint values, set through set_joints()")
            else:
                raise TransformError(f"edge {edge.name} is an {edge.kind.value} edge driven by joint "
                                     f"{getattr(edge, 'joint', '?')}: set its joint value instead")
            if changed or created:
                edge.cause = cause
                self.version += 1
                self._last_change = (self.version, edge)
        if changed or created:
            self._notify([edge], structure_changed=created)

    def set_static(self, parent: str, child: str, transform: np.ndarray) -> None:
        """Replace the value of a static edge (a new calibration), in either direction."""
        with self._lock.write():
            edge = self.edge(parent, child)
            if not isinstance(edge, StaticEdge):
                raise TransformError(f"edge {edge.name} is a {edge.kind.value} edge, not a static one")
            edge.assign(transform if edge.parent == parent else se3.inverse(np.asarray(transform, dtype=float)))
            self.version += 1
        self._notify([edge])

    def place_static(self, parent: str, child: str, transform: np.ndarray) -> bool:
        """Make ``parent -> child`` a static edge with this value, as tf2 treats /tf_static: add it,
        replace its value (a new calibration), or nothing when it already has this value (a static
        broadcaster re-sends its whole set). Returns whether the graph changed; an edge of another
        kind is a :class:`TransformError`."""
        matrix = se3.frozen(se3.as_transform(transform))
        with self._lock.write():
            edge = self._edges.get((parent, child)) or self._edges.get((child, parent))
        if edge is None:
            try:
                self.add_edge(StaticEdge(parent, child, matrix))
                return True
            except TransformError:  # another writer added it meanwhile: replace its value below
                edge = self.edge(parent, child)
        if not isinstance(edge, StaticEdge):
            raise TransformError(f"edge {edge.name} is a {edge.kind.value} edge of the graph, not a static "
                                 "one: a static transform cannot set it")
        value = matrix if edge.parent == parent else se3.frozen(se3.inverse(matrix))
        if np.array_equal(edge.transform(), value):
            return False
        self.set_static(edge.parent, edge.child, value)
        return True

    def reading(self) -> ContextManager[None]:
        """Hold the read lock: several lookups inside see one consistent state of the graph."""
        return self._lock.read()

    def set_joint(self, joint: str, value: float) -> None:
        """Set one joint value (axis edge or joint of a kinematic model)."""
        unknown = self.set_joints({joint: value})
        if unknown:
            raise TransformError(f"unknown joint {joint!r}; {did_you_mean(joint, self.joint_names)}")

    def set_joints(self, values: Mapping[str, float], cause: Stamp | None = None) -> list[str]:
        """Set many joint values at once (a JointState): each kinematic model updates in bulk.
        ``cause``: the stamp of the input they came from, kept on what changed (for latency).

        Returns the names nothing in the graph drives; each is also logged once, as
        robot_state_publisher does, and otherwise ignored.
        """
        changed: list[Dependency] = []
        for name, value in values.items():  # nothing changes when one value is wrong
            if not isinstance(value, (int, float, np.number)) or isinstance(value, bool) or not math.isfinite(value):
                raise EdgeError(f"joint {name}: expected a finite number, got {value!r}")
        with self._lock.write():
            remaining = dict(values)
            for model in self._models.values():
                before = model.version
                unknown = set(model.set_positions(remaining))
                if model.version != before:  # same values again: no callbacks, caches stay valid
                    changed.append(model)
                if len(unknown) != len(remaining):
                    remaining = {name: value for name, value in remaining.items() if name in unknown}
            for name in list(remaining):
                edge = self._joints.get(name)
                if edge is not None:
                    value = remaining.pop(name)
                    if edge.value != value:
                        edge.assign(value)
                        changed.append(edge)
            self._changed_by(changed, cause)
        self._report_unknown_joints(remaining)
        self._notify(changed)
        return list(remaining)

    def set_joint_array(self, names: tuple[str, ...], positions: np.ndarray, cause: Stamp | None = None) -> list[str]:
        """:meth:`set_joints` for values as they arrive in a JointState: names and an array, kept an
        array down to the kinematic models (:meth:`KinematicModel.set_array`). Refused, changing
        nothing: a length that differs from the names', a non-finite value. ``cause``: the stamp of
        the input they came from, kept on what changed (for latency)."""
        if type(positions) is not np.ndarray or positions.dtype != np.float64:
            positions = np.asarray(positions, dtype=float)
        if positions.shape != (len(names),):
            raise EdgeError(f"joint sample with {len(names)} names but {positions.size} positions: refused")
        values = positions.tolist()
        if not math.isfinite(sum(values)):  # NaN and infinities make the sum non-finite (and so may
            # huge finite values, which pass); a Python sum of a list is 2.5x cheaper than numpy's
            bad = next((i for i, value in enumerate(values) if not math.isfinite(value)), None)
            if bad is not None:
                raise EdgeError(f"joint {names[bad]}: expected a finite number, got {positions[bad]!r}")
        changed: list[Dependency] = []
        left: list[str] = []
        with self._lock.write():
            remaining: tuple[str, ...] = names
            for model in self._models.values():
                before = model.version
                unknown = model.set_array(names, positions)
                if model.version != before:
                    changed.append(model)
                remaining = unknown if remaining is names else tuple(n for n in remaining if n in unknown)
            if remaining:
                joints = self._joints
                for name in remaining:
                    edge = joints.get(name)
                    if edge is None:
                        left.append(name)
                        continue
                    value = values[names.index(name)]
                    if edge.value != value:
                        edge.assign(value)
                        changed.append(edge)
            self._changed_by(changed, cause)
        if left:
            self._report_unknown_joints(left)
        if changed:
            self._notify(changed)
        return left

    def _changed_by(self, changed: list[Dependency], cause: Stamp | None) -> None:
        """Joint values changed ``changed`` (under the write lock): they keep the stamp of the input
        that caused it (for latency), and the graph's version moves on."""
        if changed:
            for dependency in changed:
                dependency.cause = cause
            self.version += 1

    def _report_unknown_joints(self, names: Iterable[str]) -> None:
        """Log once each joint name that nothing in the graph drives, as robot_state_publisher does."""
        new = [name for name in names if name not in self._reported_unknown_joints]
        if new:
            self._reported_unknown_joints.update(new)
            log.warning("ignoring joint(s) that no edge or model has: %s", ", ".join(sorted(new)))

    @property
    def joint_names(self) -> list[str]:
        names = list(self._joints)
        for model in self._models.values():
            names.extend(model.joint_names)
        return names

    # --- reads ----------------------------------------------------------------------------------
    def lookup(self, target: str, source: str, time: float | None = None) -> np.ndarray:
        """``T_target_source``: maps coordinates in ``source`` to ``target`` (the pose of ``source``
        in ``target``). With ``time``, dynamic edges are interpolated at that time (not cached)."""
        if time is None:
            query = self._queries.get((target, source))
            if query is not None and query.graph_version == self.version:
                return query.value
            return self._refresh(query or self._new_query(target, source))
        time = _finite_time(time, "time")
        with self._lock.read():
            steps = self._resolve(target, source)
            return self._product(steps, time)

    def query(self, target: str, source: str) -> Query:
        """The query object for ``(target, source)``, e.g. to register callbacks; the frames and the
        path between them may not exist yet."""
        return self._queries.get((target, source)) or self._new_query(target, source)

    def path(self, target: str, source: str) -> list[str]:
        """Frames from ``target`` to ``source`` along the path lookups use."""
        with self._lock.read():
            return self._path_frames(target, source)

    def _new_query(self, target: str, source: str) -> Query:
        query = Query(self, target, source)
        return self._queries.setdefault((target, source), query)

    def _resolve_path(self, query: Query) -> None:
        """(Re)compute the query's path after a structure change; the read lock is held."""
        if query.structure_version == self.structure_version:
            return
        steps = self._resolve(query.target, query.source)
        dependencies = tuple(dict.fromkeys(step.dependency for step in steps))
        if query.callbacks:
            for old in query.dependencies:
                old.watchers.discard(query)
            for new in dependencies:
                new.watchers.add(query)
        query.steps, query.dependencies = steps, dependencies
        query.structure_version = self.structure_version
        query.versions = ()
        query.step_versions = []
        query.positions = ({step.dependency: index for index, step in enumerate(steps)}
                           if len(dependencies) == len(steps) else {})

    def _refresh(self, query: Query) -> np.ndarray:
        with self._lock.read():
            version = self.version
            if len(query.steps) == 1 and query.structure_version == self.structure_version:
                # One step (a robot's base to its gripper): the step caches its own value per version.
                query.value = query.steps[0].value(None)
                query.graph_version = version
                return query.value
            last_version, last_edge = self._last_change
            if (last_version == version and query.graph_version == version - 1 and query.step_versions
                    and query.structure_version == self.structure_version):
                # Exactly one write since this query's value: one edge changed, known without scanning.
                assert last_edge is not None  # a version after the first write names its edge
                index = query.positions.get(last_edge)
                if index is None and last_edge not in query.dependencies:
                    query.graph_version = version  # off the path: the value stands
                    return query.value
                if index is not None and index <= query.prefix_valid and index + 1 >= query.suffix_valid:
                    query.value = self._replace_step(query, index)
                    query.step_versions[index] = last_edge.version
                    query.versions = None  # the slow path compares step_versions instead
                    query.graph_version = version
                    return query.value
            self._resolve_path(query)
            versions = tuple(dependency.version for dependency in query.dependencies)
            if versions != query.versions:
                query.value = self._evaluate(query)
                query.versions = versions
            query.graph_version = version
            return query.value

    @staticmethod
    def _evaluate(query: Query) -> np.ndarray:
        """The query's value after some steps changed, from cached partial products.

        The common change is one edge of a long path (a tracked object under a chain of static
        edges): the value is then ``prefix[k] @ step_k @ suffix[k+1]``, two matrix products instead
        of one per hop; the prefix products before the change and the suffix products after it stay
        valid for the next change of the same edge. Any other change rebuilds every prefix and suffix
        product (twice the products of a plain evaluation, once).
        """
        steps = query.steps
        count = len(steps)
        if count < 3:  # nothing to save
            query.step_versions = []
            return TransformGraph._product(steps, None)
        now = [step.dependency.version for step in steps]
        old = query.step_versions
        query.step_versions = now
        if len(old) == count:
            changed = [k for k in range(count) if now[k] != old[k]]
            if not changed:
                return query.value
            low, high = changed[0], changed[-1]
            if low == high and low <= query.prefix_valid and low + 1 >= query.suffix_valid:
                return TransformGraph._replace_step(query, low)
            if low <= query.prefix_valid and high + 1 >= query.suffix_valid:
                result = query.prefix[low] if low else None
                for k in range(low, high + 1):
                    value = steps[k].value(None)
                    result = value if result is None else result @ value
                assert result is not None  # the loop ran at least once (low <= high)
                if high + 1 < count:
                    result = result @ query.suffix[high + 1]
                query.prefix_valid, query.suffix_valid = low, high + 1
                return se3.frozen(result) if result.flags.writeable else result
        values = [step.value(None) for step in steps]
        prefix = [se3.IDENTITY, values[0]]
        for value in values[1:]:
            prefix.append(prefix[-1] @ value)
        suffix = [se3.IDENTITY] * (count + 1)
        suffix[count - 1] = values[-1]
        for k in range(count - 2, -1, -1):
            suffix[k] = values[k] @ suffix[k + 1]
        query.prefix, query.suffix = prefix, suffix
        query.prefix_valid, query.suffix_valid = count, 0
        return se3.frozen(prefix[count])

    @staticmethod
    def _replace_step(query: Query, index: int) -> np.ndarray:
        """The value when only step ``index`` changed: ``prefix[index] @ step @ suffix[index + 1]``."""
        value = query.steps[index].value(None)
        if index:
            value = query.prefix[index] @ value
        if index + 1 < len(query.steps):
            value = value @ query.suffix[index + 1]
        query.prefix_valid, query.suffix_valid = index, index + 1
        return se3.frozen(value) if value.flags.writeable else value

    @staticmethod
    def _product(steps: list[_Step], time: float | None) -> np.ndarray:
        if not steps:
            return se3.IDENTITY
        result = steps[0].value(time)
        for step in steps[1:]:
            result = result @ step.value(time)
        return se3.frozen(result) if len(steps) > 1 else result

    def _path_frames(self, target: str, source: str) -> list[str]:
        self._check_frame(target)
        self._check_frame(source)
        # Search in one canonical direction, so (a, b) and (b, a) walk the same path in a cycle.
        start, goal = sorted((target, source))
        previous = self._search(start, goal)
        if goal not in previous:
            reachable = sorted(previous if target == start else self._search(target, None))
            shown = ", ".join(reachable[:12]) + (" ..." if len(reachable) > 12 else "")
            raise TransformError(f"no path from {target} to {source}: {target} only reaches {shown}")
        frames = [goal]
        while frames[-1] != start:
            link = previous[frames[-1]]
            assert link is not None
            frames.append(link[0])
        return frames[::-1] if target == start else frames

    def _search(self, start: str, goal: str | None) -> dict[str, tuple[str, Edge] | None]:
        """Breadth-first from ``start`` until ``goal`` (or everything reachable): frame -> how reached."""
        previous: dict[str, tuple[str, Edge] | None] = {start: None}
        frontier = deque([start])
        while frontier and goal not in previous:
            frame = frontier.popleft()
            for edge in self._adjacent[frame]:
                other = edge.child if edge.parent == frame else edge.parent
                if other not in previous:
                    previous[other] = (frame, edge)
                    frontier.append(other)
        return previous

    def _resolve(self, target: str, source: str) -> list[_Step]:
        frames = self._path_frames(target, source)
        steps: list[_Step] = []
        index = 0
        while index < len(frames) - 1:
            edge = self.edge(frames[index], frames[index + 1])
            if isinstance(edge, ModelEdge):
                end = index + 1
                while end < len(frames) - 1:
                    following = self.edge(frames[end], frames[end + 1])
                    if not (isinstance(following, ModelEdge) and following.model is edge.model):
                        break
                    end += 1
                steps.append(_Segment(edge.model, frames[index], frames[end]))
                index = end
                continue
            steps.append(_Forward(edge) if edge.parent == frames[index] else _Backward(edge))
            index += 1
        return steps

    def _notify(self, changed: Iterable[Dependency], structure_changed: bool = False) -> None:
        """Run the callbacks of every query whose path went through a changed edge or model.

        After a structure change every query with callbacks is looked up again: its path may now be
        shorter or different, and its callbacks must follow the new path from now on.
        """
        queries: dict[int, Query] = {}
        for dependency in changed:
            for query in list(dependency.watchers):
                if query.callbacks:  # a query nobody listens to is computed when it is looked up
                    queries[id(query)] = query
        if structure_changed:
            for query in list(self._queries.values()):
                if query.callbacks:
                    queries[id(query)] = query
        for query in queries.values():
            try:
                value = self.lookup(query.target, query.source)
            except LookupError as error:
                log.debug("query %s <- %s has no value after the change: %s", query.target, query.source, error)
                continue
            watched = any(query in dependency.watchers for dependency in changed)
            if not watched and query.notified is not None and np.array_equal(value, query.notified):
                continue  # a structure change elsewhere left this value as it was
            query.notified = value
            for callback in list(query.callbacks):
                try:
                    callback(value)
                except Exception:
                    log.exception("callback of query %s <- %s failed", query.target, query.source)

    # --- diagnostics ----------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The whole graph, JSON-ready: frames, edges with kinds, values and stamps."""
        with self._lock.read():
            edges = []
            for edge in self._edges.values():
                try:
                    edges.append(edge.describe())
                except LookupError as error:
                    edges.append({"parent": edge.parent, "child": edge.child, "kind": edge.kind.value,
                                  "error": str(error)})
            return {"version": self.version, "frames": list(self._adjacent), "edges": edges,
                    "models": sorted(self._models)}
