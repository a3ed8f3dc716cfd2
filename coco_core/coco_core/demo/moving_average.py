"""A triggered filter: the moving average of the last ``window`` samples."""

from __future__ import annotations

from collections import deque

from ..attributes import Attribute
from ..component import Component
from ..operations import operation
from ..ports import InputPort, OutputPort
from ..stamps import Stamped


MAX_WINDOW = 100_000
"""The largest window, in samples: 100 s of a 1 kHz signal. Every sample sums the whole window, so
``set_window(10**12)`` from a caller would make each update slower without end as samples come."""


class MovingAverage(Component):
    """Averages every incoming sample with the ones before it; keeps the input's stamp."""

    window = Attribute(int, 8, "number of samples averaged", min=1, max=MAX_WINDOW)

    sample = InputPort(Stamped, event=True, doc="samples to filter; each arrival triggers an update")
    filtered = OutputPort(Stamped, "the average, with the stamp of the newest sample in it")

    def init(self) -> None:
        self._values: deque[float] = deque(maxlen=self.window)

    @operation
    def set_window(self, window: int) -> int:
        """Change the window (runs in this component's thread); returns the previous one. A window
        outside 1..:data:`MAX_WINDOW` is refused (the attribute's bounds), the old one kept."""
        previous = self.window
        self.window = window
        self._values = deque(self._values, maxlen=self.window)
        return previous

    def on_update(self) -> None:
        for sample in self.sample.read_all():
            self._values.append(sample.value)
            self.filtered.write(Stamped(sum(self._values) / len(self._values), sample.stamp))
