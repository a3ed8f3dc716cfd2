"""A triggered filter: the moving average of the last ``window`` samples."""

from __future__ import annotations

from collections import deque

from ..attributes import Attribute
from ..component import Component
from ..operations import operation
from ..ports import InputPort, OutputPort
from ..stamps import Stamped


class MovingAverage(Component):
    """Averages every incoming sample with the ones before it; keeps the input's stamp."""

    window = Attribute(int, 8, "number of samples averaged", min=1)

    sample = InputPort(Stamped, event=True, doc="samples to filter; each arrival triggers an update")
    filtered = OutputPort(Stamped, "the average, with the stamp of the newest sample in it")

    def init(self) -> None:
        self._values: deque[float] = deque(maxlen=self.window)

    @operation
    def set_window(self, window: int) -> int:
        """Change the window (runs in this component's thread); returns the previous one."""
        previous = self.window
        self.window = window
        self._values = deque(self._values, maxlen=self.window)
        return previous

    def on_update(self) -> None:
        for sample in self.sample.read_all():
            self._values.append(sample.value)
            self.filtered.write(Stamped(sum(self._values) / len(self._values), sample.stamp))
