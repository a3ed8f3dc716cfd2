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
import struct

from coco_core.errors import WrongTypeError
from std_msgs.msg import Float64

from .base import Converter
from .cdr_writer import ENCAPSULATION

_DOUBLE = struct.Struct("<d")


class Float64Converter(Converter[Float64, float]):
    """``std_msgs/Float64`` <-> ``float``."""

    type_name = "std_msgs/msg/Float64"
    coco_type = float
    writes_cdr = True

    def to_coco(self, msg: Float64) -> float:
        self._check_message(msg)
        return msg.data

    def to_ros(self, value: float) -> Float64:
        return Float64(data=self._real(value))

    def to_cdr(self, value: float) -> bytes:
        return ENCAPSULATION + _DOUBLE.pack(self._real(value))

    def _real(self, value: float) -> float:
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise WrongTypeError(f"{type(self).__name__} publishes real numbers as {self.type_name}, "
                                 f"got {type(value).__name__}")
        return float(value)
