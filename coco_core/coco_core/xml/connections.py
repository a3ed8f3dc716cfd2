"""``<connection>``: which output port feeds which input port, and with which policy.

Only the component names can be checked once the whole application is read (see
:mod:`.references`); port names and types are checked by the builder, which knows the classes.
"""

from __future__ import annotations

from ..model import ConnectionSpec, PortRef
from ..policy import BufferPolicy, SyncPolicy
from .reader import CONDITIONS, FileReader
from .tree import Element
from .values import parse_bool, parse_int

CONNECTION_ATTRIBUTES = ("buffersize", "data", "event", "policy", "transport", *CONDITIONS)
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
    size = _buffer_size(reader, element, values, data)
    event = reader.parsed(element, values, "event", parse_bool)
    children = reader.children(element, ("dest", "src"))
    src = _port(reader, element, children, "src")
    dest = _port(reader, element, children, "dest")
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
    )


def _buffer_size(
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
            f'<connection> attribute buffersize="{text}" on a {data.value} connection is ignored: it '
            "holds the newest value only (the original CoCo ignores the size too)",
            element,
        )
        return 1
    if size < 1:
        reader.error(
            f'<connection> attribute buffersize="{text}": expected at least 1, or -1 for the default',
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
    values = reader.attributes(element, ("port", "task"), required=("port", "task"))
    reader.empty(element)
    return PortRef(
        component=values.get("task", "").strip(),
        port=values.get("port", "").strip(),
        location=element.location,
    )
