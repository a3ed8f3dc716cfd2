"""The application's ``<arg>``s as ROS parameters of the launcher's node (and of its children's).

A ROS user sets a node's values with ``-p name:=value``, ``--params-file`` and ``ros2 param set``;
a CoCo user with ``name:=value``. Both reach the same ``<arg>``, in this order of precedence:

1. ``name:=value`` on the launcher's command line (CoCo's and ROS 2 launch's own syntax);
2. ``-p name:=value`` and ``--params-file`` (rcl merges these two: the later on the line wins);
3. the file's ``value=`` / ``default=`` (``value=`` is fixed: only 1 changes it, as before).

Every declared ``<arg>`` is declared as a node parameter, typed from its final value (``true`` /
``false`` a bool, an integer an int, a number a double, anything else a string), with the arg's
``doc`` and ``<choice>`` values in its descriptor and its ``min`` / ``max`` as the integer or
floating point range, so ``ros2 param list/get/describe`` tell what the application runs with. An
arg is read when the application is built, so a change while it runs would be accepted and
ignored: every arg is declared ``read_only`` (rqt_reconfigure and Foxglove offer no field that
always fails; ``ros2 param set`` is refused), its descriptor saying how to change it (restart with
``name:=VALUE``). The components' attributes are parameters too (:mod:`.component_parameters`).
Parameters given with ``-p`` that no ``<arg>`` declares are reported once (a typo would otherwise
go unnoticed); the node's own parameters (``use_sim_time``, ``qos_overrides.*``) are left to rclpy,
and ``diagnostics.*`` to :mod:`coco_ros.diagnostics`.
"""

from __future__ import annotations

import logging
import math
import sys
from collections.abc import Mapping
from typing import Any

from coco_core import CocoError
from coco_core.errors import did_you_mean
from coco_core.model import AppSpec, ArgDeclaration

log = logging.getLogger("coco.parameters")

NODE_PARAMETERS = ("use_sim_time", "start_type_description_service")
"""Parameters every rclpy node declares for itself: never an application arg."""
_NODE_PREFIXES = ("qos_overrides.", "diagnostics.")
"""rclpy's QoS overrides, and the launcher's /diagnostics settings (coco_ros.diagnostics)."""


def is_node_parameter(name: str) -> bool:
    """Whether ``name`` belongs to rclpy's node rather than to the application."""
    return name in NODE_PARAMETERS or name.startswith(_NODE_PREFIXES)


def typed_value(text: str) -> bool | int | float | str:
    """The ROS parameter value for an arg's text: the type ``ros2 param set`` users expect."""
    lowered = text.strip().lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    try:
        return int(text)
    except ValueError:
        pass
    try:
        number = float(text)
    except ValueError:
        return text
    return number if math.isfinite(number) else text


def arg_text(name: str, value: Any) -> str:
    """The ``<arg>`` text for a ROS parameter value (the inverse of :func:`typed_value`)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float, str)):
        return str(value)
    raise CocoError(f"parameter {name!r} is {value!r}: an application <arg> takes one value "
                    "(a bool, an integer, a number or a string), not an array")


INT64 = (-(2 ** 63), 2 ** 63 - 1)


def with_range(descriptor: Any, kind: str, low: float | None, high: float | None) -> Any:
    """``descriptor`` with the integer (``kind`` "integer") or floating point ("double") range of the
    bounds ``low`` / ``high`` (either may be None: that end is open), which rclpy checks on every
    set and rqt_reconfigure and Foxglove show as a slider's ends; another kind takes no range."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange

    if low is None and high is None:
        return descriptor
    if kind == "integer":
        descriptor.integer_range = [IntegerRange(from_value=INT64[0] if low is None else math.ceil(low),
                                                 to_value=INT64[1] if high is None else math.floor(high), step=0)]
    elif kind == "double":
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=-sys.float_info.max if low is None else float(low),
            to_value=sys.float_info.max if high is None else float(high), step=0.0)]
    return descriptor


def given_parameters(node: Any) -> dict[str, str]:
    """The values ``-p`` and ``--params-file`` gave ``node`` (created with
    ``automatically_declare_parameters_from_overrides``), as arg texts."""
    return {name: arg_text(name, parameter.value)
            for name, parameter in node.get_parameters_by_prefix("").items()
            if not is_node_parameter(name) and parameter.value is not None}


class ArgParameters:
    """Declares ``spec``'s args on ``node``, read-only: the application reads them when it is built."""

    def __init__(self, node: Any, spec: AppSpec) -> None:
        self.node = node
        self.spec = spec

    def declare(self, given: Mapping[str, str]) -> None:
        """Declare every arg (its final value, even where ``-p`` said otherwise because
        ``name:=value`` won) and report ``-p`` values that no arg takes."""
        declarations = self.spec.arg_declarations
        unknown = sorted(name for name in given if name not in declarations)
        if unknown:
            log.warning("parameters %s set with -p or --params-file are not <arg>s of application %s and "
                        "change nothing; %s", ", ".join(unknown), self.spec.name,
                        did_you_mean(unknown[0], list(declarations)))
        for name, declaration in declarations.items():
            if self.node.has_parameter(name):  # given with -p: declared from the overrides, without a descriptor
                self.node.undeclare_parameter(name)
            # Its final value, even where name:=value won over -p: the node says what really runs.
            self.node.declare_parameter(name, typed_value(declaration.value), self.descriptor(declaration),
                                        ignore_override=True)

    def descriptor(self, declaration: ArgDeclaration) -> Any:
        """An arg's descriptor: read-only with the way to change it, its doc, choices and range."""
        from rcl_interfaces.msg import ParameterDescriptor

        name = declaration.name
        constraints = [f"read-only: <arg> of application {self.spec.name}, read when it was built; restart the "
                       f"launcher with {name}:=VALUE or -p {name}:=VALUE"]
        if declaration.choices:
            constraints.append(f"one of: {', '.join(declaration.choices)}")
        descriptor = ParameterDescriptor(
            description=declaration.doc or f"<arg> {name} of application {self.spec.name}",
            additional_constraints="; ".join(constraints), read_only=True)
        value = typed_value(declaration.value)
        kind = "double" if isinstance(value, float) else "integer" if isinstance(value, int) else "other"
        return with_range(descriptor, kind, declaration.min, declaration.max)
