"""The paper's UpdateColorCalc colour scale, shared by what computes a colour and what draws it.

The teleoperation app colours the bowl by the end-effector distance: green when close, yellow
half-way, red when far. EndEffectorDistance (coco_ros) computes that colour and UpdateColor
(coco_mr_display) can compute it from the distance itself; both must give the same colour, so the
scale lives here, in the package both depend on.
"""

from __future__ import annotations

import math

GREEN = (0.0, 1.0, 0.0)
YELLOW = (1.0, 1.0, 0.0)
RED = (1.0, 0.0, 0.0)


def green_yellow_red(s: float) -> tuple[float, float, float]:
    """RGB (0..1) of ``s`` in 0..1 (clamped): green at 0, yellow at 0.5, red at 1, linear in between;
    NaN (unknown) is red, the colour of "not there yet"."""
    if math.isnan(s):
        return RED
    s = min(1.0, max(0.0, s))
    return (min(1.0, 2.0 * s), min(1.0, 2.0 * (1.0 - s)), 0.0)
