"""``visualization_msgs/Marker`` arrows <-> a force applied at a point: what RViz and Foxglove draw of
a haptic contact (the proxy and the force on the device), without a plug-in.

The CoCo side is ``(start, vector)``, two 3-tuples: the arrow starts at ``start`` and shows
``vector`` scaled by ``scale`` metres per unit (a force of 5 N is a 10 cm arrow at the default
0.02 m/N). A value with a ``proxy`` and a ``force`` (a haptic renderer's ``HapticSample``) is drawn
from its proxy. The frame is the converter's ``frame_id``. Each message replaces the previous arrow
(one ``ns``/``id``).
"""

from __future__ import annotations

import math
from typing import Any

from coco_core.errors import MessageError, WrongTypeError
from geometry_msgs.msg import Point, Vector3
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker

from .base import Converter, make_header

Vector = tuple[float, float, float]
SHAFT_M = 0.004
"""The arrow's shaft diameter; its head is twice as wide and as long."""


class ForceArrowConverter(Converter[Marker, tuple]):
    """``visualization_msgs/Marker`` (an ARROW by its two points) <-> ``(start, vector)``."""

    type_name = "visualization_msgs/msg/Marker"
    coco_type = tuple

    def __init__(self, frame_id: str = "", scale: float = 0.02, ns: str = "force") -> None:
        if not (math.isfinite(scale) and scale > 0):
            raise MessageError(f"scale must be a positive number of metres per unit, got {scale}")
        self.frame_id, self.scale, self.ns = frame_id, scale, ns

    def to_coco(self, msg: Marker) -> tuple[Vector, Vector]:
        self._check_message(msg)
        if msg.type != Marker.ARROW or len(msg.points) != 2:
            raise MessageError(f"{type(self).__name__} reads arrows given by two points, got marker type "
                                 f"{msg.type} with {len(msg.points)} points")
        start, end = msg.points
        return ((start.x, start.y, start.z),
                ((end.x - start.x) / self.scale, (end.y - start.y) / self.scale, (end.z - start.z) / self.scale))

    def to_ros(self, value: Any) -> Marker:
        start, vector = self._parts(value)
        end = [s + self.scale * v for s, v in zip(start, vector)]
        return Marker(header=make_header(None, self.frame_id), ns=self.ns, id=0, type=Marker.ARROW,
                      action=Marker.ADD, points=[Point(x=start[0], y=start[1], z=start[2]),
                                                 Point(x=end[0], y=end[1], z=end[2])],
                      scale=Vector3(x=SHAFT_M, y=2 * SHAFT_M, z=2 * SHAFT_M),
                      color=ColorRGBA(r=1.0, g=0.2, b=0.1, a=1.0))

    def _parts(self, value: Any) -> tuple[list[float], list[float]]:
        pair = (value.proxy, value.force) if hasattr(value, "proxy") and hasattr(value, "force") else value
        try:
            start, vector = ([float(c) for c in part] for part in pair)
        except (TypeError, ValueError):
            start, vector = [], []
        if len(start) != 3 or len(vector) != 3 or not all(math.isfinite(c) for c in start + vector):
            raise WrongTypeError(f"{type(self).__name__} draws (start, vector) pairs of 3 finite numbers, or a "
                                 f"value with a proxy and a force, as {self.type_name} arrows, got {value!r}")
        return start, vector
