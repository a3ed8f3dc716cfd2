"""The god-object (proxy) of one device point on one implicit surface, and its contact material.

The algorithm is in :mod:`coco_mr_haptics.kernel` (compiled); this is the object a renderer holds:
the proxy's state and the material as two small arrays the kernel updates in place, read back as
plain floats. One :meth:`GodObject.step` per haptic cycle is one call into compiled code.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import kernel
from .scene import Scene


@dataclass
class Material:
    """The contact's parameters (SI units)."""

    stiffness: float = 800.0
    """N/m between device and proxy."""
    damping: float = 1.0
    """N s/m on the device velocity along the contact normal. The spring held for a 1 ms cycle returns
    up to stiffness x 0.5 ms N s/m more than it took (Colgate's passivity bound); damping above that
    keeps the contact passive."""
    static_friction: float = 0.0
    """Coefficient of the cone inside which the proxy sticks."""
    dynamic_friction: float = 0.0
    """Coefficient of the cone on which a sliding proxy trails the device."""
    max_force: float = 8.0
    """N: the force is clamped to this magnitude."""
    max_slide: float = 4e-4
    """m per sliding sub-step: keep it below half the thinnest wall of the scene."""
    iterations: int = 12
    """Sliding sub-steps per cycle: ``iterations * max_slide`` is how far the proxy may slide in one
    cycle (4.8 mm, a hand at 4.8 m/s at 1 kHz)."""

    def vector(self, out: np.ndarray | None = None) -> np.ndarray:
        """The kernel's material vector (filled in place when ``out`` is given)."""
        out = np.empty(kernel.MATERIAL) if out is None else out
        out[:] = (self.stiffness, self.damping, self.static_friction, self.dynamic_friction,
                  self.max_force, self.max_slide, self.iterations)
        return out


def warm_up() -> None:
    """Load the compiled kernel now (about a second the first time in a process, from numba's cache;
    longer after a change of the kernel), so that the first haptic cycle is not the one that pays."""
    global _warm
    if not _warm:
        from .implicit import Sphere

        GodObject(Scene(Sphere(1.0)), warm=False).step(0.0, 0.0, 0.5)
        _warm = True


_warm = False


class GodObject:
    """The proxy on ``scene``: :meth:`step` with the device position (and velocity) each cycle."""

    def __init__(self, scene: Scene, material: Material | None = None, *, warm: bool = True) -> None:
        if warm:
            warm_up()
        self.scene = scene
        self.material = material or Material()
        self.state = kernel.new_state()
        self._material = self.material.vector()

    def set_material(self, material: Material) -> None:
        self.material = material
        self.material.vector(self._material)

    def reset(self) -> None:
        """Forget the history: the next step starts the proxy afresh."""
        self.state[:] = 0.0

    def step(self, x: float, y: float, z: float, vx: float = 0.0, vy: float = 0.0,
             vz: float = 0.0) -> bool:
        """Move the proxy for the device at ``(x, y, z)`` moving at ``v``; True in contact."""
        scene = self.scene
        return kernel.step(scene.ops, scene.prm, scene.stack, self.state, self._material,
                           float(x), float(y), float(z), float(vx), float(vy), float(vz))

    @property
    def contact(self) -> bool:
        return bool(self.state[kernel.CONTACT])

    @property
    def sticking(self) -> bool:
        return bool(self.state[kernel.STICKING])

    @property
    def proxy(self) -> tuple[float, float, float]:
        s = self.state
        return float(s[kernel.PX]), float(s[kernel.PY]), float(s[kernel.PZ])

    @property
    def normal(self) -> tuple[float, float, float]:
        """Outward normal at the proxy (meaningful in contact)."""
        s = self.state
        return float(s[kernel.NX]), float(s[kernel.NY]), float(s[kernel.NZ])

    @property
    def force(self) -> tuple[float, float, float]:
        """The force on the device from the last step (N)."""
        s = self.state
        return float(s[kernel.FX]), float(s[kernel.FY]), float(s[kernel.FZ])

    @property
    def depth(self) -> float:
        """Penetration of the device along the normal at the last step (m)."""
        return float(self.state[kernel.DEPTH])
