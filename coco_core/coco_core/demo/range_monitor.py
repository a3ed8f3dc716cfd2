"""A peer that watches values and counts those outside a range."""

from __future__ import annotations

import logging

from ..attributes import Attribute
from ..component import Component
from ..ports import InputPort
from ..stamps import Stamped

log = logging.getLogger("coco")


class RangeMonitor(Component):
    """Counts values outside ``[low, high]``; logs the first one of each excursion."""

    low = Attribute(float, -1.0, "lowest accepted value")
    high = Attribute(float, 1.0, "highest accepted value")

    values = InputPort(Stamped, doc="values to check")

    def init(self) -> None:
        self.checked = 0
        self.outside = 0
        self._inside = True

    def on_update(self) -> None:
        for sample in self.values.read_all():
            self.checked += 1
            inside = self.low <= sample.value <= self.high
            if not inside:
                self.outside += 1
                if self._inside:
                    log.info("%s: value %.3f (sample %d) left [%g, %g]", self.name, sample.value,
                             sample.stamp.seq, self.low, self.high)
            self._inside = inside

    def on_stop(self) -> None:
        log.info("%s: %d of %d values outside [%g, %g]", self.name, self.outside, self.checked,
                 self.low, self.high)
