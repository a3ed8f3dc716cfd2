"""URDF robots in the transformation graph, their kinematics computed in bulk by Pinocchio.

:func:`load_urdf` reads a URDF (a file, a ``package://`` URL or the XML text itself), builds a
Pinocchio model and adds one :class:`~.graph.ModelEdge` per URDF joint to a graph: revolute,
continuous and prismatic joints are ``axis`` edges, fixed joints ``static`` ones, every link a frame.
Floating and planar joints are kept fixed at their origin, as robot_state_publisher does.

Joint values arrive as one name -> value mapping (a JointState) through
:meth:`~.graph.TransformGraph.set_joints`. :meth:`UrdfModel.set_positions` writes them into
Pinocchio's configuration vector through a name -> index table prepared at load time and bumps the
model's version if any value changed; nothing else happens on the write path. The first lookup that
needs the model afterwards runs ``pinocchio.forwardKinematics`` once for that version, and each
``T_a_b`` asked for is computed from the two frame placements and cached until the next change.

As robot_state_publisher does: names the model does not have (a real Baxter also publishes
``head_nod`` and ``torso_t0``, fixed joints in its URDF) are returned to the graph, which logs them
once and ignores them; a joint that never receives a value keeps 0 and is listed once after the
first update (:attr:`UrdfModel.never_set`); a mimic joint follows its leader
(``multiplier * leader + offset``) and a value given for it is ignored.
"""

from __future__ import annotations

import logging
import math
import os
import tempfile
import threading
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..files import URDF_LIMIT, FileReadError, read_regular_file
from . import se3
from .edges import EdgeKind
from .graph import KinematicModel, ModelEdge, TransformError, TransformGraph
from .resources import ResourceNotFoundError, resolve
from .urdf_visuals import UrdfVisual, parse_visuals
from ..errors import EdgeError, UrdfError

try:
    import pinocchio
except ImportError:  # reported when a URDF is loaded, so the rest of the graph works without it
    pinocchio = None

log = logging.getLogger("coco.transforms")

MOVING_TYPES = ("revolute", "continuous", "prismatic")
"""URDF joint types that become ``axis`` edges and take a value."""
FIXED_TYPES = ("fixed", "floating", "planar")
"""URDF joint types that become ``static`` edges (floating and planar stay at their origin)."""

__all__ = ["MOVING_TYPES", "ResourceNotFoundError", "UrdfError", "UrdfJoint", "UrdfModel", "UrdfVisual", "load_urdf"]


@dataclass(frozen=True)
class UrdfJoint:
    """One ``<joint>`` of a URDF, as declared (link names without the frame prefix)."""

    name: str
    type: str
    parent: str
    child: str
    lower: float | None = None
    """Position limits of revolute and prismatic joints; None for the others."""
    upper: float | None = None
    mimic: tuple[str, float, float] | None = None
    """``(leader, multiplier, offset)`` of a mimic joint."""

    @property
    def moving(self) -> bool:
        return self.type in MOVING_TYPES


@dataclass(frozen=True)
class UrdfDescription:
    """The structure of a URDF as parsed and checked before Pinocchio sees it."""

    robot: str
    links: list[str]
    joints: list[UrdfJoint]
    root: str
    visuals: list[UrdfVisual]
    """What the links look like (for a display), from the same parse."""


def parse_urdf(text: str, label: str) -> UrdfDescription:
    """Parse and check the structure of a URDF: links, joints, one tree. ``label`` names the source in
    errors. Pinocchio would reject the same mistakes, but only says "not a valid URDF model"."""
    try:
        robot = ET.fromstring(text)
    except ET.ParseError as error:
        raise UrdfError(f"{label} is not well-formed XML: {error}") from None
    if robot.tag != "robot":
        raise UrdfError(f"{label}: the root element must be <robot>, got <{robot.tag}>")
    links: list[str] = []
    for element in robot.findall("link"):
        name = element.get("name")
        if not name:
            raise UrdfError(f"{label}: a <link> has no name")
        if name in links:
            raise UrdfError(f"{label}: link {name!r} is declared twice")
        links.append(name)
    if not links:
        raise UrdfError(f"{label}: robot {robot.get('name', '?')!r} has no <link>")
    known = set(links)
    joints: list[UrdfJoint] = []
    parents: dict[str, str] = {}
    for element in robot.findall("joint"):
        joints.append(_parse_joint(element, label, known, parents))
    names = {joint.name for joint in joints}
    if len(names) != len(joints):
        twice = sorted({joint.name for joint in joints if sum(j.name == joint.name for j in joints) > 1})
        raise UrdfError(f"{label}: joint(s) declared twice: {', '.join(twice)}")
    by_name = {joint.name: joint for joint in joints}
    for joint in joints:
        if joint.mimic is not None:
            leader = by_name.get(joint.mimic[0])
            if leader is None or not leader.moving:
                what = "is not a joint of the robot" if leader is None else f"is a {leader.type} joint"
                raise UrdfError(f"{label}: joint {joint.name} mimics {joint.mimic[0]!r}, which {what}")
    roots = [link for link in links if link not in parents]
    if len(roots) != 1:
        raise UrdfError(f"{label}: a URDF is a tree with one root link, found "
                        f"{len(roots)} links without a parent joint: {', '.join(roots) or 'none (a cycle)'}")
    children: dict[str, list[str]] = {}
    for joint in joints:
        children.setdefault(joint.parent, []).append(joint.child)
    reached, stack = {roots[0]}, [roots[0]]
    while stack:
        for child in children.get(stack.pop(), ()):
            if child not in reached:
                reached.add(child)
                stack.append(child)
    if len(reached) != len(links):
        cut = sorted(known - reached)
        raise UrdfError(f"{label}: links not connected to the root {roots[0]} (a cycle?): {', '.join(cut)}")
    return UrdfDescription(robot.get("name") or "robot", links, joints, roots[0], parse_visuals(robot, label))


def _parse_joint(element: ET.Element, label: str, links: set[str], parents: dict[str, str]) -> UrdfJoint:
    name = element.get("name")
    if not name:
        raise UrdfError(f"{label}: a <joint> has no name")
    kind = element.get("type", "")
    if kind not in MOVING_TYPES + FIXED_TYPES:
        raise UrdfError(f"{label}: joint {name} has type {kind!r}; expected one of "
                        f"{', '.join(MOVING_TYPES + FIXED_TYPES)}")
    ends = []
    for tag in ("parent", "child"):
        node = element.find(tag)
        link = node.get("link") if node is not None else None
        if not link:
            raise UrdfError(f"{label}: joint {name} has no <{tag} link=...>")
        if link not in links:
            raise UrdfError(f"{label}: joint {name} names {tag} link {link!r}, which is not declared")
        ends.append(link)
    parent, child = ends
    if child in parents:
        raise UrdfError(f"{label}: link {child} is the child of two joints ({parents[child]} and {name})")
    parents[child] = name
    lower = upper = None
    if kind in ("revolute", "prismatic"):
        limit = element.find("limit")
        lower = _number(limit, "lower", 0.0, label, name)
        upper = _number(limit, "upper", 0.0, label, name)
    mimic = None
    node = element.find("mimic")
    if node is not None and kind in MOVING_TYPES:
        leader = node.get("joint")
        if not leader:
            raise UrdfError(f"{label}: the <mimic> of joint {name} names no joint")
        if leader == name:
            raise UrdfError(f"{label}: joint {name} mimics itself")
        mimic = (leader, _number(node, "multiplier", 1.0, label, name), _number(node, "offset", 0.0, label, name))
    return UrdfJoint(name, kind, parent, child, lower, upper, mimic)


def _number(element: ET.Element | None, attribute: str, default: float, label: str, joint: str) -> float:
    text = element.get(attribute) if element is not None else None
    if text is None:
        return default
    try:
        return float(text)
    except ValueError:
        raise UrdfError(f"{label}: joint {joint}: {attribute}={text!r} is not a number") from None


def _build_pinocchio(text: str, label: str) -> Any:
    """Pinocchio's model of a URDF text (no root joint, mimic joints as independent joints: the model
    makes them follow their leader itself)."""
    if pinocchio is None:
        raise UrdfError(f"cannot load {label}: URDF support needs Pinocchio (pip install pin)")
    try:
        return pinocchio.buildModelFromXML(text)
    except Exception as error:  # Pinocchio raises ValueError/RuntimeError; urdfdom prints the cause
        detail = _stderr_of(lambda: pinocchio.buildModelFromXML(text))
        raise UrdfError(f"Pinocchio cannot load {label}: {error}" + (f" ({detail})" if detail else "")) from None


def _stderr_of(call: Any) -> str:
    """What native code printed on file descriptor 2 while ``call`` ran (urdfdom reports its errors
    there, not in the exception). Only used on the error path."""
    try:
        saved = os.dup(2)
    except OSError:
        return ""
    with tempfile.TemporaryFile() as capture:
        os.dup2(capture.fileno(), 2)
        try:
            call()
        except Exception:
            pass
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        capture.seek(0)
        lines = capture.read().decode(errors="replace").splitlines()
    messages = [line.strip().removeprefix("Error:").strip() for line in lines
                if line.strip() and not line.strip().startswith("at line")]
    return "; ".join(messages)


class UrdfModel(KinematicModel):
    """A URDF robot whose link transforms Pinocchio computes; its frames are ``prefix + link``.

    ``model`` and ``data`` are Pinocchio's; ``data`` holds the joint placements of the last lookup
    (code that runs its own algorithms should use ``model.createData()``). Not thread-safe on its
    own: the graph serialises writes against lookups.
    """

    __slots__ = ("model", "data", "prefix", "joint_prefix", "source", "visuals", "root_link", "joints", "_links",
                 "_frames", "_root_ids", "_slots", "_followers", "_derived", "_nq", "_values", "_q", "_state",
                 "_unset", "_updated", "_lock", "_plans")

    def __init__(self, description: UrdfDescription, model: Any, name: str | None = None, prefix: str = "",
                 source: Path | None = None, joint_prefix: str = "") -> None:
        super().__init__(name or prefix + description.robot)
        label = str(source) if source is not None else f"URDF of {description.robot}"
        self.model = model
        self.data = model.createData()
        self.prefix = prefix
        """Prepended to every link name to make its frame name."""
        self.joint_prefix = joint_prefix
        """Prepended to every URDF joint name to make the name its value arrives under."""
        self.source = source
        """The URDF file (None when loaded from text)."""
        self.visuals = description.visuals
        """The links' visuals (mesh file names as written, relative to ``source``'s folder)."""
        self.root_link = description.root
        self.joints: dict[str, UrdfJoint] = {joint.name: joint for joint in description.joints}
        """Every URDF joint by its URDF name, as declared (unprefixed)."""
        self._links = list(description.links)
        self._frames: dict[str, int] = {}
        for link in self._links:
            frame = model.getFrameId(link, pinocchio.BODY)
            if frame >= model.nframes:
                raise UrdfError(f"{label}: Pinocchio's model has no frame for link {link}")
            self._frames[prefix + link] = frame
        # Frames rigidly attached to the universe with an identity placement (the root link).
        self._root_ids = {frame for frame in self._frames.values()
                          if model.frames[frame].parentJoint == 0 and model.frames[frame].placement.isIdentity()}

        # Layout: self._values is Pinocchio's q (a numpy array), followed by one raw angle per continuous
        # joint (whose q entries are cos, sin). A joint name maps to one slot; mimic joints and
        # continuous joints are "derived" entries written from their slot when q is built. Names are
        # the ones values arrive under: joint_prefix + URDF joint name.
        values = [float(x) for x in pinocchio.neutral(model)]
        self._nq = model.nq
        self._slots: dict[str, int] = {}
        self._derived: list[tuple[int, int, float, float, bool]] = []  # (q index, slot, mult, offset, cos/sin)
        moving = [joint for joint in description.joints if joint.moving]
        for joint in moving:
            if joint.mimic is None:
                index, size = self._q_range(joint.name, label)
                if size == 1:
                    self._slots[joint_prefix + joint.name] = index
                else:
                    self._slots[joint_prefix + joint.name] = len(values)
                    values.append(0.0)
                    self._derived.append((index, len(values) - 1, 1.0, 0.0, True))
        self._followers: dict[str, tuple[str, float, float]] = {}  # name -> independent leader, mult, offset
        for joint in moving:
            if joint.mimic is not None:
                leader, multiplier, offset = self._resolve_mimic(joint, label)
                index, size = self._q_range(joint.name, label)
                self._derived.append((index, self._slots[joint_prefix + leader], multiplier, offset, size == 2))
                self._followers[joint_prefix + joint.name] = (joint_prefix + leader, multiplier, offset)
        for joint in description.joints:
            if joint.type in ("floating", "planar"):
                log.warning("%s: %s joint %s is kept fixed at its origin (as robot_state_publisher does)",
                            label, joint.type, joint.name)
        self._values = np.array(values, dtype=float)
        self._q = self._build_q(self._values)
        self._state: tuple[int, dict[tuple[str, str], np.ndarray]] = (-1, {})
        self._unset = set(self._slots)
        self._updated = False
        self._lock = threading.Lock()
        self._plans: dict[tuple[str, ...], tuple[np.ndarray, np.ndarray, tuple[str, ...]]] = {}
        """Names of a joint sample -> (indices into its positions, slots they go to, unknown names),
        made on the first sample with these names: later samples cost one gather and one scatter."""

    def _q_range(self, joint: str, label: str) -> tuple[int, int]:
        if not self.model.existJointName(joint):
            raise UrdfError(f"{label}: Pinocchio's model has no joint {joint}")
        pin_joint = self.model.joints[self.model.getJointId(joint)]
        if pin_joint.nq not in (1, 2):
            raise UrdfError(f"{label}: joint {joint} has {pin_joint.nq} configuration values in Pinocchio")
        return pin_joint.idx_q, pin_joint.nq

    def _resolve_mimic(self, joint: UrdfJoint, label: str) -> tuple[str, float, float]:
        """Follow a chain of mimic joints to an independent leader: ``(leader, multiplier, offset)``."""
        multiplier, offset, seen = 1.0, 0.0, [joint.name]
        current = joint
        while current.mimic is not None:
            leader, factor, shift = current.mimic
            # joint = multiplier * current + offset, and current = factor * leader + shift
            multiplier, offset = multiplier * factor, multiplier * shift + offset
            if leader in seen:
                raise UrdfError(f"{label}: mimic joints form a cycle: {' -> '.join(seen + [leader])}")
            seen.append(leader)
            current = self.joints[leader]
        return current.name, multiplier, offset

    # --- description ----------------------------------------------------------------------------
    @property
    def joint_names(self) -> list[str]:
        """Joints that take a value (revolute, continuous, prismatic; not mimic joints)."""
        return list(self._slots)

    @property
    def mimic_joints(self) -> dict[str, tuple[str, float, float]]:
        """Mimic joints: name -> ``(leader, multiplier, offset)`` as declared in the URDF (names with
        the joint prefix)."""
        result = {}
        for joint in self.joints.values():
            if joint.mimic is not None:
                leader, multiplier, offset = joint.mimic
                result[self.joint_prefix + joint.name] = (self.joint_prefix + leader, multiplier, offset)
        return result

    @property
    def link_names(self) -> list[str]:
        """The URDF's links (frame names without the prefix)."""
        return list(self._links)

    @property
    def frame_names(self) -> list[str]:
        """The graph frames of the links: ``prefix + link``."""
        return list(self._frames)

    def frame(self, link: str) -> str:
        """The graph frame of a URDF link."""
        return self.prefix + link

    @property
    def limits(self) -> dict[str, tuple[float, float]]:
        """Position limits of the joints that take a value (continuous joints: ``(-inf, inf)``)."""
        result = {}
        for name in self._slots:
            joint = self.joints[name[len(self.joint_prefix):]]
            result[name] = (-math.inf, math.inf) if joint.lower is None else (joint.lower, joint.upper)
        return result  # type: ignore[return-value]

    @property
    def positions(self) -> dict[str, float]:
        """Current value of every moving joint, mimic joints included."""
        values = self._values
        result = {name: float(values[slot]) for name, slot in self._slots.items()}
        for name, (leader, multiplier, offset) in self._followers.items():
            result[name] = multiplier * result[leader] + offset
        return result

    @property
    def never_set(self) -> list[str]:
        """Joints that take a value but never received one (they keep 0)."""
        return [name for name in self._slots if name in self._unset]

    # --- writes ---------------------------------------------------------------------------------
    def set_positions(self, values: Mapping[str, float]) -> list[str]:
        """Apply a name -> value mapping in one update; returns the names this model does not have.

        Values for mimic joints are ignored (they follow their leader). The version changes only if
        a value did. Raises ``ValueError`` naming the joint for a value that is not a number (the
        model is then unchanged).
        """
        slots = self._slots
        current = self._values
        new = current.copy()
        unknown: list[str] = []
        for name, value in values.items():
            slot = slots.get(name)
            if slot is not None:
                try:
                    new[slot] = value
                except (TypeError, ValueError):
                    raise EdgeError(f"model {self.name}: joint {name} value {value!r} is not a number") from None
            elif name not in self._followers:
                unknown.append(name)
        if self._unset:
            self._unset.difference_update(values)
        if new.tobytes() != current.tobytes():
            self._q = self._build_q(new)
            self._values = new
            self.version += 1
        if not self._updated and len(unknown) != len(values):
            self._updated = True
            if self._unset:
                log.warning("model %s: joint(s) without a value after the first update keep 0 until they "
                            "get one: %s", self.name, ", ".join(self.never_set))
        return unknown

    def set_array(self, names: tuple[str, ...], positions: np.ndarray) -> tuple[str, ...]:
        """Apply joint values given as names and an array (a JointState as it arrives), without a
        mapping: the values go from the array into Pinocchio's ``q`` by one indexed copy. The caller
        checked the values (finite, as many as names). Returns the names this model does not have."""
        plan = self._plans.get(names)
        if plan is None:
            selected = [i for i, name in enumerate(names) if name in self._slots]
            unknown = tuple(name for name in names if name not in self._slots and name not in self._followers)
            plan = (np.array(selected, dtype=np.intp), np.array([self._slots[names[i]] for i in selected],
                                                                 dtype=np.intp), unknown)
            self._plans[names] = plan
        indices, slots, unknown = plan
        if self._unset:
            self._unset.difference_update(names)
        new = self._values.copy()
        new[slots] = positions[indices]
        if new.tobytes() != self._values.tobytes():  # a byte compare: 10x cheaper than array_equal
            self._q = self._build_q(new)
            self._values = new
            self.version += 1
        return unknown

    def _build_q(self, values: np.ndarray) -> np.ndarray:
        """Pinocchio's ``q`` from the slot values: a copy of its first ``nq`` entries, then the
        mimic joints and the (cos, sin) pairs of continuous joints written from their slots."""
        q = values[:self._nq].copy()
        for index, slot, multiplier, offset, circular in self._derived:
            value = multiplier * float(values[slot]) + offset
            if circular:
                q[index] = math.cos(value)
                q[index + 1] = math.sin(value)
            else:
                q[index] = value
        return q

    # --- reads ----------------------------------------------------------------------------------
    def relative(self, a: str, b: str) -> np.ndarray:
        """``T_a_b`` between two link frames (prefixed names), with the current joint values."""
        state = self._state
        if state[0] == self.version:
            value = state[1].get((a, b))
            if value is not None:
                return value
        return self._compute(a, b)

    def _compute(self, a: str, b: str) -> np.ndarray:
        with self._lock:
            state = self._state
            if state[0] != self.version:
                version = self.version
                pinocchio.forwardKinematics(self.model, self.data, self._q)
                state = self._state = (version, {})
            value = state[1].get((a, b))
            if value is not None:
                return value
            frames = self._frames
            if a not in frames or b not in frames:
                missing = a if a not in frames else b
                raise TransformError(f"frame {missing!r} is not a link of model {self.name}")
            ia, ib = frames[a], frames[b]
            if ia == ib:
                value = se3.IDENTITY
            elif ia in self._root_ids:
                value = se3.frozen(pinocchio.updateFramePlacement(self.model, self.data, ib).homogeneous)
            elif ib in self._root_ids:
                value = se3.frozen(pinocchio.updateFramePlacement(self.model, self.data, ia).inverse().homogeneous)
            else:
                placement_a = pinocchio.updateFramePlacement(self.model, self.data, ia)
                placement_b = pinocchio.updateFramePlacement(self.model, self.data, ib)
                value = se3.frozen(placement_a.actInv(placement_b).homogeneous)
            state[1][(a, b)] = value
            return value

    def placement(self, link: str) -> np.ndarray:
        """``T_root_link`` of a URDF link (unprefixed name), with the current joint values."""
        return self.relative(self.prefix + self.root_link, self.prefix + link)

    # --- graph ----------------------------------------------------------------------------------
    def edges(self) -> list[ModelEdge]:
        """One edge per URDF joint, parent link -> child link: ``axis`` for moving joints, ``static``
        for the others."""
        return [ModelEdge(self.prefix + joint.parent, self.prefix + joint.child, self,
                          EdgeKind.AXIS if joint.moving else EdgeKind.STATIC, self.joint_prefix + joint.name)
                for joint in self.joints.values()]

    def add_to(self, graph: TransformGraph) -> None:
        """Add the model's edges to ``graph``; nothing is added if any of them conflicts."""
        if self.name in graph.models:
            raise TransformError(f"the graph already has a model named {self.name!r}: load this one with "
                                 "another name or a frame prefix")
        edges = self.edges()
        frames = set(graph.frames)
        for edge in edges:
            if edge.parent in frames and edge.child in frames:
                try:
                    existing = graph.edge(edge.parent, edge.child)
                except TransformError:
                    continue
                raise TransformError(f"model {self.name}: joint {edge.joint} would join {edge.parent} and "
                                     f"{edge.child}, already joined by {existing!r}; use a frame prefix")
        for edge in edges:
            graph.add_edge(edge)
        if not edges:
            graph.add_single_link_model(self, self.prefix + self.root_link)

    # --- loading --------------------------------------------------------------------------------
    @classmethod
    def load(cls, source: str | os.PathLike[str], name: str | None = None, prefix: str = "",
             joint_prefix: str = "") -> UrdfModel:
        """A model from a URDF file, a ``package://`` or ``file://`` URL, or the URDF text itself."""
        text_source = isinstance(source, str) and source.lstrip().startswith("<")
        if text_source:
            path, text, label = None, str(source), "URDF text"
        else:
            path = resolve(source)
            label = str(path)
            try:
                text = read_regular_file(path, URDF_LIMIT, "URDF").decode("utf-8")
            except FileReadError as error:
                raise UrdfError(str(error)) from None
            except UnicodeDecodeError as error:
                raise UrdfError(f"cannot read URDF {path}: {error}") from None
        description = parse_urdf(text, label)
        model = _build_pinocchio(text, label)
        return cls(description, model, name=name, prefix=prefix, source=path, joint_prefix=joint_prefix)

    def __repr__(self) -> str:
        return (f"<UrdfModel {self.name}: {len(self._links)} links, {len(self._slots)} joints, "
                f"v{self.version}>")


def load_urdf(graph: TransformGraph, source: str | os.PathLike[str], name: str | None = None,
              prefix: str = "", joint_prefix: str = "") -> UrdfModel:
    """Load a URDF (file, ``package://`` URL or XML text) and add its joints to ``graph`` as edges
    between ``prefix + link`` frames. ``name`` names the model in the graph (default: ``prefix`` +
    the robot's name). Returns the model (joint names, limits, Pinocchio model and data).

    As robot_state_publisher's ``frame_prefix``, ``prefix`` renames frames only: values still arrive
    under the URDF's joint names. A name given to :meth:`~.graph.TransformGraph.set_joints` drives the
    first model that has it, so two copies of one robot in a graph also need distinct
    ``joint_prefix`` es (their JointStates then name ``joint_prefix + joint``)."""
    model = UrdfModel.load(source, name=name, prefix=prefix, joint_prefix=joint_prefix)
    model.add_to(graph)
    return model
