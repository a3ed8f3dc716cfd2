"""CoCo core: the component runtime of CoCo for ROS 2, importable without ROS.

Three orthogonal graphs: the *computational graph* (components joined by ports), the *scheduling tree*
(processes > activities > components > peers, decided in the application file) and the
*transformation graph* of reference frames. This package holds the first two; see the README.

The public names are imported on first use (PEP 562): ``import coco_core`` itself costs almost
nothing, so that a launcher installs its signal handling before the runtime (numpy, the
transformation graph) is loaded, and a signal during start-up has its defined effect.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

_EXPORTS = {
    "Activity": "activity", "PeriodicActivity": "activity", "TriggeredActivity": "activity",
    "Application": "application", "WiringError": "application",
    "Attribute": "attributes", "AttributeValueError": "attributes", "FileAttribute": "attributes",
    "Component": "component", "ErrorPolicy": "component", "UnknownNameError": "component",
    "Connection": "connections",
    "CocoError": "errors", "ConfigError": "errors", "ConfigErrors": "errors", "Location": "errors",
    "Greedy": "filters", "MaxFrequency": "filters", "Merge": "filters", "MergeGroup": "filters",
    "PreSignal": "filters", "Split": "filters", "Cull": "filters", "Gather": "filters", "GatherGroup": "filters",
    "iteration_ports": "iteration",
    "Operation": "operations", "current_activity": "operations", "operation": "operations",
    "NEW_DATA": "policy", "NO_DATA": "policy", "OLD_DATA": "policy", "BufferPolicy": "policy",
    "ConnectionPolicy": "policy", "ReadStatus": "policy", "SyncPolicy": "policy",
    "FramePool": "pool", "LocalFramePool": "pool", "Slot": "pool", "SlotState": "pool",
    "InputPort": "ports", "OutputPort": "ports", "PooledOutputPort": "ports",
    "register": "registry",
    "SchedulingRequest": "thread_placement",
    "Message": "stamps", "Stamp": "stamps", "Stamped": "stamps",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'coco_core' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


if TYPE_CHECKING:
    from .activity import Activity, PeriodicActivity, TriggeredActivity
    from .application import Application, WiringError
    from .attributes import Attribute, AttributeValueError, FileAttribute
    from .component import Component, ErrorPolicy, UnknownNameError
    from .connections import Connection
    from .errors import CocoError, ConfigError, ConfigErrors, Location
    from .filters import Cull, Gather, GatherGroup, Greedy, MaxFrequency, Merge, MergeGroup, PreSignal, Split
    from .iteration import iteration_ports
    from .operations import Operation, current_activity, operation
    from .policy import NEW_DATA, NO_DATA, OLD_DATA, BufferPolicy, ConnectionPolicy, ReadStatus, SyncPolicy
    from .pool import FramePool, LocalFramePool, Slot, SlotState
    from .ports import InputPort, OutputPort, PooledOutputPort
    from .registry import register
    from .thread_placement import SchedulingRequest
    from .stamps import Message, Stamp, Stamped
