"""Conversions between ROS messages and the values that flow on CoCo ports.

One module per message family (``joints``, ``images``, ``clouds``, ``geometry``, ``arrays``,
``scalars``), each converter with ``to_coco(msg)`` and ``to_ros(value)``; :func:`converter_for` finds
the converter of a message type by name, which is how a ROSInterface configured in XML gets one::

    converter = converter_for("geometry_msgs/msg/PoseStamped", child_frame="tool")
    pose = converter.to_coco(msg)          # a FramePose, T_<header.frame_id>_tool
    port = InputPort(converter.coco_type)  # the CoCo side's type

Images and clouds are converted with numpy only, never element by element in Python; stamps become
float seconds (see :mod:`coco_ros.convert.stamps` for the precision and how ROS stamps stay exact).
A family's message package is imported only when one of its converters is asked for.
"""

from __future__ import annotations

import importlib
import inspect
from typing import Any

from coco_core.errors import MessageError

from .base import Converter

#: ROS type name -> (module of this package, converter class)
_CONVERTERS: dict[str, tuple[str, str]] = {
    "sensor_msgs/msg/JointState": ("joints", "JointStateConverter"),
    "sensor_msgs/msg/Image": ("images", "ImageMessageConverter"),
    "sensor_msgs/msg/CameraInfo": ("images", "CameraInfoConverter"),
    "sensor_msgs/msg/CompressedImage": ("compressed", "CompressedImageConverter"),
    "sensor_msgs/msg/PointCloud2": ("clouds", "PointCloud2Converter"),
    "geometry_msgs/msg/PoseStamped": ("geometry", "PoseStampedConverter"),
    "geometry_msgs/msg/TransformStamped": ("geometry", "TransformStampedConverter"),
    "geometry_msgs/msg/WrenchStamped": ("forces", "WrenchStampedConverter"),
    "std_msgs/msg/ColorRGBA": ("colors", "ColorRGBAConverter"),
    "visualization_msgs/msg/Marker": ("markers", "ForceArrowConverter"),
    "tf2_msgs/msg/TFMessage": ("geometry", "TFMessageConverter"),
    "std_msgs/msg/Float64": ("scalars", "Float64Converter"),
    **{f"std_msgs/msg/{element}{suffix}MultiArray": ("arrays", "MultiArrayConverter")
       for element in ("Float", "Int", "UInt") for suffix in ("8", "16", "32", "64")
       if not (element == "Float" and suffix in ("8", "16"))},
}


def supported_types() -> tuple[str, ...]:
    """The ROS message types with a converter, as ``package/msg/Name``."""
    return tuple(sorted(_CONVERTERS))


def normalize_type_name(type_name: str | type) -> str:
    """``sensor_msgs/Image``, ``sensor_msgs.msg.Image`` or the message class -> ``sensor_msgs/msg/Image``."""
    if isinstance(type_name, type):
        package = type_name.__module__.split(".", 1)[0]
        return f"{package}/msg/{type_name.__name__}"
    parts = [part for part in str(type_name).strip().replace(".", "/").split("/") if part]
    if len(parts) == 2:
        parts.insert(1, "msg")
    return "/".join(parts)


def converter_for(type_name: str | type, **options: Any) -> Converter:
    """A converter for the ROS message type ``type_name``, with its ``options``.

    Raises ``ValueError`` naming the supported types when there is no converter for the type, and
    naming the converter's options when one is wrong.
    """
    name = normalize_type_name(type_name)
    try:
        module_name, class_name = _CONVERTERS[name]
    except KeyError:
        raise MessageError(f"no converter for ROS message type {str(type_name)!r}; supported: "
                           f"{', '.join(supported_types())}") from None
    cls = getattr(importlib.import_module(f".{module_name}", __name__), class_name)
    if module_name == "arrays":
        options = {**options, "type_name": name}
    parameters = [p for p in inspect.signature(cls).parameters if p != "type_name"]
    try:
        inspect.signature(cls).bind(**options)
    except TypeError:
        unknown = sorted(set(options) - set(parameters) - {"type_name"})
        accepted = ", ".join(parameters) or "none"
        raise MessageError(f"the {name} converter has no option(s) {', '.join(unknown)}; its options: "
                           f"{accepted}") from None
    return cls(**options)


__all__ = ["Converter", "converter_for", "normalize_type_name", "supported_types"]
