"""``sensor_msgs/JointState`` <-> :class:`JointSample`.

Incoming joint states become a :class:`JointStateSample`: a ``JointSample`` (so the transformation
interface and anything else that takes joint samples accepts it) that also keeps the velocities and
efforts, ``None`` when the message has none. Positions are required: a JointState that carries only
velocities or efforts is refused, since a sample without positions would move no joint. Any
``JointSample`` can be published; velocities and efforts are written when it has them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from coco_core.transforms.samples import JointSample
from sensor_msgs.msg import JointState

from .base import Converter, header_stamp, make_header, typed_array


@dataclass(frozen=True, slots=True)
class JointStateSample(JointSample):
    """A :class:`JointSample` with the optional velocities and efforts of a JointState, in the order
    of ``names``."""

    velocities: np.ndarray | None = None
    efforts: np.ndarray | None = None


class JointStateConverter(Converter[JointState, JointSample]):
    """``sensor_msgs/JointState`` <-> :class:`JointSample` (a :class:`JointStateSample` when read)."""

    type_name = "sensor_msgs/msg/JointState"
    coco_type = JointSample

    def to_coco(self, msg: JointState) -> JointStateSample:
        self._check_message(msg)
        names = tuple(msg.name)
        positions = _values(msg.position, "position", names, required=True)
        return JointStateSample(names, positions, header_stamp(msg.header),
                                _values(msg.velocity, "velocity", names), _values(msg.effort, "effort", names))

    def to_ros(self, value: JointSample) -> JointState:
        self._check_value(value)
        msg = JointState(header=make_header(value.stamp, ""), name=list(value.names))
        msg.position = _checked(value.positions, "positions", value.names)
        if isinstance(value, JointStateSample):
            if value.velocities is not None:
                msg.velocity = _checked(value.velocities, "velocities", value.names)
            if value.efforts is not None:
                msg.effort = _checked(value.efforts, "efforts", value.names)
        return msg


def _values(field: object, label: str, names: tuple[str, ...], required: bool = False) -> np.ndarray | None:
    values = np.array(field, dtype=np.float64)
    if len(values) == len(names) and (len(values) or required):
        return values
    if len(values) == 0 and not required:
        return None
    raise ValueError(f"JointState has {len(names)} names but {len(values)} {label} values"
                     + (" (positions are required)" if required and not len(values) else ""))


def _checked(values: np.ndarray, label: str, names: tuple[str, ...]):
    array = np.asarray(values, dtype=np.float64).reshape(-1)
    if len(array) != len(names):
        raise ValueError(f"a joint sample with {len(names)} names has {len(array)} {label}")
    return typed_array(array, "d")
