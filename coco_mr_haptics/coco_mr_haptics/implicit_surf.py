"""HapticImplicitSurf: the god-object on an implicit surface described in the application file.

    <attribute name="surface" value="difference(box(size=[0.2,0.2,0.1]), translate([0,0,0.05], sphere(0.04)))"/>

The expression (see :mod:`coco_mr_haptics.expression` and docs/xml_format.md) is checked when the
file is loaded, so a typo is reported at its file:line and column. Placements written
``frame('name', ...)`` follow that frame of the transformation graph every haptic cycle (a tracked
object); the proxy is held by the surface as it moves. Changing ``surface`` at run time swaps the
scene between two cycles, the proxy staying where it is.
"""

from __future__ import annotations

import numpy as np

from coco_core.attributes import Attribute
from coco_core.errors import AttributeValueError

from .expression import parse_surface, surface_problem
from .proxy import GodObject
from .renderer import SurfaceRenderer
from .scene import Scene


class HapticImplicitSurf(SurfaceRenderer):
    """Proxy-based rendering of an implicit surface (Salisbury and Tarr 1997)."""

    surface = Attribute(str, "", "the surface expression, e.g. sphere(0.05) or "
                        "difference(box(size=[0.2,0.2,0.1]), sphere(0.04))", check=surface_problem)

    def on_config(self) -> None:
        super().on_config()
        if not self.surface.strip():
            raise AttributeValueError(f"{self.name}: the attribute surface is empty; describe the surface, "
                                      "e.g. sphere(0.05)")
        self.scene = Scene(parse_surface(self.surface))
        self._built = self.surface
        self.proxy_object = GodObject(self.scene, self.material())
        self._material_changed = False
        self._frames: dict[str, np.ndarray | None] = {frame: None for frame in self.scene.frames}

    def prepare(self) -> None:
        if self.surface != self._built:
            self.scene = Scene(parse_surface(self.surface))
            self._built = self.surface
            self._frames = {frame: None for frame in self.scene.frames}
            assert self.proxy_object is not None  # made in on_config
            self.proxy_object.scene = self.scene
        if self._frames:
            graph, render_frame = self.transform_graph, self.render_frame
            for frame, seen in self._frames.items():
                pose = graph.lookup(render_frame, frame)
                if pose is not seen:  # the graph hands out a new array only after a change
                    self.scene.set_frame_pose(frame, pose)
                    self._frames[frame] = pose

    def render(self, x: float, y: float, z: float, vx: float, vy: float, vz: float) -> bool:
        assert self.proxy_object is not None  # made in on_config
        return self.proxy_object.step(x, y, z, vx, vy, vz)
