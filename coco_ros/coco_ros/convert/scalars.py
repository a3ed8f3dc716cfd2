"""``std_msgs/Float64`` <-> ``float``: one number per message, such as a distance or a gain.

What the teleop components write (``EndEffectorDistance.distance``, a ``Stamped[float]``) goes out
as a Float64 through a ROSInterface, which unwraps the ``Stamped``; a one-element
``Float64MultiArray`` would say the same with a layout to fill in and to check on the other side.
Any real number is published (Python and numpy integers and floats, converted to ``float``); a
``bool`` is refused, since a flag published as 0.0 or 1.0 is more likely a wiring mistake than a
measurement.
"""

from __future__ import annotations

import numbers

from coco_core.errors import WrongTypeError
from std_msgs.msg import Float64

from .base import Converter


class Float64Converter(Converter[Float64, float]):
    """``std_msgs/Float64`` <-> ``float``."""

    type_name = "std_msgs/msg/Float64"
    coco_type = float

    def to_coco(self, msg: Float64) -> float:
        self._check_message(msg)
        return msg.data

    def to_ros(self, value: float) -> Float64:
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise WrongTypeError(f"{type(self).__name__} publishes real numbers as {self.type_name}, "
                                 f"got {type(value).__name__}")
        return Float64(data=float(value))
