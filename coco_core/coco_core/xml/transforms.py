"""``<transforms>`` (extension): the declared structure of the application's transformation graph.

Declaring the structure is optional. When an application declares it, it says which frames exist and
which edges join them, with their kinds (``static``, ``dynamic``, ``axis``) and URDF robots, and by
default it becomes *strict*: a component that writes an edge that is not declared, or writes an
edge of the wrong kind, gets an error that names the edge, instead of silently growing the graph
(a typo in a frame name would otherwise create a second, disconnected frame that nobody reads).

Every file may have ``<transforms>`` sections (an included sub-application declares the frames it
publishes): they are merged in document order. The checks that need all of them (an edge or a joint
declared twice, URDF files searched in the resource paths) run with the other whole-application
checks, from :mod:`.references`. Poses are turned into 4x4 matrices here, so that the builder only
installs them and a wrong number is reported at its line.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from ..errors import AttributeValueError, ConfigError, Location
from ..files import URDF_LIMIT, FileReadError, check_regular_file
from ..model import EdgeSpec, FrameSpec, TransformsSpec, UrdfSpec
from ..transforms import se3
from ..transforms.edges import JointType
from .reader import CONDITIONS, FileReader
from .resources import find_resource, not_found_message
from .tree import Element
from .values import parse_bool, parse_int, parse_number

TRANSFORMS_ATTRIBUTES = ("history", "strict", *CONDITIONS)
TRANSFORMS_CHILDREN = ("axis", "dynamic", "frame", "static", "urdf")
POSE_ATTRIBUTES = ("quaternion", "rpy", "xyz")
FRAME_ATTRIBUTES = ("name", *CONDITIONS)
STATIC_ATTRIBUTES = ("child", "parent", *POSE_ATTRIBUTES, *CONDITIONS)
DYNAMIC_ATTRIBUTES = ("child", "history", "parent", *CONDITIONS)
AXIS_ATTRIBUTES = ("axis", "child", "dh", "joint", "parent", "type", "value", *POSE_ATTRIBUTES,
                   *CONDITIONS)
URDF_ATTRIBUTES = ("attach", "file", "joint_prefix", "name", "prefix", *POSE_ATTRIBUTES, *CONDITIONS)
JOINT_TYPES = tuple(joint_type.value for joint_type in JointType)
URL_SCHEMES = ("package://", "file://")
"""URDF names that the builder resolves (through :mod:`coco_core.transforms.resources`)."""


@dataclass
class TransformsDraft:
    """The ``<transforms>`` sections read so far, merged, with what the whole-application check
    needs: where each section setting was first given, and the directory of each URDF's file."""

    spec: TransformsSpec
    settings: dict[str, tuple[object, str, Location]] = field(default_factory=dict)
    """Setting name -> (value, text as written, where it was first given)."""
    urdf_directories: list[tuple[UrdfSpec, str]] = field(default_factory=list)


def read_transforms(
    reader: FileReader, element: Element, draft: TransformsDraft | None
) -> TransformsDraft:
    """Add a ``<transforms>`` section whose conditions held to ``draft`` (created on the first one)."""
    if draft is None:
        draft = TransformsDraft(TransformsSpec(location=element.location))
    values = reader.attributes(element, TRANSFORMS_ATTRIBUTES)
    strict = reader.parsed(element, values, "strict", parse_bool)
    if strict is not None and _setting(reader, element, draft, "strict", strict, values["strict"]):
        draft.spec.strict = strict
    history = reader.parsed(element, values, "history", _history)
    if history is not None and _setting(reader, element, draft, "history", history, values["history"]):
        draft.spec.history = history
    for child in reader.children(element, TRANSFORMS_CHILDREN):
        if not reader.kept(child):
            continue
        if child.tag == "frame":
            _read_frame(reader, child, draft.spec)
        elif child.tag == "urdf":
            urdf = _read_urdf(reader, child)
            if urdf is not None:
                draft.spec.urdfs.append(urdf)
                draft.urdf_directories.append((urdf, reader.directory))
        else:
            edge = _read_edge(reader, child)
            if edge is not None:
                draft.spec.edges.append(edge)
    return draft


def check_transforms(draft: TransformsDraft, paths: list[str]) -> list[ConfigError]:
    """The checks that need every section: each pair of frames is joined by one declared edge, each
    joint drives one edge, and relative URDF files exist (they become absolute paths)."""
    errors: list[ConfigError] = []
    edges: dict[frozenset[str], EdgeSpec] = {}
    joints: dict[str, EdgeSpec] = {}
    for edge in draft.spec.edges:
        pair = frozenset((edge.parent, edge.child))
        first = edges.setdefault(pair, edge)
        if first is not edge:
            errors.append(ConfigError(
                f"<{edge.kind}> {edge.name}: frames {edge.parent} and {edge.child} are already joined by "
                f"the {first.kind} edge {first.name} declared at {first.location}; two frames are "
                "joined by at most one edge",
                edge.location,
            ))
        if edge.kind == "axis" and edge.joint:
            first = joints.setdefault(edge.joint, edge)
            if first is not edge:
                errors.append(ConfigError(
                    f"joint {edge.joint!r} already drives edge {first.name} declared at {first.location}; "
                    "joint names are unique",
                    edge.location,
                ))
    loaded: dict[tuple[str, str, str, str], UrdfSpec] = {}
    for urdf, directory in draft.urdf_directories:
        if not urdf.file.startswith(URL_SCHEMES):
            found, tried = find_resource(urdf.file, directory, paths)
            if found is None:
                message = f"<urdf> file {not_found_message(urdf.file, tried)}"
                errors.append(ConfigError(message, urdf.location))
                continue
            try:
                check_regular_file(found, URDF_LIMIT, "<urdf> file")
            except FileReadError as error:
                errors.append(ConfigError(str(error), urdf.location))
                continue
            urdf.file = found
        first_urdf = loaded.setdefault((urdf.file, urdf.name, urdf.prefix, urdf.joint_prefix), urdf)
        if first_urdf is not urdf:
            errors.append(ConfigError(
                f"<urdf> {urdf.file} is already loaded at {first_urdf.location} with the same name, prefix "
                "and joint_prefix; give this copy another prefix= and joint_prefix=",
                urdf.location,
            ))
    return errors


def _setting(
    reader: FileReader, element: Element, draft: TransformsDraft, name: str, value: object, text: str
) -> bool:
    """Whether a section setting may take ``value``: sections are merged, so two of them must not
    disagree (which of the two would win would depend on the order of the includes)."""
    first = draft.settings.setdefault(name, (value, text, element.location))
    if first[0] == value:
        return True
    reader.error(
        f'<transforms> attribute {name}="{text}" contradicts {name}="{first[1]}" at {first[2]}; '
        f"the <transforms> sections of an application are merged: give {name}= once",
        element,
    )
    return False


def _read_frame(reader: FileReader, element: Element, spec: TransformsSpec) -> None:
    """A frame may be declared more than once: a file that is also loaded on its own declares the
    frames it uses, as its includer may."""
    values = reader.attributes(element, FRAME_ATTRIBUTES, required=("name",))
    reader.empty(element)
    name = values.get("name", "").strip()
    if name and all(frame.name != name for frame in spec.frames):
        spec.frames.append(FrameSpec(name, element.location))


def _read_edge(reader: FileReader, element: Element) -> EdgeSpec | None:
    """A ``<static>``, ``<dynamic>`` or ``<axis>``; None when its frames are missing or the same (all
    its values are read anyway, so that their errors are reported too)."""
    allowed = {"static": STATIC_ATTRIBUTES, "dynamic": DYNAMIC_ATTRIBUTES, "axis": AXIS_ATTRIBUTES}
    required = ("parent", "child", "joint", "type") if element.tag == "axis" else ("parent", "child")
    values = reader.attributes(element, allowed[element.tag], required=required)
    reader.empty(element)
    parent, child = values.get("parent", "").strip(), values.get("child", "").strip()
    edge = EdgeSpec(element.tag, parent, child, location=element.location)
    if element.tag == "static":
        edge.origin = _origin(reader, element, values)
    elif element.tag == "dynamic":
        edge.history = reader.parsed(element, values, "history", _history)
    else:
        _read_axis(reader, element, values, edge)
    if parent and parent == child:
        reader.error(
            f'<{element.tag}> parent= and child= are both "{parent}"; an edge joins two different frames',
            element,
        )
        return None
    return edge if parent and child else None


def _read_axis(reader: FileReader, element: Element, values: dict[str, str], edge: EdgeSpec) -> None:
    edge.joint = values.get("joint", "").strip()
    edge.joint_type = reader.choice(element, values, "type", JOINT_TYPES, "")
    value = reader.parsed(element, values, "value", _number("a joint value (radians or metres)"))
    edge.value = value or 0.0
    if values.get("dh", "").strip():
        geometry = [name for name in ("xyz", "rpy", "quaternion", "axis") if values.get(name, "").strip()]
        if geometry:
            reader.error(
                f"<axis> has dh= and {', '.join(name + '=' for name in geometry)}: dh= gives the whole "
                "joint geometry (d theta r alpha, moving about z); give one or the other",
                element,
            )
        expected = "4 numbers d theta r alpha (metres and radians)"
        edge.dh = reader.parsed(element, values, "dh", _vector(4, expected))
        return
    edge.origin = _origin(reader, element, values)
    axis = reader.parsed(element, values, "axis", _vector(3, "3 numbers x y z, not all zero", nonzero=True))
    if axis is not None:
        edge.axis = axis


def _read_urdf(reader: FileReader, element: Element) -> UrdfSpec | None:
    values = reader.attributes(element, URDF_ATTRIBUTES, required=("file",))
    reader.empty(element)
    file = values.get("file", "").strip()
    attach = values.get("attach", "").strip()
    origin = _origin(reader, element, values)
    if not attach:
        placed = [name for name in ("xyz", "rpy", "quaternion") if values.get(name, "").strip()]
        if placed:
            reader.error(
                f"<urdf> has {', '.join(name + '=' for name in placed)} but no attach=: they place the "
                "robot's root link in the attach= frame; give attach=",
                element,
            )
    if "://" in file and not file.startswith(URL_SCHEMES):
        reader.error(
            f'<urdf> attribute file="{file}": expected a file name, a package:// URL or a file:// URL',
            element,
        )
        return None
    if not file:
        return None
    return UrdfSpec(
        file=file,
        name=values.get("name", "").strip(),
        prefix=values.get("prefix", "").strip(),
        joint_prefix=values.get("joint_prefix", "").strip(),
        attach=attach,
        origin=origin,
        location=element.location,
    )


def _origin(reader: FileReader, element: Element, values: dict[str, str]) -> list[list[float]]:
    """The 4x4 transform of ``xyz`` and ``rpy`` or ``quaternion`` (URDF's ``<origin>`` conventions:
    metres, fixed-axis roll pitch yaw in radians; quaternions ``x y z w`` as in ROS messages).
    Wrong values are reported and count as zero, since the load fails anyway."""
    xyz = reader.parsed(element, values, "xyz", _vector(3, "3 numbers x y z (metres)")) or (0.0,) * 3
    rotations = [name for name in ("rpy", "quaternion") if values.get(name, "").strip()]
    if len(rotations) > 1:
        reader.error(
            f"<{element.tag}> has both rpy= and quaternion=; "
            "they are two ways to give the rotation: give one",
            element,
        )
        return se3.make(None, xyz).tolist()
    rotation = None
    if rotations == ["rpy"]:
        rpy = reader.parsed(element, values, "rpy", _vector(3, "3 numbers roll pitch yaw (radians)"))
        rotation = se3.rpy_to_matrix(*rpy) if rpy is not None else None
    elif rotations == ["quaternion"]:
        expected = "4 numbers x y z w, not all zero"
        quaternion = reader.parsed(element, values, "quaternion", _vector(4, expected, nonzero=True))
        rotation = se3.quaternion_to_matrix(quaternion) if quaternion is not None else None
    return se3.make(rotation, xyz).tolist()


def _vector(count: int, expected: str, nonzero: bool = False) -> Callable[[str], tuple[float, ...]]:
    """A parser of ``count`` numbers separated by white space (as URDF writes them)."""

    def parse(text: str) -> tuple[float, ...]:
        words = text.split()
        if len(words) != count:
            raise AttributeValueError(expected)
        numbers = tuple(parse_number(word, expected) for word in words)
        if nonzero and not any(numbers):
            raise AttributeValueError(expected)
        return numbers

    return parse


def _number(expected: str) -> Callable[[str], float]:
    return lambda text: parse_number(text, expected)


def _history(text: str) -> int:
    expected = "a number of samples, at least 1"
    size = parse_int(text, expected)
    if size < 1:
        raise AttributeValueError(expected)
    return size

