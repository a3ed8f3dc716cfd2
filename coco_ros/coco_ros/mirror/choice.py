"""Which ROS message type mirrors a port: from the ``<topic type=...>``, the port's declared type,
or, for a port declared as carrying anything (``Stamped``, ``object``, a union), its first value.

The message type of a publisher is fixed when it is made, before any value: a port typed
``JointSample`` is known from its declaration, one typed ``Stamped`` (most measurement ports) only
once a value shows what it wraps. Every rule maps a CoCo value class onto a converter of
:mod:`coco_ros.convert`, the same ones a ROSInterface uses, so a mirrored port and a published one
carry the same messages.
"""

from __future__ import annotations

import inspect
import numbers
import types
import typing
from typing import Any

import numpy as np
from coco_core.errors import MessageError
from coco_core.pool import Slot
from coco_core.stamps import Stamped
from coco_mr_vision.mesh import TriangleMesh

from ..convert import converter_for, normalize_type_name, supported_types
from ..convert.base import Converter
from .adapt import is_handle

BY_CLASS: tuple[str, ...] = (
    "sensor_msgs/msg/JointState",
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/TransformStamped",
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CameraInfo",
    "sensor_msgs/msg/PointCloud2",
)
"""Converters chosen by their ``coco_type``, first match wins (a FramePose is a PoseStamped, not a
TFMessage entry; /tf comes from the graph through a TFBridge)."""

NUMBER = "std_msgs/msg/Float64"
CLOUD = "sensor_msgs/msg/PointCloud2"
POSE = "geometry_msgs/msg/PoseStamped"
ARRAY = "std_msgs/msg/Float64MultiArray"
FORCE = "geometry_msgs/msg/WrenchStamped"


def by_value(port_type: Any) -> bool:
    """Whether a port declared with ``port_type`` shows its values' type only when it has one:
    ``Stamped``, ``object``, ``Any`` or a union (``Image | Stamped``)."""
    if port_type in (object, Any, Stamped):
        return True
    return typing.get_origin(port_type) in (typing.Union, types.UnionType)


def ros_type_of(cls: type) -> str | None:
    """The ROS type that mirrors values of class ``cls``; None when no converter knows them."""
    if cls is bool or issubclass(cls, Slot):
        return None  # a flag is not a measurement (Float64 refuses it); a pooled frame is a slot of bytes
    if issubclass(cls, numbers.Real):
        return NUMBER
    for name in BY_CLASS:
        coco_type = converter_for(name).coco_type
        if issubclass(cls, coco_type):
            return name
    if "force" in getattr(cls, "__dataclass_fields__", {}):
        return FORCE  # a HapticForce (coco_mr_haptics): its force and stamp
    if issubclass(cls, TriangleMesh):
        return CLOUD  # its vertices (adapt.mesh_cloud)
    if is_handle(cls):
        return POSE  # a device's handle (adapt.adapted)
    if issubclass(cls, (tuple, list, np.ndarray)):
        return ARRAY
    return None


def value_ros_type(value: Any) -> str | None:
    """:func:`ros_type_of` the class of ``value`` (a ``Stamped`` one's payload)."""
    return ros_type_of(type(value.value if isinstance(value, Stamped) else value))


def mirror_converter(ros_type: str, frame: str) -> Converter:
    """The converter of a mirror, given the topic's ``frame`` where it takes one (``frame_id``)."""
    taken = "frame_id" in inspect.signature(type(converter_for(ros_type)).__init__).parameters
    return converter_for(ros_type, frame_id=frame) if frame and taken else converter_for(ros_type)


def explicit_converter(type_name: str, where: str) -> Converter:
    """The converter of a ``<topic type=...>``, or a :class:`MessageError` naming ``where``."""
    name = normalize_type_name(type_name)
    if name not in supported_types():
        raise MessageError(f"{where}: no converter for ROS type {type_name!r}; supported: "
                           f"{', '.join(supported_types())}")
    try:
        return converter_for(name)
    except ImportError as error:
        raise MessageError(f"{where}: {name} cannot be published in this installation: {error}") from None
