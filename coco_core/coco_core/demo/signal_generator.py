"""A periodic source: a noisy sine wave, stamped at acquisition."""

from __future__ import annotations

import math
import random
import time

from ..attributes import Attribute
from ..component import Component
from ..ports import OutputPort
from ..stamps import Stamp, Stamped


class SignalGenerator(Component):
    """Writes one sample of ``amplitude * sin(2 pi frequency t) + noise`` per activation."""

    frequency = Attribute(float, 0.5, "sine frequency in Hz; may be changed while running", min=0.0, live=True)
    amplitude = Attribute(float, 1.0, "peak value of the sine", live=True)
    noise = Attribute(float, 0.1, "standard deviation of the added Gaussian noise", min=0.0, live=True)
    seed = Attribute(int, 1, "seed of the noise, so that runs are repeatable")

    sample = OutputPort(Stamped, "the noisy sample, stamped when it was produced")

    def on_config(self) -> None:
        self._random = random.Random(self.seed)
        self._start = time.perf_counter()
        self._phase = 0.0
        self._last = self._start
        self._seq = 0

    def on_update(self) -> None:
        now = time.perf_counter()
        # Integrate the phase so that a frequency change at run time does not make the signal jump.
        self._phase += 2.0 * math.pi * self.frequency * (now - self._last)
        self._last = now
        self._seq += 1
        value = self.amplitude * math.sin(self._phase) + self._random.gauss(0.0, self.noise)
        self.sample.write(Stamped(value, Stamp(now, self._seq, self.name)))
