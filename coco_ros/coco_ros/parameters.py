"""The application's ``<arg>``s as ROS parameters of the launcher's node (and of its children's).

A ROS user sets a node's values with ``-p name:=value``, ``--params-file`` and ``ros2 param set``;
a CoCo user with ``name:=value``. Both reach the same ``<arg>``, in this order of precedence:

1. ``name:=value`` on the launcher's command line (CoCo's and ROS 2 launch's own syntax);
2. ``-p name:=value`` and ``--params-file`` (rcl merges these two: the later on the line wins);
3. the file's ``value=`` / ``default=`` (``value=`` is fixed: only 1 changes it, as before).

Every declared ``<arg>`` is declared as a node parameter, typed from its final value (``true`` /
``false`` a bool, an integer an int, a number a double, anything else a string), with the arg's
``doc`` and ``<choice>`` values in its descriptor, so ``ros2 param list/get/describe`` tell what the
application runs with. An arg is read when the application is built, so a change while it runs
would be accepted and ignored: ``ros2 param set`` on an arg is refused with the reason instead.
Parameters given with ``-p`` that no ``<arg>`` declares are reported once (a typo would otherwise
go unnoticed); the node's own parameters (``use_sim_time``, ``qos_overrides.*``) are left to rclpy,
and ``diagnostics.*`` to :mod:`coco_ros.diagnostics`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from typing import Any

from coco_core import CocoError
from coco_core.errors import did_you_mean
from coco_core.model import AppSpec

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


def given_parameters(node: Any) -> dict[str, str]:
    """The values ``-p`` and ``--params-file`` gave ``node`` (created with
    ``automatically_declare_parameters_from_overrides``), as arg texts."""
    return {name: arg_text(name, parameter.value)
            for name, parameter in node.get_parameters_by_prefix("").items()
            if not is_node_parameter(name) and parameter.value is not None}


class ArgParameters:
    """Declares ``spec``'s args on ``node`` and refuses changes to them while the application runs."""

    def __init__(self, node: Any, spec: AppSpec) -> None:
        self.node = node
        self.spec = spec

    def declare(self, given: Mapping[str, str]) -> None:
        """Declare every arg (its final value, even where ``-p`` said otherwise because
        ``name:=value`` won), report ``-p`` values that no arg takes, then guard the args."""
        from rcl_interfaces.msg import ParameterDescriptor
        from rclpy.parameter import Parameter

        declarations = self.spec.arg_declarations
        unknown = sorted(name for name in given if name not in declarations)
        if unknown:
            log.warning("parameters %s set with -p or --params-file are not <arg>s of application %s and "
                        "change nothing; %s", ", ".join(unknown), self.spec.name,
                        did_you_mean(unknown[0], list(declarations)))
        for name, declaration in declarations.items():
            value = typed_value(declaration.value)
            if self.node.has_parameter(name):
                if self.node.get_parameter(name).value != value:
                    # name:=value won over -p: the node says what the application really runs with.
                    self.node.set_parameters([Parameter(name, value=value)])
                continue
            choices = f"one of: {', '.join(declaration.choices)}" if declaration.choices else ""
            self.node.declare_parameter(name, value, ParameterDescriptor(
                description=declaration.doc or f"<arg> {name} of application {self.spec.name}",
                additional_constraints=choices, read_only=declaration.fixed))
        self.node.add_on_set_parameters_callback(self._refuse_args)

    def _refuse_args(self, parameters: list[Any]) -> Any:
        """A change to an arg is refused with the reason (the application reads its args when it is
        built); other parameters (the node's own) are rclpy's business."""
        from rcl_interfaces.msg import SetParametersResult

        refused = [parameter.name for parameter in parameters if parameter.name in self.spec.arg_declarations]
        if not refused:
            return SetParametersResult(successful=True)
        names = ", ".join(refused)
        return SetParametersResult(successful=False, reason=(
            f"{names}: <arg> of application {self.spec.name}, read when it was built; it cannot change "
            f"while it runs: restart the launcher with {refused[0]}:=VALUE or -p {refused[0]}:=VALUE"))
