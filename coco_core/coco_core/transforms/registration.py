"""Registration: estimate the fixed transform between two disjoint frames from sampled measurements.

Two parts of the transformation graph that nothing joins yet (say ``world``, where the robot stands,
and ``camera``) are bridged for a while by a *temporary path*, e.g. a dynamic edge
``camera -> marker`` fed by a marker tracker while the robot holds the marker, whose pose on the
gripper is known. Each time a new measurement arrives, the whole chain ``world -> ... -> gripper ->
marker <- camera`` gives one sample of ``T_world_camera``. The samples, possibly from several
temporary paths (several markers, several robot poses), are averaged on SE(3) with outlier rejection,
the residual is reported, and the result is installed as a static edge ``world -> camera`` while the
temporary edges are removed.

The averaging on SE(3) is in :mod:`.averaging` (plain functions of arrays, for samples that come
from elsewhere too).
"""

from __future__ import annotations

import logging
import math
import threading
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Sequence, Union

import numpy as np

from . import se3
from .averaging import AverageResult, robust_average, root_mean_square
from .edges import Edge, ExtrapolationError, StaticEdge
from .graph import TransformGraph
from ..errors import RegistrationError

log = logging.getLogger("coco.transforms")

EdgeSpec = Union[Edge, Sequence[str]]
"""An edge of a temporary path: an :class:`Edge` or a ``(parent, child)`` pair."""


def _key(parent: str, child: str) -> frozenset[str]:
    return frozenset((parent, child))


def _edge_frames(spec: EdgeSpec) -> tuple[str, str]:
    if isinstance(spec, Edge):
        return spec.parent, spec.child
    if isinstance(spec, str) or len(spec) != 2 or not all(isinstance(frame, str) for frame in spec):
        raise RegistrationError(f"an edge of a temporary path is an Edge or a (parent, child) pair, got {spec!r}")
    return spec[0], spec[1]


def _path_specs(via: EdgeSpec | Sequence[EdgeSpec]) -> list[EdgeSpec]:
    """One edge, or a sequence of edges: ``("camera", "marker")`` vs ``[("camera", "x"), ("x", "marker")]``."""
    if isinstance(via, Edge) or (not isinstance(via, str) and len(via) == 2
                                 and all(isinstance(frame, str) for frame in via)):
        return [via]  # type: ignore[list-item]  # mypy does not narrow a pair of str through all()
    return list(via)


@dataclass
class MeasurementPath:
    """A temporary path of a registration: the edges that bridge the two frames while measuring."""

    name: str
    edges: tuple[tuple[str, str], ...]
    created: tuple[tuple[str, str], ...] = ()
    """Edges the registration added to the graph (dynamic ones, to be fed by a tracker)."""
    samples: int = 0
    """Samples recorded through this path."""
    last_versions: tuple[int, ...] | None = field(default=None, repr=False)

    @property
    def keys(self) -> set[frozenset[str]]:
        return {_key(parent, child) for parent, child in self.edges}


@dataclass(frozen=True)
class PathStatistics:
    """How the samples of one temporary path agree with the combined estimate (m, rad)."""

    used: int
    rejected: int
    rms_translation: float
    rms_rotation: float


@dataclass(frozen=True, eq=False)
class RegistrationResult(AverageResult):
    """The estimated ``T_parent_child`` with its residuals, overall and per temporary path."""

    parent: str = ""
    child: str = ""
    paths: dict[str, PathStatistics] = field(default_factory=dict)
    labels: tuple[str, ...] = ()
    """The path name of each sample, in the order of the residual arrays."""

    def summary(self) -> str:
        per_path = "; ".join(f"{name}: {stats.used} used, {stats.rejected} rejected, RMS "
                             f"{stats.rms_translation * 1e3:.3f} mm {math.degrees(stats.rms_rotation):.4f} deg"
                             for name, stats in self.paths.items())
        return f"{self.parent}->{self.child}: {super().summary()}" + (f" [{per_path}]" if len(self.paths) > 1 else "")

    def describe(self) -> dict[str, Any]:
        described = super().describe()
        described.update(parent=self.parent, child=self.child,
                         paths={name: vars(stats) for name, stats in self.paths.items()})
        return described


class Registration:
    """Estimate ``T_parent_child`` between two frames that no path joins yet, and install it as a
    static edge.

    Samples come from temporary paths (:meth:`add_path`, or ``via``): edges that bridge the two parts
    of the graph while measuring, e.g. ``("camera", "marker")``, a dynamic edge (created when missing)
    that a tracker feeds. :meth:`sample` records ``T_parent_child`` through every temporary path whose
    measurement changed since its last sample; :meth:`add_sample` records a measured value directly.
    Several paths are evaluated independently (each one with the other temporary edges left out, so
    that two paths open at the same time do not mix) and their samples are averaged together.
    :meth:`solve` returns the robust mean with its residuals; :meth:`install` removes the temporary
    edges and adds (or, with ``replace=True``, updates) the static edge ``parent -> child``.

    ``replace=True`` re-registers frames already joined by a static edge: the edge is taken out of
    the graph while measuring (so the temporary path closes no loop through it), and put back with the
    new value by :meth:`install`, or with its old value by :meth:`cancel`. Used as a context manager, a
    registration that was not installed is cancelled on exit.

    Take samples while the measured part is at rest: an axis edge (a robot joint) has no history, so a
    measurement is combined with the joint values of the moment it is sampled. With ``time``, dynamic
    edges on the path are interpolated at that time.
    """

    def __init__(self, graph: TransformGraph, parent: str, child: str,
                 via: EdgeSpec | Sequence[EdgeSpec] | None = None, *, replace: bool = False,
                 min_samples: int = 3) -> None:
        if parent == child:
            raise RegistrationError(f"a registration needs two different frames, got {parent!r} twice")
        self.graph = graph
        self.parent = parent
        self.child = child
        self.min_samples = min_samples
        self.paths: list[MeasurementPath] = []
        self.result: RegistrationResult | None = None
        self._samples: list[np.ndarray] = []
        self._weights: list[float] = []
        self._labels: list[str] = []
        self._lock = threading.Lock()
        self._replaced: StaticEdge | None = None
        self._closed: str | None = None
        route = self._route(set(), exclude=set())
        if route is not None:
            frames = [frame for frame, _ in route]
            direct = graph.edge(parent, child) if len(frames) == 2 else None
            if not (replace and isinstance(direct, StaticEdge)):
                hint = (" (pass replace=True to re-register it)" if isinstance(direct, StaticEdge) else "")
                raise RegistrationError(f"frames {parent} and {child} are already joined: "
                                        f"{' -> '.join(frames)}{hint}; a registration needs two disjoint frames")
            graph.remove_edge(direct.parent, direct.child)
            self._replaced = direct
            again = self._route(set(), exclude=set())
            if again is not None:
                graph.add_edge(direct)
                raise RegistrationError(f"frames {parent} and {child} are also joined by "
                                        f"{' -> '.join(frame for frame, _ in again)}; cannot re-register them")
            log.info("registration %s->%s: took the static edge out of the graph while measuring", parent, child)
        if via is not None:
            try:
                self.add_path(via)
            except BaseException:
                self.cancel()  # put a replaced edge back
                raise

    # --- temporary paths and samples -----------------------------------------------------------
    def add_path(self, edges: EdgeSpec | Sequence[EdgeSpec], name: str | None = None) -> MeasurementPath:
        """Declare a temporary path: one edge ``(parent, child)`` (or an :class:`Edge`), or several.
        Missing edges are added to the graph as dynamic edges, ready for a tracker to write. The path
        together with the rest of the graph must join the two frames. Its edges are removed by
        :meth:`install` and :meth:`cancel`."""
        self._check_open()
        frames = [_edge_frames(spec) for spec in _path_specs(edges)]
        if not frames:
            raise RegistrationError("a temporary path needs at least one edge")
        taken = {key for path in self.paths for key in path.keys}
        for parent, child in frames:
            if _key(parent, child) in taken:
                raise RegistrationError(f"edge {parent}->{child} is already part of another temporary path")
            if _key(parent, child) == _key(self.parent, self.child):
                raise RegistrationError(f"edge {parent}->{child} is the one being registered; it cannot be "
                                        "part of a temporary path")
        name = name or ", ".join(f"{parent}->{child}" for parent, child in frames)
        if any(existing.name == name for existing in self.paths):
            raise RegistrationError(f"a temporary path is already named {name!r}")
        created: list[tuple[str, str]] = []
        existing = self._existing_edges()
        for parent, child in frames:
            if (parent, child) not in existing and (child, parent) not in existing:
                self.graph.add_dynamic(parent, child)
                created.append((parent, child))
        path = MeasurementPath(name, tuple(frames), tuple(created))
        try:
            self._resolve(path)
        except RegistrationError:
            for parent, child in created:
                self.graph.remove_edge(parent, child)
            raise
        self.paths.append(path)
        return path

    def sample(self, time: float | None = None, *, only_new: bool = True) -> int:
        """Record ``T_parent_child`` through each temporary path; return how many samples were recorded.

        A path is skipped while a dynamic edge on it has no value (at ``time``), and, with ``only_new``,
        when none of its temporary edges changed since its last sample (the tracker has not sent a new
        measurement, so the same value would count twice).
        """
        self._check_open()
        recorded: list[tuple[MeasurementPath, np.ndarray, tuple[int, ...]]] = []
        with self._reading():
            for path in self.paths:
                route = self._resolve(path)
                keys = path.keys
                versions = tuple(edge.version for _, edge in route[1:]
                                 if edge is not None and _key(edge.parent, edge.child) in keys)
                if only_new and versions == path.last_versions:
                    continue
                try:
                    value = self._product(route, time)
                except ExtrapolationError:
                    continue
                recorded.append((path, value, versions))
        with self._lock:
            for path, value, versions in recorded:
                path.last_versions = versions
                path.samples += 1
                self._samples.append(value)
                self._weights.append(1.0)
                self._labels.append(path.name)
        return len(recorded)

    def add_sample(self, transform: np.ndarray, *, weight: float = 1.0, label: str = "manual") -> None:
        """Record a measured ``T_parent_child`` directly (from any source)."""
        self._check_open()
        value = se3.as_transform(transform)
        if not (math.isfinite(weight) and weight >= 0.0):
            raise RegistrationError(f"a sample's weight must be finite and non-negative, got {weight}")
        with self._lock:
            self._samples.append(value)
            self._weights.append(float(weight))
            self._labels.append(label)

    @property
    def sample_count(self) -> int:
        return len(self._samples)

    @property
    def samples(self) -> np.ndarray:
        """The recorded samples of ``T_parent_child``, shape ``(n, 4, 4)`` (a copy)."""
        with self._lock:
            return np.array(self._samples).reshape(-1, 4, 4)

    def clear(self) -> None:
        """Forget the recorded samples (e.g. after moving the camera); the paths stay."""
        with self._lock:
            self._samples.clear()
            self._weights.clear()
            self._labels.clear()
            for path in self.paths:
                path.samples = 0
                path.last_versions = None

    # --- result ----------------------------------------------------------------------------------
    def solve(self, **options: Any) -> RegistrationResult:
        """The robust mean of the samples (options of :func:`robust_average`: ``threshold``,
        ``max_translation``, ``max_rotation``, ...), with residuals overall and per path."""
        with self._lock:
            samples, weights, labels = list(self._samples), list(self._weights), tuple(self._labels)
        options.setdefault("min_samples", self.min_samples)
        if len(samples) < options["min_samples"]:
            sources = ", ".join(path.name for path in self.paths) or "add_sample()"
            raise RegistrationError(
                f"registration {self.parent}->{self.child} needs at least {options['min_samples']} samples, "
                f"got {len(samples)} (from {sources})")
        average = robust_average(samples, weights, **options)
        per_path: dict[str, PathStatistics] = {}
        names = np.array(labels)
        for name in dict.fromkeys(labels):
            mine = names == name
            kept = mine & average.inliers
            per_path[name] = PathStatistics(int(np.count_nonzero(kept)), int(np.count_nonzero(mine & ~average.inliers)),
                                            root_mean_square(average.translation_residuals[kept]),
                                            root_mean_square(average.rotation_residuals[kept]))
        result = RegistrationResult(average.transform, average.inliers, average.translation_residuals,
                                    average.rotation_residuals, average.translation_threshold,
                                    average.rotation_threshold, average.iterations, self.parent, self.child,
                                    per_path, labels)
        self.result = result
        return result

    def install(self, result: RegistrationResult | None = None, **options: Any) -> RegistrationResult:
        """Solve (unless ``result`` is given), remove the temporary edges, and install the estimate as
        the static edge ``parent -> child`` (updating the replaced edge with ``replace=True``)."""
        self._check_open()
        if result is None:
            result = self.solve(**options)
        elif (result.parent, result.child) != (self.parent, self.child):
            raise RegistrationError(f"the result is for {result.parent}->{result.child}, not "
                                    f"{self.parent}->{self.child}")
        route = self._route(set(), exclude={key for path in self.paths for key in path.keys})
        if route is not None:
            raise RegistrationError(f"frames {self.parent} and {self.child} got joined meanwhile: "
                                    f"{' -> '.join(frame for frame, _ in route)}; not installing")
        self._remove_paths()
        if self._replaced is not None:
            edge, self._replaced = self._replaced, None
            edge.assign(result.transform if edge.parent == self.parent else se3.inverse(result.transform))
            self.graph.add_edge(edge)
        else:
            self.graph.add_static(self.parent, self.child, result.transform)
        self._closed = "installed"
        log.info("registration installed %s", result.summary())
        return result

    def cancel(self) -> None:
        """Remove the temporary edges and put back the replaced edge, if any; install nothing."""
        if self._closed:
            return
        self._remove_paths()
        if self._replaced is not None:
            edge, self._replaced = self._replaced, None
            self.graph.add_edge(edge)
        self._closed = "cancelled"

    def __enter__(self) -> Registration:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.cancel()

    def __repr__(self) -> str:
        state = self._closed or f"{len(self._samples)} samples"
        return f"<Registration {self.parent}->{self.child} via {[p.name for p in self.paths]} ({state})>"

    # --- internals -------------------------------------------------------------------------------
    def _check_open(self) -> None:
        if self._closed:
            raise RegistrationError(f"registration {self.parent}->{self.child} is already {self._closed}")

    def _existing_edges(self) -> set[tuple[str, str]]:
        return {(edge.parent, edge.child) for edge in self.graph.edges}

    def _remove_paths(self) -> None:
        existing = self._existing_edges()
        for path in self.paths:
            for parent, child in path.edges:
                if (parent, child) in existing or (child, parent) in existing:
                    self.graph.remove_edge(parent, child)

    def _reading(self) -> Any:
        """The graph's read lock, so that a sample sees one consistent state of all its edges."""
        return self.graph.reading()

    def _route(self, allowed: set[frozenset[str]], exclude: set[frozenset[str]]
               ) -> list[tuple[str, Edge | None]] | None:
        """Fewest-hop route ``parent .. child`` as ``[(frame, edge that led there)]``, skipping the
        edges in ``exclude`` unless they are in ``allowed``; None when there is none."""
        adjacent: dict[str, list[Edge]] = {}
        for edge in self.graph.edges:
            key = _key(edge.parent, edge.child)
            if key in exclude and key not in allowed:
                continue
            adjacent.setdefault(edge.parent, []).append(edge)
            adjacent.setdefault(edge.child, []).append(edge)
        if self.parent not in adjacent or self.child not in adjacent:
            return None
        previous: dict[str, tuple[str, Edge] | None] = {self.parent: None}
        frontier = deque([self.parent])
        while frontier and self.child not in previous:
            frame = frontier.popleft()
            for edge in adjacent[frame]:
                other = edge.child if edge.parent == frame else edge.parent
                if other not in previous:
                    previous[other] = (frame, edge)
                    frontier.append(other)
        if self.child not in previous:
            return None
        route: list[tuple[str, Edge | None]] = []
        frame = self.child
        while True:
            link = previous[frame]
            route.append((frame, link[1] if link else None))
            if link is None:
                return route[::-1]
            frame = link[0]

    def _resolve(self, path: MeasurementPath) -> list[tuple[str, Edge | None]]:
        temporary = {key for other in self.paths for key in other.keys} | path.keys
        route = self._route(path.keys, exclude=temporary)
        if route is None:
            existing = self._existing_edges()
            missing = [f"{p}->{c}" for p, c in path.edges if (p, c) not in existing and (c, p) not in existing]
            reason = (f"edge(s) {', '.join(missing)} were removed" if missing else
                      f"the rest of the graph does not link its ends to {self.parent} and {self.child}")
            raise RegistrationError(
                f"temporary path {path.name} does not join {self.parent} and {self.child}: {reason}")
        if not any(edge is not None and _key(edge.parent, edge.child) in path.keys for _, edge in route):
            raise RegistrationError(f"frames {self.parent} and {self.child} are joined without a temporary path: "
                                    f"{' -> '.join(frame for frame, _ in route)}")
        return route

    @staticmethod
    def _product(route: list[tuple[str, Edge | None]], time: float | None) -> np.ndarray:
        result = np.eye(4)
        for (frame, _), (_, edge) in zip(route, route[1:]):
            assert edge is not None
            if edge.parent == frame:
                step = edge.transform() if time is None else edge.transform_at(time)
            else:
                step = edge.inverse() if time is None else se3.inverse(edge.transform_at(time))
            result = result @ step
        return result
