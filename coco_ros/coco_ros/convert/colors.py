"""``std_msgs/ColorRGBA`` <-> an RGB(A) tuple: the colours CoCo computes (``UpdateColorCalc``'s
green-yellow-red of the teleoperation's distance) as RViz and Foxglove take them.

A colour is three or four numbers in 0..1, alpha 1 when absent; anything else (a NaN, a component
outside 0..1, another length) is refused, so that a wrong port mirrored as a colour is not mistaken
for a colour by a viewer.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from coco_core.errors import WrongTypeError
from std_msgs.msg import ColorRGBA

from .base import Converter

RGBA = tuple[float, float, float, float]


class ColorRGBAConverter(Converter[ColorRGBA, tuple]):
    """``std_msgs/ColorRGBA`` <-> ``(r, g, b, a)``; ``(r, g, b)`` is published with alpha 1."""

    type_name = "std_msgs/msg/ColorRGBA"
    coco_type = tuple

    def to_coco(self, msg: ColorRGBA) -> RGBA:
        self._check_message(msg)
        return (msg.r, msg.g, msg.b, msg.a)

    def to_ros(self, value: Sequence[float]) -> ColorRGBA:
        try:
            channels = [float(channel) for channel in value]
        except (TypeError, ValueError):
            raise WrongTypeError(f"{type(self).__name__} publishes (r, g, b[, a]) in 0..1 as {self.type_name}, "
                                 f"got {value!r}") from None
        if len(channels) == 3:
            channels.append(1.0)
        if len(channels) != 4 or not all(math.isfinite(c) and 0.0 <= c <= 1.0 for c in channels):
            raise WrongTypeError(f"{type(self).__name__} publishes (r, g, b[, a]) in 0..1 as {self.type_name}, "
                                 f"got {value!r}")
        return ColorRGBA(r=channels[0], g=channels[1], b=channels[2], a=channels[3])
