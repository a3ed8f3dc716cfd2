"""Message type names <-> Python message classes, and CDR (de)serialization with rclpy.

Bags name types ``pkg/msg/Name`` (old ones sometimes ``pkg/Name``); the class is ``Name`` in the
Python module ``pkg.msg`` that rosidl generates. A class is looked up once per type and the answer,
found or not, is cached, so a replay of a million messages imports nothing after the first.
``tf2_msgs/msg/TFMessage`` is no exception: the workspace builds tf2_msgs (``vendor/tf2_msgs``), so
/tf and /tf_static are deserialized by rclpy like any other topic.
"""

from __future__ import annotations

import importlib
import re
import threading
from typing import Any, Callable

from coco_core.errors import MessageError, MessageTypeError, WrongTypeError


_TYPE_NAME = re.compile(r"^([A-Za-z][A-Za-z0-9_]*)/(?:([A-Za-z][A-Za-z0-9_]*)/)?([A-Za-z][A-Za-z0-9_]*)$")

TF_MESSAGE = "tf2_msgs/msg/TFMessage"
"""The type of /tf and /tf_static, whose latched messages all count (see ``BagReader.latched``)."""


def normalize_type(type_name: str) -> str:
    """``pkg/Name`` or ``pkg/msg/Name`` -> ``pkg/msg/Name``; anything else is an error."""
    match = _TYPE_NAME.match(type_name.strip()) if isinstance(type_name, str) else None
    if not match:
        raise MessageError(f"expected a message type name like 'std_msgs/msg/String', got {type_name!r}")
    package, namespace, name = match.groups()
    return f"{package}/{namespace or 'msg'}/{name}"


def type_name_of(message: Any) -> str:
    """The ``pkg/msg/Name`` of a message object (a rosidl-generated class)."""
    cls = type(message)
    parts = cls.__module__.split(".")
    if len(parts) >= 2 and hasattr(cls, "get_fields_and_field_types"):
        return f"{parts[0]}/{parts[1]}/{cls.__name__}"
    raise WrongTypeError(
        f"expected a ROS message object (a rosidl-generated class), got {cls.__module__}.{cls.__name__}"
    )


class TypeResolver:
    """Finds and caches the decoder of each message type; thread-safe."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._decoders: dict[str, Callable[[bytes], Any] | MessageTypeError] = {}
        self._classes: dict[str, type] = {}

    def message_class(self, type_name: str, where: str = "") -> type:
        """The Python class of ``type_name``; :class:`MessageTypeError` says which package is missing."""
        self.decoder(type_name, where)
        return self._classes[normalize_type(type_name)]

    def decoder(self, type_name: str, where: str = "") -> Callable[[bytes], Any]:
        """A function CDR bytes -> message object for ``type_name`` (resolved once, then cached)."""
        found = self._decoders.get(type_name)
        if found is None:
            with self._lock:
                found = self._decoders.get(type_name)
                if found is None:
                    found = self._resolve(type_name, where)
                    self._decoders[type_name] = found
        if isinstance(found, MessageTypeError):
            raise found
        return found

    def _resolve(self, type_name: str, where: str) -> Callable[[bytes], Any] | MessageTypeError:
        try:
            full = normalize_type(type_name)
        except ValueError as error:
            return MessageTypeError(where or type_name, str(error))
        package, namespace, name = full.split("/")
        module_name = f"{package}.{namespace}"
        problem = ""
        try:
            module = importlib.import_module(module_name)
            cls = getattr(module, name)
        except ImportError as error:
            problem = f"its Python module {module_name!r} cannot be imported ({error})"
        except AttributeError:
            problem = f"module {module_name!r} has no class {name!r}"
        else:
            from .cdr_decoder import message_decoder

            self._classes[full] = cls
            return message_decoder(cls)
        return MessageTypeError(
            where or full,
            f"cannot deserialize messages of type {full!r}: {problem}; install the package that "
            f"provides it (e.g. pip install ros-jazzy-{package.replace('_', '-')}) or leave the topic out",
        )
