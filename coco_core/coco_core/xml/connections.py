"""``<connection>``: which output port feeds which input port, and with which policy or filter.

Only the component and activity names can be checked once the whole application is read (see
:mod:`.references`); port names and types are checked by the builder, which knows the classes. An
end may name an activity's ``beginit``/``endit`` port (``<src activity="..." port="endit"/>``,
:mod:`coco_core.iteration`), and a ``<filter>`` child puts a FlowVR filter on the connection's path
(:mod:`coco_core.filters`).
"""

from __future__ import annotations

import math

from ..errors import GeometryError
from ..filters import FILTERS
from ..frustum import Frustum
from ..hosts.channel import CODECS
from ..iteration import BEGIN, END, PORTS
from ..model import ConnectionSpec, FilterSpec, PortRef
from ..policy import BufferPolicy, SyncPolicy
from .reader import CONDITIONS, FileReader
from .tree import Element
from .values import parse_bool, parse_int, parse_number

CONNECTION_ATTRIBUTES = ("buffersize", "codec", "data", "event", "policy", "stamps_only", "transport", *CONDITIONS)
BUFFER_POLICIES = tuple(policy.value for policy in BufferPolicy)
SYNC_POLICIES = tuple(policy.value for policy in SyncPolicy)
SIZED = (BufferPolicy.BUFFER, BufferPolicy.CIRCULAR)
"""Policies whose size means something, so that it must be written down."""


def read_connection(reader: FileReader, element: Element) -> ConnectionSpec | None:
    """A ``<connection>`` whose conditions held; None when it lacks ``<src>`` or ``<dest>``."""
    values = reader.attributes(element, CONNECTION_ATTRIBUTES)
    data = BufferPolicy(reader.choice(element, values, "data", BUFFER_POLICIES, "DATA"))
    policy = SyncPolicy(reader.choice(element, values, "policy", SYNC_POLICIES, "LOCKED"))
    transport = values.get("transport", "").strip() or "LOCAL"
    if transport != "LOCAL":
        reader.error(
            f'<connection> attribute transport="{transport}" is not available in this version; '
            "only LOCAL (components of one process) is",
            element,
        )
    size = buffer_size(reader, element, values, data)
    event = reader.parsed(element, values, "event", parse_bool)
    stamps_only = reader.parsed(element, values, "stamps_only", parse_bool)
    codec = reader.choice(element, values, "codec", CODECS, "plain")
    children = reader.children(element, ("dest", "filter", "src"))
    src = _port(reader, element, children, "src")
    dest = _port(reader, element, children, "dest")
    filter_element = reader.once(element, children, "filter")
    filter_spec = None if filter_element is None else _filter(reader, filter_element, data, size)
    if src is None or dest is None:
        return None
    return ConnectionSpec(
        src=src,
        dest=dest,
        data=data,
        policy=policy,
        transport="LOCAL",
        buffersize=size,
        event=event,
        location=element.location,
        filter=filter_spec,
        stamps_only=bool(stamps_only),
        codec=codec,
    )


def buffer_size(
    reader: FileReader, element: Element, values: dict[str, str], data: BufferPolicy
) -> int:
    """``buffersize``: -1 or nothing means 1, which only makes sense for the unsized policies."""
    text = values.get("buffersize", "").strip()
    size = reader.parsed(element, values, "buffersize", parse_int) if text else -1
    if size is None:
        return 1
    if size == -1:
        if data in SIZED:
            reader.error(
                f"a {data.value} connection needs buffersize= (how many values it holds, at least 1)",
                element,
            )
        return 1
    if size == 0 and data not in SIZED:
        reader.warn(
            f'<{element.tag}> attribute buffersize="{text}" on a {data.value} connection is ignored: it '
            "holds the newest value only (the original CoCo ignores the size too)",
            element,
        )
        return 1
    if size < 1:
        reader.error(
            f'<{element.tag}> attribute buffersize="{text}": expected at least 1, or -1 for the default',
            element,
        )
        return 1
    return size


def _port(
    reader: FileReader, connection: Element, children: list[Element], tag: str
) -> PortRef | None:
    element = reader.once(connection, children, tag)
    if element is None:
        reader.error(f'<connection> needs a <{tag} task="..." port="..."/>', connection)
        return None
    values = reader.attributes(element, ("activity", "port", "task"), required=("port",))
    reader.empty(element)
    port = values.get("port", "").strip()
    if ("task" in element.attributes) == ("activity" in element.attributes):
        reader.error(f"<{tag}> needs either task= (a component) or activity= (an activity's "
                     f"{' or '.join(PORTS)} port), not both", element)
        return None
    if "activity" in element.attributes:
        expected = END if tag == "src" else BEGIN
        if port != expected:
            reader.error(f'<{tag} activity=...> port="{port}": an activity\'s ports are {" and ".join(PORTS)}, '
                         f"and a connection {'starts at' if tag == 'src' else 'ends at'} its {expected}", element)
            return None
        return PortRef(values.get("activity", "").strip(), port, element.location, activity=True)
    return PortRef(
        component=values.get("task", "").strip(),
        port=port,
        location=element.location,
    )


CAMERA = ("position", "look_at", "up", "fov_y", "aspect", "near", "far")
"""A Cull's frustum given as the display's camera (``GLCameraManager``'s attribute names, and the
window's aspect); ``position`` and ``look_at`` are required, the others default as the camera's."""
CAMERA_UP = (0.0, 0.0, 1.0)
CAMERA_DEFAULTS = {"fov_y": 45.0, "aspect": 4 / 3, "near": 0.05, "far": 100.0}
"""``GLCameraManager``'s defaults (and :data:`CAMERA_UP`), and the aspect of the display's default
640 x 480 window."""
FILTER_ATTRIBUTES = {"PreSignal": ("tokens",), "MaxFrequency": ("hz",), "Greedy": (), "Merge": (), "Gather": (),
                     "Split": ("by",), "Cull": ("region", "stamp", "view_projection", *CAMERA)}
"""Each filter's own attributes (beside ``type``)."""


def _filter(reader: FileReader, element: Element, data: BufferPolicy, size: int) -> FilterSpec | None:
    """``<filter type="PreSignal" tokens="N"/>``, ``<filter type="MaxFrequency" hz="F"/>``,
    ``<filter type="Greedy"/>``, ``<filter type="Merge"/>``, ``<filter type="Gather"/>``,
    ``<filter type="Split" by="stamp"/>``
    or ``<filter type="Cull" region="x0 y0 x1 y1" stamp="bbox"/>``: the filter decides the
    buffering, so ``data`` stays DATA."""
    kind = (reader.attribute(element, "type") or "").strip()
    if kind not in FILTERS:
        reader.check_attributes(element, ("type", *sorted({name for names in FILTER_ATTRIBUTES.values() for name in names})),
                                required=("type",))
        if kind:
            reader.error(f'<filter> type="{kind}" is not a filter; expected one of: {", ".join(FILTERS)}', element)
        return None
    required = {"MaxFrequency": ("type", "hz")}.get(kind, ("type",))
    values = reader.attributes(element, ("type", *FILTER_ATTRIBUTES[kind]), required=required)
    reader.empty(element)
    if data is not BufferPolicy.DATA:
        reader.error(f'a connection with a <filter> keeps what its filter keeps: leave out data="{data.value}" '
                     f"(buffersize= bounds the filter's buffer)", element)
    spec = FilterSpec(kind, location=element.location)
    if kind == "PreSignal":
        tokens = reader.parsed(element, values, "tokens", lambda text: parse_int(text, "a whole number >= 0"))
        if tokens is not None and tokens < 0:
            reader.error(f'<filter> attribute tokens="{tokens}": expected a whole number >= 0', element)
        spec.tokens = max(0, tokens or 0) if tokens is not None else 1
        if spec.tokens > size:
            reader.error(f"a PreSignal with {spec.tokens} tokens needs buffersize >= {spec.tokens} on its "
                         f"connection (it holds them all at the start), got {size}", element)
    elif kind == "MaxFrequency":
        hz = reader.parsed(element, values, "hz", lambda text: parse_number(text, "a frequency in Hz > 0"))
        if hz is not None and not 0 < hz < float("inf"):
            reader.error(f'<filter> attribute hz="{values.get("hz")}": expected a frequency in Hz > 0', element)
            hz = None
        spec.hz = hz or 0.0
        if hz is None:
            return None
    elif kind == "Split":
        spec.by = values.get("by", "").strip()
        if "by" in values and not spec.by:
            reader.error('<filter type="Split"> attribute by="": expected the name of a user stamp (a whole '
                         "number that chooses the output), or no by= to take turns", element)
    elif kind == "Cull":
        spec.stamp = values.get("stamp", "bbox").strip()
        if not spec.stamp:
            reader.error('<filter type="Cull"> attribute stamp="": expected the name of the user stamp that '
                         "holds each message's bounding box (default bbox)", element)
        forms = [form for form, given in (("region=", "region" in values),
                                          ("a camera (position=, look_at=, ...)", bool(set(CAMERA) & set(values))),
                                          ("view_projection=", "view_projection" in values)) if given]
        if len(forms) != 1:
            reader.error('<filter type="Cull"> needs one region for its receiver: region="x0 y0 x1 y1" (a box), '
                         'a camera (position="x y z" look_at="x y z", and up=, fov_y=, aspect=, near=, far= as the '
                         'display\'s camera) or view_projection="16 numbers" (the 4x4 matrix row by row, OpenGL '
                         f"clip space); got {' and '.join(forms) if forms else 'none'}", element)
            return None
        if "region" in values:
            region = _region(values["region"])
            if region is None:
                reader.error(f'<filter type="Cull"> attribute region="{values.get("region", "")}": expected 2k '
                             "numbers, the region's minimum corner then its maximum (x0 y0 x1 y1, or x0 y0 z0 x1 y1 "
                             "z1), each minimum at most its maximum", element)
                return None
            spec.region = region
        else:
            spec.frustum = _frustum(reader, element, values)
            if spec.frustum is None:
                return None
    return spec


def _frustum(reader: FileReader, element: Element, values: dict[str, str]) -> Frustum | None:
    """A Cull's frustum: ``view_projection=`` (16 numbers, row by row) or the camera's attributes
    (:data:`CAMERA`); None once a wrong attribute was reported."""
    try:
        if "view_projection" in values:
            matrix = _numbers(reader, element, values, "view_projection", 16, "the 4x4 view-projection matrix, "
                              "row by row (OpenGL clip space)")
            return None if matrix is None else Frustum(matrix)
        missing = [name for name in ("position", "look_at") if name not in values]
        if missing:
            reader.error(f'<filter type="Cull"> with a camera needs {" and ".join(f"{name}=" for name in missing)} '
                         '(x y z, in the frame of the messages\' boxes)', element)
            return None
        position = _numbers(reader, element, values, "position", 3, "the camera's position, x y z")
        look_at = _numbers(reader, element, values, "look_at", 3, "the point the camera looks at, x y z")
        up = _numbers(reader, element, values, "up", 3, "the world direction shown upwards, x y z")
        scalars = {name: reader.parsed(element, values, name, lambda text: parse_number(text, expected))
                   for name, expected in (("fov_y", "a vertical field of view in degrees, between 0 and 180"),
                                          ("aspect", "the window's width / height, > 0"),
                                          ("near", "the near clipping distance, > 0"),
                                          ("far", "the far clipping distance, > near"))}
        if position is None or look_at is None or (up is None and "up" in values) or any(
                scalars[name] is None and name in values for name in scalars):
            return None  # said
        fov_y, aspect, near, far = (value if (value := scalars[name]) is not None else CAMERA_DEFAULTS[name]
                                    for name in ("fov_y", "aspect", "near", "far"))
        return Frustum.of_camera(position, look_at, up or CAMERA_UP, fov_y, aspect, near, far)
    except GeometryError as error:
        reader.error(f'<filter type="Cull">: {error}', element)
        return None


def _numbers(reader: FileReader, element: Element, values: dict[str, str], name: str, count: int,
             expected: str) -> tuple[float, ...] | None:
    """Attribute ``name``: ``count`` finite numbers (spaces or commas between); None when missing,
    or once reported as wrong."""
    if name not in values:
        return None
    try:
        numbers = tuple(float(word) for word in values[name].replace(",", " ").split())
    except ValueError:
        numbers = ()
    if len(numbers) != count or not all(math.isfinite(value) for value in numbers):
        reader.error(f'<filter type="Cull"> attribute {name}="{values[name]}": expected {count} numbers, {expected}',
                     element)
        return None
    return numbers


def _region(text: str) -> tuple[float, ...] | None:
    """A Cull's region: 2k finite numbers (spaces or commas between), minimum corner then maximum;
    None when it is not one."""
    try:
        values = tuple(float(word) for word in text.replace(",", " ").split())
    except ValueError:
        return None
    half = len(values) // 2
    if not values or len(values) % 2 or not all(math.isfinite(value) for value in values):
        return None
    if any(low > high for low, high in zip(values[:half], values[half:])):
        return None
    return values
