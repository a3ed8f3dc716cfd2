"""Topic specifications of a ROSInterface: ``port=/topic:package/msg/Type;key=value;...``.

One spec names the CoCo port, the ROS topic, the message type and optional settings::

    joints=/joint_states:sensor_msgs/msg/JointState
    cloud=/camera/points:sensor_msgs/PointCloud2;depth=2;reliability=best_effort
    pose=/tool_pose:geometry_msgs/msg/PoseStamped;child_frame=tool;durability=transient_local

- ``port``: the port name (a Python identifier);
- ``/topic``: the topic (absolute, or relative to the node's namespace); no ``:``, ``=`` or ``;``;
- ``package/msg/Type`` (or ``package/Type``): a message type with a converter
  (:func:`coco_ros.convert.supported_types`);
- QoS options: ``depth=N`` (keep-last depth, default 10), ``reliability=reliable|best_effort``
  (default reliable), ``durability=volatile|transient_local`` (default volatile);
- any other ``key=value`` is an option of the type's converter (``child_frame=tool`` for PoseStamped,
  ``copy=true`` for Image, ``drop_invalid=true`` for PointCloud2, ``labels=x|y|z`` for the
  MultiArrays: list values are separated by ``|``). Booleans and numbers are parsed after the
  converter's defaults.

Specs contain no spaces or commas: the attribute (a list) is split on both.
"""

from __future__ import annotations

import inspect
import re
from dataclasses import dataclass, field
from typing import Any, Sequence

from coco_core.errors import SpecError

from ..bag.qos import Qos
from ..convert import converter_for, normalize_type_name, supported_types
from ..convert.base import Converter

SYNTAX = ("port=/topic:package/msg/Type[;depth=N][;reliability=reliable|best_effort]"
          "[;durability=volatile|transient_local][;converter_option=value]")
"""The spec syntax, as error messages show it."""

RELIABILITY = ("reliable", "best_effort")
DURABILITY = ("volatile", "transient_local")
QOS_KEYS = ("depth", "reliability", "durability")

_PORT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_TOPIC = re.compile(r"^~?/?[A-Za-z_{][A-Za-z0-9_{}~/]*$")
_TRUE = {"true", "1", "yes", "on"}
_FALSE = {"false", "0", "no", "off"}


@dataclass(frozen=True)
class TopicSpec:
    """One parsed spec: port, topic, normalized message type, QoS and converter options."""

    port: str
    topic: str
    type_name: str
    qos: Qos = Qos()
    options: dict[str, Any] = field(default_factory=dict)
    text: str = ""

    def converter(self) -> Converter:
        """A converter of this spec's type with its options (checked when the spec was parsed)."""
        return converter_for(self.type_name, **self.options)

    def qos_profile(self):  # -> rclpy.qos.QoSProfile
        """The rclpy QoS profile of the subscription or publisher."""
        return self.qos.to_rclpy()

    def describe(self) -> str:
        extra = "".join(f";{key}={value}" for key, value in self.options.items())
        return (f"{self.port}={self.topic}:{self.type_name};depth={self.qos.depth};"
                f"reliability={self.qos.reliability};durability={self.qos.durability}{extra}")


def available_types() -> tuple[str, ...]:
    """The supported types whose converter can be made here (tf2_msgs may be missing)."""
    found = []
    for name in supported_types():
        try:
            converter_for(name)
        except ImportError:
            continue
        found.append(name)
    return tuple(found)


def _fail(text: str, problem: str) -> SpecError:
    return SpecError(f"topic spec {text!r}: {problem}; expected {SYNTAX}")


def parse_spec(text: str) -> TopicSpec:
    """Parse and check one spec (the converter is made once, so its options and imports are checked)."""
    original = text
    text = text.strip()
    head, *option_items = text.split(";")
    port, equals, rest = head.partition("=")
    if not equals:
        raise _fail(original, "no '=' between the port name and the topic")
    port = port.strip()
    if not _PORT.match(port):
        raise _fail(original, f"port name {port!r} is not an identifier")
    topic, colon, type_text = rest.partition(":")
    topic, type_text = topic.strip(), type_text.strip()
    if not colon or not type_text:
        raise _fail(original, "no ':package/msg/Type' after the topic")
    if not _TOPIC.match(topic) or topic.endswith("/") or "//" in topic:
        raise _fail(original, f"{topic!r} is not a valid topic name")
    type_name = normalize_type_name(type_text)
    if type_name not in supported_types():
        raise _fail(original, f"no converter for message type {type_text!r}; supported: "
                    f"{', '.join(available_types())}")

    try:
        raw = parse_options(option_items)
    except ValueError as error:
        raise _fail(original, str(error)) from None

    qos = _qos(original, raw)
    options = {key: value for key, value in raw.items() if key not in QOS_KEYS}
    try:
        options = converter_options(type_name, options)
    except ImportError as error:
        raise _fail(original, f"{type_name} cannot be bridged in this installation: {error}. Types that "
                    f"can be bridged here: {', '.join(available_types())}") from None
    except (ValueError, TypeError) as error:
        raise _fail(original, f"{error} (QoS options: {', '.join(QOS_KEYS)})") from None
    return TopicSpec(port, topic, type_name, qos, options, original)


def parse_specs(texts: Sequence[str]) -> list[TopicSpec]:
    """Parse several specs; a port named twice is an error."""
    specs = [parse_spec(text) for text in texts]
    seen: set[str] = set()
    for spec in specs:
        if spec.port in seen:
            raise SpecError(f"topic spec {spec.text!r}: port {spec.port!r} is named by another spec too")
        seen.add(spec.port)
    return specs


def check_specs(texts: Sequence[str]) -> str | None:
    """An attribute ``check``: the first problem of ``texts`` as text, or None."""
    try:
        parse_specs(texts)
    except SpecError as error:
        return str(error)
    return None


def _qos(text: str, raw: dict[str, str]) -> Qos:
    depth = 10
    if "depth" in raw:
        try:
            depth = int(raw["depth"])
        except ValueError:
            depth = 0
        if depth < 1:
            raise _fail(text, f"depth must be an integer >= 1, got {raw['depth']!r}")
    reliability = raw.get("reliability", "reliable").lower()
    if reliability not in RELIABILITY:
        raise _fail(text, f"reliability must be {' or '.join(RELIABILITY)}, got {raw['reliability']!r}")
    durability = raw.get("durability", "volatile").lower()
    if durability not in DURABILITY:
        raise _fail(text, f"durability must be {' or '.join(DURABILITY)}, got {raw['durability']!r}")
    return Qos(depth=depth, reliability=reliability, durability=durability)


def parse_options(items: Sequence[str]) -> dict[str, str]:
    """``key=value`` items (a spec's part after its type, split on ``;``) -> value texts by key.

    Shared with ``BagReplay``'s per-topic converter options, so both read one syntax."""
    raw: dict[str, str] = {}
    for item in items:
        item = item.strip()
        if not item:
            continue
        key, equals, value = item.partition("=")
        key = key.strip()
        if not equals or not key:
            raise SpecError(f"option {item!r} is not key=value")
        if key in raw:
            raise SpecError(f"option {key!r} given twice")
        raw[key] = value.strip()
    return raw


def converter_options(type_name: str, options: dict[str, str]) -> dict[str, Any]:
    """Option texts -> the typed keywords of ``type_name``'s converter, checked by making one.

    Raises ``ValueError`` naming the converter's options when one is unknown or badly typed, and
    ``ImportError`` when the type's message package is missing."""
    typed = _typed_options(type_name, options)
    converter_for(type_name, **typed)
    return typed


def _typed_options(type_name: str, options: dict[str, str]) -> dict[str, Any]:
    """Option texts -> the types of the converter's defaults (bool, int, float, list via ``|``)."""
    if not options:
        return {}
    from .. import convert

    module_name, class_name = convert._CONVERTERS[type_name]
    import importlib

    cls = getattr(importlib.import_module(f"coco_ros.convert.{module_name}"), class_name)
    parameters = inspect.signature(cls).parameters
    typed: dict[str, Any] = {}
    for key, value in options.items():
        parameter = parameters.get(key)
        default = parameter.default if parameter is not None else inspect.Parameter.empty
        if isinstance(default, bool):
            word = value.lower()
            if word not in _TRUE | _FALSE:
                raise SpecError(f"option {key} expects true or false, got {value!r}")
            typed[key] = word in _TRUE
        elif isinstance(default, (int, float)):
            try:
                typed[key] = type(default)(value)
            except ValueError:
                raise SpecError(f"option {key} expects a number, got {value!r}") from None
        elif isinstance(default, (tuple, list)):
            typed[key] = tuple(item for item in value.split("|") if item)
        else:
            typed[key] = value
    return typed
