"""A distribution of non-negative quantities (durations, point counts) in bounded memory, for the
summaries of runs of any length.

A summary that keeps every latency it saw to take a median at the end grows with the run: the Baxter
replay looped for ten minutes grew its launcher by megabytes a minute, most of it the pages that the
kept floats pinned, not the floats. :class:`LogHistogram` keeps a count per logarithmic bin
instead (an HDR histogram's idea): its size is fixed whatever the run's length, and a quantile is
exact to the bin's relative width (``precision``, 0.5 % by default; 4,600 bins from 100 ns to 1000 s
for durations in seconds; ``lowest`` and ``highest`` suit other quantities).
Count, mean and max are exact.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import MeasurementError


class LogHistogram:
    """Counts of non-negative values in logarithmic bins; see the module docstring."""

    def __init__(self, lowest: float = 1e-7, highest: float = 1e3, precision: float = 0.005) -> None:
        if not 0 < lowest < highest or not 0 < precision < 1:
            raise MeasurementError("need 0 < lowest < highest and 0 < precision < 1, "
                                   f"got {lowest}, {highest}, {precision}")
        self.lowest = lowest
        self._scale = 1.0 / math.log1p(precision)
        self._bins = np.zeros(int(math.log(highest / lowest) * self._scale) + 2, dtype=np.int64)
        self._ratio = 1.0 + precision
        self.count = 0
        self.total = 0.0
        self.max = -math.inf
        self.min = math.inf

    def record(self, value: float) -> None:
        """Count one value; negative and non-finite ones are refused (:class:`MeasurementError`: a
        clock error upstream, for a duration)."""
        if not math.isfinite(value) or value < 0:
            raise MeasurementError(f"a value must be a finite number >= 0, got {value!r}")
        index = 0 if value <= self.lowest else min(int(math.log(value / self.lowest) * self._scale) + 1,
                                                    len(self._bins) - 1)
        self._bins[index] += 1
        self.count += 1
        self.total += value
        if value > self.max:
            self.max = value
        if value < self.min:
            self.min = value

    @property
    def mean(self) -> float | None:
        return self.total / self.count if self.count else None

    def quantile(self, q: float) -> float:
        """The ``q`` quantile (0..1) to the bins' precision, within the exact min and max (which it is
        for a quantile below ``lowest`` or above ``highest``)."""
        if not 0.0 <= q <= 1.0:
            raise MeasurementError(f"a quantile is between 0 and 1, got {q}")
        if not self.count:
            raise MeasurementError("nothing was recorded: there is no quantile")
        rank = q * (self.count - 1)  # the same rank as a sorted list's index (floor), as numpy's "lower"
        index = int(np.searchsorted(np.cumsum(self._bins), math.floor(rank) + 1))
        if index == 0:  # at or below lowest: the smallest there is
            return self.min
        if index == len(self._bins) - 1:  # above highest: the largest
            return self.max
        return min(max(self.lowest * self._ratio ** (index - 0.5), self.min), self.max)  # the bin's middle

    def milliseconds(self, **quantiles: float) -> dict[str, float | None]:
        """The named quantiles (``median=0.5``), the max and the mean, in milliseconds, for a summary's
        JSON; nulls when nothing was recorded. The mean because some figures are stated as one (the
        CoCo paper's 75 ms sensor-to-display latency is an average)."""
        mean = self.mean
        if mean is None:
            return {**{name: None for name in quantiles}, "max": None, "mean": None}
        return {**{name: 1e3 * self.quantile(q) for name, q in quantiles.items()}, "max": 1e3 * self.max,
                "mean": 1e3 * mean}
