"""LogHistogram: a run's latency distribution in fixed memory, its quantiles to 0.5 %."""

from __future__ import annotations

import numpy as np
import pytest

from coco_core.errors import MeasurementError
from coco_core.histogram import LogHistogram


def test_quantiles_match_the_sorted_values_to_the_precision() -> None:
    values = np.random.default_rng(3).lognormal(np.log(0.02), 1.0, 20_001)  # latencies around 20 ms
    histogram = LogHistogram()
    for value in values:
        histogram.record(float(value))
    for q in (0.0, 0.01, 0.5, 0.9, 0.99, 1.0):
        exact = float(np.quantile(values, q, method="lower"))
        assert histogram.quantile(q) == pytest.approx(exact, rel=0.005), q
    assert histogram.count == len(values)
    assert histogram.mean == pytest.approx(values.mean(), rel=1e-12)
    assert histogram.max == values.max() and histogram.min == values.min()


def test_its_size_does_not_grow_with_the_run() -> None:
    histogram = LogHistogram()
    size = histogram._bins.nbytes
    for value in np.linspace(0.0, 5.0, 100_000):
        histogram.record(float(value))
    assert histogram._bins.nbytes == size < 64_000
    assert histogram.quantile(0.5) == pytest.approx(2.5, rel=0.005)


def test_values_outside_the_range_are_kept_by_the_exact_extremes() -> None:
    histogram = LogHistogram(lowest=1e-3, highest=1.0)
    for value in (0.0, 5e-4, 0.5, 30.0):
        histogram.record(value)
    assert histogram.quantile(0.0) == 0.0 and histogram.quantile(1.0) == 30.0


@pytest.mark.parametrize("value", [-1e-3, float("nan"), float("inf")])
def test_a_negative_or_non_finite_duration_is_refused(value: float) -> None:
    with pytest.raises(MeasurementError, match="finite number >= 0"):
        LogHistogram().record(value)


def test_an_empty_histogram_has_no_quantile() -> None:
    histogram = LogHistogram()
    assert histogram.mean is None
    with pytest.raises(MeasurementError, match="nothing was recorded"):
        histogram.quantile(0.5)
