"""CoCo core: the component runtime of CoCo for ROS 2, importable without ROS.

Three orthogonal graphs: the *computational graph* (components joined by ports), the *scheduling tree*
(processes > activities > components > peers, decided in the application file) and the
*transformation graph* of reference frames. This package holds the first two; see the README.
"""

from .activity import Activity, PeriodicActivity, TriggeredActivity
from .application import Application, WiringError
from .attributes import Attribute, AttributeValueError
from .component import Component, ErrorPolicy, UnknownNameError
from .connections import Connection
from .errors import CocoError, ConfigError, ConfigErrors, Location
from .operations import Operation, current_activity, operation
from .policy import (
    NEW_DATA,
    NO_DATA,
    OLD_DATA,
    BufferPolicy,
    ConnectionPolicy,
    ReadStatus,
    SyncPolicy,
)
from .pool import FramePool, Slot, SlotState
from .ports import InputPort, OutputPort, PooledOutputPort
from .registry import register
from .scheduling import SchedulingRequest
from .stamps import Stamp, Stamped

__all__ = [
    "Activity", "Application", "Attribute", "AttributeValueError", "BufferPolicy", "CocoError",
    "Component", "ConfigError", "ConfigErrors", "Connection", "ConnectionPolicy", "ErrorPolicy",
    "FramePool", "InputPort", "Location", "NEW_DATA", "NO_DATA", "OLD_DATA", "Operation", "OutputPort",
    "PeriodicActivity", "PooledOutputPort", "ReadStatus", "SchedulingRequest", "Slot", "SlotState",
    "Stamp", "Stamped", "SyncPolicy", "TriggeredActivity", "UnknownNameError", "WiringError",
    "current_activity", "operation", "register",
]
