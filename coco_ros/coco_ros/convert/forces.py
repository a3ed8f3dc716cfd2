"""``geometry_msgs/WrenchStamped`` <-> a force and torque: what a haptic renderer applies to the
device (``HapticForce``, the proxy's force) as RViz draws and rqt_plot plots it.

The CoCo side is ``(fx, fy, fz, tx, ty, tz)``; a value that has a ``force`` (a ``HapticForce``:
three numbers, and its ``stamp`` for the header) or a 3-tuple (a force alone) is published with a
zero torque. The frame is the converter's ``frame_id``: a force carries none of its own.
"""

from __future__ import annotations

import math
from typing import Any

from coco_core.errors import WrongTypeError
from geometry_msgs.msg import Vector3, Wrench, WrenchStamped

from .base import Converter, make_header

WRENCH_SIZE = 6


class WrenchStampedConverter(Converter[WrenchStamped, tuple]):
    """``geometry_msgs/WrenchStamped`` <-> ``(fx, fy, fz, tx, ty, tz)``."""

    type_name = "geometry_msgs/msg/WrenchStamped"
    coco_type = tuple

    def __init__(self, frame_id: str = "") -> None:
        self.frame_id = frame_id

    def to_coco(self, msg: WrenchStamped) -> tuple[float, ...]:
        self._check_message(msg)
        force, torque = msg.wrench.force, msg.wrench.torque
        return (force.x, force.y, force.z, torque.x, torque.y, torque.z)

    def to_ros(self, value: Any) -> WrenchStamped:
        stamp = getattr(value, "stamp", None)
        components = self._components(getattr(value, "force", value))
        return WrenchStamped(header=make_header(stamp if isinstance(stamp, float) and stamp > 0 else None,
                                                self.frame_id),
                             wrench=Wrench(force=Vector3(x=components[0], y=components[1], z=components[2]),
                                           torque=Vector3(x=components[3], y=components[4], z=components[5])))

    def _components(self, value: Any) -> list[float]:
        try:
            components = [float(c) for c in value]
        except (TypeError, ValueError):
            components = []
        if len(components) == 3:
            components += [0.0, 0.0, 0.0]
        if len(components) != WRENCH_SIZE or not all(math.isfinite(c) for c in components):
            raise WrongTypeError(f"{type(self).__name__} publishes a force (fx, fy, fz), a wrench (fx, fy, fz, "
                                 f"tx, ty, tz) or a value with a force as {self.type_name}, got {value!r}")
        return components


