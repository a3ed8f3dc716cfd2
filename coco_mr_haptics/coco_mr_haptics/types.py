"""What flows on the haptic ports: device state in, force out, one sample per haptic cycle.

Small frozen records of plain floats: a haptic cycle makes a few of them every millisecond, so they
are slotted dataclasses and a named tuple, not numpy arrays.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple
from coco_core.wire import value_type

Vector = tuple[float, float, float]


@value_type
@dataclass(frozen=True, slots=True)
class HapticDeviceState:
    """A device's handle: position (m) and velocity (m/s) in the device's workspace frame, buttons as
    a bit mask (bit i = button i pressed), ``stamp`` in ``time.perf_counter`` seconds."""

    position: Vector
    velocity: Vector = (0.0, 0.0, 0.0)
    buttons: int = 0
    stamp: float = 0.0

    def pressed(self, button: int) -> bool:
        return bool(self.buttons >> button & 1)


@value_type
@dataclass(frozen=True, slots=True)
class HapticForce:
    """The force (N) to apply to the handle, in the device's workspace frame."""

    force: Vector
    stamp: float = 0.0


@value_type
class HapticSample(NamedTuple):
    """One haptic cycle as the renderer saw it, in the renderer's frame (the CSV's row)."""

    time: float
    device: Vector
    proxy: Vector
    force: Vector
    contact: bool
    renderer: str
    """Name of the renderer in contact ("" when none; the first one when several)."""
    depth: float
    """Penetration along the normal (m), the deepest among the renderers in contact."""
    unready: str = ""
    """Renderers (comma-separated) with no surface to render this cycle: a HapticCloud before its
    first cloud structure; a run where they stay unready touched nothing it was meant to."""
    fault: bool = False
    """A renderer's force (or the sum) was not finite this cycle: it was left out (zero sent)."""
