"""CPython's garbage collector kept out of a real-time loop's cycles.

CPython frees most objects by reference counting at once; its cyclic collector runs besides, when
the allocations since the last collection pass a threshold, in whichever thread happens to allocate,
and holds the interpreter lock for the whole collection: a few hundred microseconds to milliseconds
with a large heap. A 1 kHz haptic loop that allocates (every float and tuple does) then misses a
deadline now and then, whatever its scheduling class. In a ``<process gc="between_cycles">``:

- once every activity of the process is configured, everything built so far (components, their
  kernels, caches) is frozen (``gc.freeze``: moved where no collection ever scans it again) and
  automatic collection is turned off;
- the process's fastest periodic activity runs the collections the thresholds ask for itself,
  right after a cycle, when at least ``slack`` remains before its next deadline (what a collection
  of the young objects takes, with margin); when the slack is never there, a young generation ten
  times over its threshold is collected anyway, so that garbage cannot pile up for ever (counted as
  ``forced``).

Reference counting still frees everything that is not in a cycle at once; only cyclic garbage
waits for the next collection.
"""

from __future__ import annotations

import gc
import logging

log = logging.getLogger("coco")

GC_MODES = ("auto", "between_cycles")
"""The ``<process gc=...>`` values: CPython's own collector, or collections between cycles."""

SLACK = 300e-6
"""s before the next deadline in which a collection may still start (a young-generation collection
after freezing takes tens of microseconds)."""

FORCED = 10
"""A young generation this many times over its threshold is collected even without the slack."""


class GarbageBetweenCycles:
    """Collections run by one periodic activity between its cycles; see the module docstring."""

    def __init__(self, slack: float = SLACK) -> None:
        self.slack = slack
        self.collections = 0
        """Collections run between cycles with the slack there."""
        self.forced = 0
        """Collections run without the slack, garbage having piled up to FORCED times the threshold."""

    @staticmethod
    def take_over() -> None:
        """Freeze what the process built and turn automatic collection off (the process is configured)."""
        gc.collect()
        gc.freeze()
        gc.disable()

    def after_cycle(self, deadline: float, now: float) -> None:
        """Collect what the thresholds ask for if the time to ``deadline`` allows (or garbage piled up)."""
        young, middle, old = gc.get_count()
        first, second, third = gc.get_threshold()
        if young < first:
            return
        if deadline - now < self.slack:
            if young < FORCED * first:
                return
            self.forced += 1
        else:
            self.collections += 1
        gc.collect(2 if old >= third else 1 if middle >= second else 0)

    def describe(self) -> str:
        return (f"{self.collections} garbage collections between cycles"
                + (f", {self.forced} forced without the slack" if self.forced else ""))
