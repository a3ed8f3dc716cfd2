"""Timing on a noisy machine: calibrated loops, measured interleaved, medians and paired ratios.

A *variant* is a callable ``loop(n)`` that performs ``n`` operations. Every variant is first run to
pick ``n`` so that one repeat lasts about ``target_s`` (this also warms caches, allocators and DDS),
then the repeats go round-robin over all variants: noise from other processes hits the variants of
one round alike, and ratios are taken per round (paired) before the median.
"""

from __future__ import annotations

import gc
import statistics
import time
from dataclasses import dataclass
from typing import Callable

Loop = Callable[[int], None]


@dataclass
class Samples:
    """Per-operation times of one variant, in nanoseconds, one per repeat."""

    name: str
    per_op_ns: list[float]
    ops_per_repeat: int

    @property
    def median(self) -> float:
        return statistics.median(self.per_op_ns) if self.per_op_ns else float("nan")

    def to_json(self) -> dict[str, object]:
        return {"median_ns": self.median, "per_op_ns": self.per_op_ns, "ops_per_repeat": self.ops_per_repeat}

    def ratio_to(self, anchor: Samples) -> float:
        """Median over repeats of ``anchor / self``: how many times cheaper than the anchor."""
        pairs = [a / s for a, s in zip(anchor.per_op_ns, self.per_op_ns) if s > 0]
        return statistics.median(pairs) if pairs else float("nan")


def _timed(loop: Loop, n: int, clock: Callable[[], int] = time.perf_counter_ns) -> int:
    """Nanoseconds of ``clock`` for ``loop(n)``, with the cyclic garbage collector held off meanwhile."""
    gc.collect()
    gc.disable()
    try:
        start = clock()
        loop(n)
        return clock() - start
    finally:
        gc.enable()


def calibrate(loop: Loop, target_s: float, max_ops: int = 10_000_000) -> int:
    """Operations per repeat so that one repeat lasts about ``target_s``; doubles as the warm-up.
    Each step is timed twice and the shorter kept: a step that other processes delayed by tens of
    milliseconds (a loaded machine) would otherwise stop the doubling at a few operations, and
    every repeat of that variant would then time little more than the timer."""
    n = 1
    while True:
        elapsed = min(_timed(loop, n), _timed(loop, n))
        if elapsed >= target_s * 1e9 / 4 or n >= max_ops:
            break
        n *= 4 if elapsed < target_s * 1e9 / 64 else 2
    return max(1, min(max_ops, int(n * target_s * 1e9 / max(elapsed, 1))))


def measure(variants: dict[str, Loop], repeats: int = 7, target_s: float = 0.05) -> dict[str, Samples]:
    """Calibrate every variant, then run ``repeats`` interleaved rounds; rotate the order per round."""
    names = list(variants)
    ops = {name: calibrate(variants[name], target_s) for name in names}
    samples = {name: Samples(name, [], ops[name]) for name in names}
    for round_ in range(repeats):
        shift = round_ % len(names)
        for name in names[shift:] + names[:shift]:
            samples[name].per_op_ns.append(_timed(variants[name], ops[name]) / ops[name])
    return samples


def measure_cpu(variants: dict[str, Loop], ops: dict[str, int], repeats: int = 7) -> dict[str, Samples]:
    """Like :func:`measure` (``ops`` per repeat, from its samples), on the calling thread's CPU clock:
    for loops that run in this thread alone, a cost that other processes on the machine do not
    inflate (the time they take the core from the loop is not counted), where wall time does."""
    names = list(variants)
    samples = {name: Samples(name, [], ops[name]) for name in names}
    for round_ in range(repeats):
        shift = round_ % len(names)
        for name in names[shift:] + names[:shift]:
            samples[name].per_op_ns.append(_timed(variants[name], ops[name], time.thread_time_ns) / ops[name])
    return samples
