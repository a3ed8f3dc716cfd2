"""Components the interoperability apps (``test/data/interop_*.xml``) need besides the library ones.

``EndEffectorDistance`` writes ``Stamped[float]`` and no ROS converter publishes a ``Stamped``, so
:class:`StampedArray` turns each one into the 1-element array a ``std_msgs/Float64MultiArray``
publication of a ``ROSInterface`` takes. The launcher imports this module by ``module:Class`` with
``test/data`` on ``PYTHONPATH``.
"""

from __future__ import annotations

import numpy as np
from coco_core import Component, InputPort, OutputPort
from coco_core.stamps import Stamped


class StampedArray(Component):
    """Every ``Stamped`` number on ``value`` -> ``np.array([number])`` on ``out``, in order."""

    value = InputPort(Stamped, event=True)
    out = OutputPort(np.ndarray)

    def on_update(self) -> None:
        for sample in self.value.read_all():
            self.out.write(np.array([float(sample.value)]))
