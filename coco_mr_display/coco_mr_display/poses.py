"""Reading a pose from a port value, once for every display component.

Pose inputs (a camera pose, a head position, an entity pose) accept what the rest of the runtime
produces: a ``FramePose`` (TransformationInterface), a ``TransformSample`` (ROS bridges, bag replay),
a bare 4x4 matrix, each possibly wrapped in a ``Stamped`` by a stamping producer.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from coco_core.errors import WrongTypeError
from coco_core.stamps import unstamped
from coco_core.transforms.samples import FramePose, TransformSample


def reference_of(value: Any) -> tuple[str | None, np.ndarray]:
    """(frame the pose is expressed in, or None when the value does not say; 4x4) of a pose value."""
    value = unstamped(value)[0]
    if isinstance(value, FramePose):
        return value.target, np.asarray(value.transform, dtype=float)
    if isinstance(value, TransformSample):
        return value.parent, np.asarray(value.transform, dtype=float)
    matrix = np.asarray(value, dtype=float) if isinstance(value, (np.ndarray, list, tuple)) else None
    if matrix is None or matrix.shape != (4, 4):
        raise WrongTypeError(f"a pose input takes a FramePose, a TransformSample or a 4x4 matrix, got {value!r}")
    return None, matrix


def as_transform(value: Any) -> np.ndarray:
    """The 4x4 transform of a pose value, whatever frame it says it is in."""
    return reference_of(value)[1]
