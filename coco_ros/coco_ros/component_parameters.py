"""Component attributes as ROS parameters ``<component>.<attribute>`` of the node that runs them.

A ROS user reconfigures a node with ``ros2 param set`` (rqt_reconfigure, Foxglove's parameter
panel); a CoCo user with a component's ``set_attribute`` operation. Both reach the same attribute:

- every attribute of every component of this process (peers included) is declared, typed from its
  declaration (``int`` an integer, ``float`` a double, ``bool``, ``str`` / ``Path`` / an enum a
  string, lists the arrays), with its ``doc``, its ``choices`` and its ``min`` / ``max`` as the
  descriptor's range;
- an attribute the component reads while it runs (``Attribute(..., live=True)``) is writable: a set
  is checked as the component checks it (type, range, choices, its ``check``; NaN and infinities
  refused) and refused with that reason, else handed to the component through its
  ``set_attribute`` operation, the path every run-time change takes, applied between two updates;
- every other attribute is ``read_only`` (read when the component configures: a change would be
  accepted and ignored);
- ``ros2 param get`` returns what runs: a change made through the ``set_attribute`` operation (a
  ``call_operation`` service, another component) updates the parameter
  (:attr:`Application.attribute_watchers <coco_core.application.Application.attribute_watchers>`).
"""

from __future__ import annotations

import enum
import logging
import math
from pathlib import Path
from typing import Any, get_args, get_origin

from coco_core import Application
from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import AttributeValueError

from .parameters import with_range

log = logging.getLogger("coco.parameters")

_TEXT_TYPES = (str, Path)


def _scalar_kind(tp: Any) -> str | None:
    """``bool``, ``integer``, ``double`` or ``string`` for an attribute's scalar type; None: none fits."""
    if tp is bool:
        return "bool"
    if tp is int:
        return "integer"
    if tp is float:
        return "double"
    if tp in _TEXT_TYPES or (isinstance(tp, type) and issubclass(tp, enum.Enum)):
        return "string"
    return None


def parameter_kind(declaration: Attribute) -> tuple[str, bool] | None:
    """(scalar kind, whether an array) of an attribute's parameter; None when it has none."""
    origin = get_origin(declaration.type)
    if origin in (list, tuple):
        kind = _scalar_kind(get_args(declaration.type)[0])
        return None if kind is None else (kind, True)
    kind = _scalar_kind(declaration.type)
    return None if kind is None else (kind, False)


def _ros_scalar(value: Any) -> Any:
    if isinstance(value, enum.Enum):
        return value.name
    if isinstance(value, Path):
        return str(value)
    return value


def ros_value(value: Any, array: bool) -> Any:
    """An attribute's value as its parameter holds it (an enum by name, a path as text, a list)."""
    return [_ros_scalar(item) for item in value] if array else _ros_scalar(value)


def _not_finite(value: Any) -> bool:
    items = value if isinstance(value, (list, tuple)) else [value]
    return any(isinstance(item, float) and not math.isfinite(item) for item in items)


class ComponentParameters:
    """Declares the attributes of ``app``'s components on ``node`` and keeps both in step."""

    def __init__(self, node: Any, app: Application) -> None:
        self.node = node
        self.app = app
        self.declared: dict[str, tuple[Component, Attribute, bool]] = {}
        """Parameter name -> (component, attribute declaration, whether an array)."""

    def declare(self) -> None:
        """Declare every attribute that has a parameter type, then follow changes both ways."""
        for component in self.app.components.values():
            for name in component.attributes():
                self._declare(component, component.attribute_declaration(name))
        self.node.add_on_set_parameters_callback(self._set)
        self.app.attribute_watchers.append(self._changed)

    def _declare(self, component: Component, declaration: Attribute) -> None:
        from rclpy.exceptions import InvalidParameterException

        kind = parameter_kind(declaration)
        value = getattr(component, declaration.name)
        full = f"{component.name}.{declaration.name}"
        if kind is None or value is None:
            log.debug("attribute %s (%s) has no ROS parameter type", full, declaration.type_name)
            return
        if self.node.has_parameter(full):  # given with -p: declared from the overrides, without its descriptor
            self.node.undeclare_parameter(full)
        try:
            self.node.declare_parameter(full, ros_value(value, kind[1]), self.descriptor(component, declaration),
                                        ignore_override=True)
        except (InvalidParameterException, TypeError, ValueError) as error:
            log.warning("attribute %s is not offered as a ROS parameter: %s", full, error)
            return
        self.declared[full] = (component, declaration, kind[1])

    def descriptor(self, component: Component, declaration: Attribute) -> Any:
        """The parameter's descriptor: its doc, read_only unless live, choices and range."""
        from rcl_interfaces.msg import ParameterDescriptor

        kind = parameter_kind(declaration)
        assert kind is not None
        constraints = [] if declaration.live else [
            f"read-only: read when {component.name} configures; restart with another value in the file"]
        if declaration.choices is not None:
            constraints.append(f"one of: {', '.join(str(_ros_scalar(c)) for c in declaration.choices)}")
        if declaration.check is not None:
            constraints.append("checked further by the component")
        descriptor = ParameterDescriptor(
            description=declaration.doc or f"attribute {declaration.name} of {type(component).__name__}",
            additional_constraints="; ".join(constraints), read_only=not declaration.live)
        return with_range(descriptor, "other" if kind[1] else kind[0], declaration.min, declaration.max)

    def _set(self, parameters: list[Any]) -> Any:
        """A set from ROS: checked as the component checks it, then queued to its ``set_attribute``."""
        from rcl_interfaces.msg import SetParametersResult

        changes: list[tuple[Component, str, Any]] = []
        for parameter in parameters:
            target = self.declared.get(parameter.name)
            if target is None:
                continue
            component, declaration, _ = target
            if _not_finite(parameter.value):
                return SetParametersResult(successful=False, reason=(
                    f"{parameter.name}: {parameter.value!r} is not a value of attribute {declaration.name} "
                    f"({declaration.type_name}): NaN and infinities are refused"))
            try:
                value = declaration.validate(parameter.value, component)
            except AttributeValueError as error:
                return SetParametersResult(successful=False, reason=f"{parameter.name}: {error}")
            if value != getattr(component, declaration.name):  # equal: what runs already, told by the component
                changes.append((component, declaration.name, value))
        for component, name, value in changes:
            self.app.operation(component.name, "set_attribute")(name, value)  # applied between two updates
        return SetParametersResult(successful=True)

    def _changed(self, component: Component, name: str) -> None:
        """An attribute changed through ``set_attribute``: its parameter shows the new value (in the
        component's thread). A read-only parameter is set with its own descriptor, the one way
        rclpy lets a node change a parameter it declared read-only (as ``declare_parameters``
        itself does); the set is checked against the descriptor and refused nowhere else."""
        from rclpy.parameter import Parameter

        full = f"{component.name}.{name}"
        target = self.declared.get(full)
        if target is None:
            return
        value = ros_value(getattr(component, name), target[2])
        if self.node.get_parameter(full).value == value:
            return
        parameter = Parameter(full, self.node.get_parameter(full).type_, value)
        self.node._set_parameters_atomically_common([parameter], {full: self.node.describe_parameter(full)})
