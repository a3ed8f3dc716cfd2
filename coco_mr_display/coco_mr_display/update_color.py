"""UpdateColor: a peer of a GLEntity that colours it from a scalar through a colour map, or directly.

As the paper's teleoperation app colours the bowl by the end-effector distance: the scalar ``value``
input (a float or a ``Stamped[float]``, e.g. ``EndEffectorDistance.distance``) is mapped from
``min``..``max`` through ``colormap``; a colour arriving on ``color`` (an RGB/RGBA tuple or
``Stamped`` one, e.g. ``EndEffectorDistance.color``) is used as it is. Whichever arrived last wins.
The entity calls ``preRender`` right after this peer's update, in the same frame, so the colour drawn
is the one read this frame. Until anything arrives, the entity keeps its own colour; a NaN value is
ignored (the last colour stays).

Colour maps: ``green_yellow_red`` (green at ``min``, yellow half-way, red at ``max``, linear in
between: the teleop app's UpdateColorCalc mapping) and every matplotlib colour map by name.
"""

from __future__ import annotations

import math
from typing import Any, Callable


from coco_core.attributes import Attribute
from coco_core.colors import green_yellow_red
from coco_core.component import Component, UnknownNameError
from coco_core.errors import AttributeValueError, SetupError, did_you_mean
from coco_core.operations import operation
from coco_core.policy import NEW_DATA
from coco_core.ports import InputPort
from coco_core.stamps import Stamp, Stamped, unstamped

from .draw_state import DrawState
from .shown import ShownInputs

ColorMap = Callable[[float], tuple[float, float, float, float]]

NAMED_MAPS: dict[str, Callable[[float], tuple[float, float, float]]] = {"green_yellow_red": green_yellow_red}
"""Colour maps of this project, before matplotlib's (the teleop app's UpdateColorCalc scale)."""


def colormap(name: str) -> ColorMap:
    """The colour map called ``name``: one of :data:`NAMED_MAPS` or matplotlib's; s in 0..1 -> RGBA."""
    if name in NAMED_MAPS:
        rgb = NAMED_MAPS[name]
        return lambda s: (*rgb(s), 1.0)
    import matplotlib

    try:
        mapping = matplotlib.colormaps[name]
    except KeyError:
        raise UnknownNameError(f"unknown colour map {name!r}; "
                               f"{did_you_mean(name, [*NAMED_MAPS, *matplotlib.colormaps])}") from None
    return lambda s: tuple(float(channel) for channel in mapping(float(s)))  # type: ignore[return-value]


def _color_of(value: Any) -> tuple[float, ...]:
    values = tuple(float(channel) for channel in value)
    if len(values) not in (3, 4):
        raise AttributeValueError(f"a colour is r g b or r g b a in 0..1, got {value!r}")
    return values


class UpdateColor(Component):
    """Peer of a GLEntity: sets its colour every frame from ``value`` (mapped) or ``color``."""

    colormap = Attribute(str, "green_yellow_red", "colour map: green_yellow_red or a matplotlib name")
    min = Attribute(float, 0.0, "value drawn with the colour map's first colour (and below)")
    max = Attribute(float, 1.0, "value drawn with the colour map's last colour (and above)")

    value = InputPort(float | Stamped, doc="scalar to colour by (float or Stamped[float])")
    color = InputPort(tuple | Stamped, doc="colour to use as it is: r g b [a] in 0..1 (tuple or Stamped[tuple])")

    def on_config(self) -> None:
        if not self.max > self.min:
            raise SetupError(f"{self.name}: max ({self.max}) must be greater than min ({self.min})")
        self._map = colormap(self.colormap)
        self.current: tuple[float, ...] | None = None
        """The colour preRender applies; None until a value or colour arrived."""
        self.shown = ShownInputs()
        """The origin of the colour the next frame shows first (its GLManager stamps the frame with it)."""

    def map(self, value: float) -> tuple[float, float, float, float]:
        """The colour of ``value``: ``min``..``max`` through the colour map, clamped."""
        s = (value - self.min) / (self.max - self.min)
        return self._map(min(1.0, max(0.0, s)))

    def on_update(self) -> None:
        # The newest value or colour is drawn; the ones skipped count as dropped on their connections.
        status, value = self.value.read_newest()
        if status is NEW_DATA:
            scalar = unstamped(value)[0]
            if not math.isnan(float(scalar)):
                self._apply(self.map(float(scalar)), self.value.origin)
        status, value = self.color.read_newest()
        if status is NEW_DATA:
            self._apply(_color_of(unstamped(value)[0]), self.color.origin)

    def _apply(self, color: tuple[float, ...], stamp: Stamp | None) -> None:
        """Use ``color`` from now on; a stamped input's latency to this peer ends here, to the screen
        in its GLManager (``shown``)."""
        self.current = color
        self.shown.add(stamp)
        if stamp is not None:
            self.record_latency(stamp)

    @operation(name="preRender")
    def pre_render(self, state: DrawState) -> None:
        """Colour the entity (every part, its own colours too) with the current colour."""
        if self.current is not None:
            state.set_color(self.current)
