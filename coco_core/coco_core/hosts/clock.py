"""One clock for every host: each host's offset to the first host's clock, measured at start.

Stamps are ``time.perf_counter`` seconds (CLOCK_MONOTONIC on Linux), whose origin differs from
machine to machine, so a latency from a stamp written on one host and read on another is
meaningless until both are on one clock. As the paper did with PTP, and as NTP does over a network,
each host asks the first host for its time several times at start: one exchange gives the offset
with an error of at most half its round trip, so the exchange with the shortest round trip is kept
(NTP's clock filter). A writer puts its stamps on the application's clock (:meth:`ClockOffset.to_app`)
and a reader back on its own (:meth:`ClockOffset.from_app`), so that latencies are computed on one
clock, the first host's, wherever data went.
"""

from __future__ import annotations

from dataclasses import dataclass

EXCHANGES = 8
"""Clock exchanges per host at start; the one with the shortest round trip gives the offset."""


@dataclass(frozen=True)
class ClockOffset:
    """This host's clock against the application's: ``application time = local time + offset``."""

    offset: float = 0.0
    """Seconds."""
    uncertainty: float = 0.0
    """Seconds the offset may be off by: half the round trip of the exchange it came from."""
    exchanges: int = 0
    """How many exchanges it was chosen from (0: this is the first host, whose clock it is)."""

    def to_app(self, local: float) -> float:
        return local + self.offset

    def from_app(self, app_time: float) -> float:
        return app_time - self.offset

    def describe(self) -> str:
        if not self.exchanges:
            return "the application's clock"
        return (f"offset {self.offset * 1e3:+.3f} ms +- {self.uncertainty * 1e3:.3f} ms to the first host's "
                f"clock ({self.exchanges} exchanges)")


def exchange(sent: float, received: float, replied: float, back: float) -> tuple[float, float]:
    """(offset, round trip) of one exchange: asked at ``sent`` and answered at ``back`` here,
    received at ``received`` and replied at ``replied`` on the first host (NTP's formulas)."""
    offset = ((received - sent) + (replied - back)) / 2
    return offset, (back - sent) - (replied - received)


def best(exchanges: list[tuple[float, float]]) -> ClockOffset:
    """The offset of the exchange with the shortest round trip among ``exchanges`` (offset, round trip)."""
    offset, round_trip = min(exchanges, key=lambda pair: pair[1])
    return ClockOffset(offset, max(round_trip, 0.0) / 2, len(exchanges))
