"""A connection whose ends run apart (in two processes, or on two hosts), planned from the file alone.

Neither the launcher nor another host builds the components of the other end: what a connection
becomes across a boundary is read from the file and the installed components' class declarations.
The reader's side stores what arrives with :func:`ring_policy` (the connection's own policy, or
the feed of its filter, which runs on the reader's side), and a port's size, type and pool are its
class's declaration (:func:`declared_port`). Both levels plan their crossings so (the process
level's shared-memory channels, the host level's connections over the network), which is why this
lives beside both instead of in one of them.
"""

from __future__ import annotations

from typing import Any

from . import registry
from .filters import Greedy
from .model import ComponentSpec, ConnectionSpec
from .policy import BufferPolicy, ConnectionPolicy, SyncPolicy


def ring_policy(connection: ConnectionSpec) -> ConnectionPolicy:
    """The policy of the reader's side of ``connection`` across a boundary: its own; with a filter
    (which stays on the reader's side, :mod:`coco_core.processes.filtered`) a BUFFER of its
    ``buffersize`` that hands the filter every message in order, or for a ``Greedy`` a DATA ring
    (it keeps the newest only)."""
    size = max(1, connection.buffersize)
    if connection.filter is None:
        return ConnectionPolicy(connection.data, connection.policy, size)
    if connection.filter.type == Greedy.name:
        return ConnectionPolicy(BufferPolicy.DATA, SyncPolicy.LOCKED, 1)
    return ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, size)


def declared_port(spec: ComponentSpec | None, port: str) -> Any:
    """The class-level declaration of ``port`` on the component of ``spec``, if it has one: the
    launcher plans channels (and each host the connections between hosts) without building the
    other processes' components."""
    if spec is None:
        return None
    try:
        cls = registry.load(spec.task, spec.library)
    except Exception:  # reported where the component is built
        return None
    return cls._port_decls.get(port)
