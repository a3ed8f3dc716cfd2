"""SimulatedDevice: a named stand-in for a haptic device, closed through a virtual coupling.

There is no haptic hardware on this machine, so a simulated 3-DoF handle takes its place with the
same ports a real device driver has (state out, force in). It is not a replay of positions: a hand
(a trajectory from a CSV file, or targets on the ``hand`` port: points, or poses such as a bag's
PoseStamped through BagReplay)
pulls the handle through a spring-damper *virtual coupling*, and the rendered force pushes back, so
a stiff surface stops the handle while the hand goes on (the coupling stretches), as a user's hand
holding a real device would.

Handle dynamics, semi-implicit Euler at each update (``m`` mass, ``b`` the device's own damping):

    m dv/dt = clamp(F_rendered, max_force) + k_c (hand - x) + b_c (v_hand - v) - b v

with the position held inside the workspace box (the velocity into a limit is dropped).
"""

from __future__ import annotations

import csv
import math
import time
from pathlib import Path

import numpy as np

from coco_core.attributes import Attribute, FileAttribute
from coco_core.component import Component
from coco_core.errors import HapticDeviceError
from coco_core.files import DATA_FILE_LIMIT, read_regular_file
from coco_core.policy import NEW_DATA, NO_DATA
from coco_core.ports import InputPort, OutputPort
from coco_core.stamps import Stamped, unstamped
from coco_core.transforms.samples import FramePose, TransformSample

from .types import HapticDeviceState, HapticForce


class HandTrajectory:
    """Hand positions over time from a CSV file with the header ``time,x,y,z`` (seconds, metres;
    an optional ``buttons`` column); linear interpolation, held at the ends."""

    def __init__(self, path: Path) -> None:
        text = read_regular_file(path, DATA_FILE_LIMIT, "hand trajectory").decode("utf-8", errors="replace")
        reader = csv.DictReader(text.splitlines())
        missing = {"time", "x", "y", "z"} - set(reader.fieldnames or [])
        if missing:
            raise HapticDeviceError(f"{path}: a hand trajectory needs the columns time,x,y,z; "
                                    f"missing {', '.join(sorted(missing))} (found {reader.fieldnames})")
        rows = []
        for line, row in enumerate(reader, start=2):
            try:
                rows.append((float(row["time"]), float(row["x"]), float(row["y"]), float(row["z"]),
                             float(row.get("buttons") or 0)))
            except (TypeError, ValueError):  # a short row gives None for its missing fields
                raise HapticDeviceError(f"{path}:{line}: expected numbers, got {row}") from None
            if not all(map(math.isfinite, rows[-1])):
                raise HapticDeviceError(f"{path}:{line}: expected finite numbers, got {row}")
        if len(rows) < 2:
            raise HapticDeviceError(f"{path}: a hand trajectory needs at least 2 rows, got {len(rows)}")
        table = np.array(rows)
        if np.any(np.diff(table[:, 0]) <= 0):
            raise HapticDeviceError(f"{path}: time must increase from row to row")
        self.times, self.points, self.buttons = table[:, 0] - table[0, 0], table[:, 1:4], table[:, 4]
        self._index = 0

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    def at(self, t: float) -> tuple[tuple[float, float, float], int]:
        """Hand position and buttons at ``t`` seconds from the start (a cursor: cheap when ``t`` grows)."""
        times = self.times
        if t <= 0.0 or t >= times[-1]:
            end = 0 if t <= 0.0 else -1
            x, y, z = (float(v) for v in self.points[end])
            return (x, y, z), int(self.buttons[end])
        i = self._index if times[self._index] <= t else 0
        while times[i + 1] < t:
            i += 1
        self._index = i
        s = (t - times[i]) / (times[i + 1] - times[i])
        a, b = self.points[i], self.points[i + 1]
        return ((float(a[0] + (b[0] - a[0]) * s), float(a[1] + (b[1] - a[1]) * s),
                 float(a[2] + (b[2] - a[2]) * s)), int(self.buttons[i]))


class SimulatedDevice(Component):
    """A simulated 3-DoF haptic handle (not hardware): mass, damping, force limit, workspace box,
    driven by a hand through a virtual coupling."""

    mass = Attribute(float, 0.1, "kg: the handle's moving mass", min=1e-6)
    damping = Attribute(float, 1.0, "N s/m: the handle's own damping", min=0.0)
    max_force = Attribute(float, 8.0, "N: the largest force the device can render", min=0.0)
    workspace_min = Attribute(list[float], [-0.1, -0.1, -0.1], "m: lower corner of the workspace box")
    workspace_max = Attribute(list[float], [0.1, 0.1, 0.1], "m: upper corner of the workspace box")
    coupling_stiffness = Attribute(float, 300.0, "N/m: the virtual coupling from hand to handle", min=0.0)
    coupling_damping = Attribute(float, 3.0, "N s/m: the virtual coupling's damping", min=0.0)
    trajectory = FileAttribute("", "CSV file time,x,y,z[,buttons] of the hand (workspace frame); "
                               "empty: targets arrive on the hand port", expected="a CSV file time,x,y,z[,buttons]")
    time_step = Attribute(float, 0.0, "s per update; 0 = the measured time between updates (real time)",
                          min=0.0)
    stop_at_end = Attribute(bool, False, "stop the application once the trajectory is over")

    force = InputPort(HapticForce, doc="the rendered force (workspace frame)")
    hand = InputPort(tuple | Stamped | FramePose | TransformSample,
                     doc="hand target (workspace frame), when no trajectory file: x y z, or the translation "
                         "of a pose (a PoseStamped from a bag through BagReplay, a tracked frame)")
    state = OutputPort(HapticDeviceState, doc="the handle: position, velocity, buttons")

    def on_config(self) -> None:
        for name in ("workspace_min", "workspace_max"):
            if len(getattr(self, name)) != 3:
                raise HapticDeviceError(f"{self.name}: {name} needs 3 numbers, got {getattr(self, name)}")
        if any(lo >= hi for lo, hi in zip(self.workspace_min, self.workspace_max)):
            raise HapticDeviceError(f"{self.name}: workspace_min {self.workspace_min} must be below "
                                    f"workspace_max {self.workspace_max} on every axis")
        self._trajectory = None
        if self.trajectory:
            with self.reading_attribute_file("trajectory"):
                self._trajectory = HandTrajectory(Path(self.trajectory))
        if self._trajectory is not None:
            hand, self._buttons = self._trajectory.at(0.0)
        else:
            hand, self._buttons = self._clamp(0.0, 0.0, 0.0), 0
        self._hand = hand
        self._hand_velocity = (0.0, 0.0, 0.0)
        self.x, self.y, self.z = self._clamp(*hand)
        self.vx = self.vy = self.vz = 0.0
        self.elapsed = 0.0
        self._last: float | None = None
        self._rendered = (0.0, 0.0, 0.0)
        self._stop_requested = False

    def _clamp(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        lo, hi = self.workspace_min, self.workspace_max
        return min(max(x, lo[0]), hi[0]), min(max(y, lo[1]), hi[1]), min(max(z, lo[2]), hi[2])

    def _time_step(self) -> float:
        if self.time_step > 0.0:
            return self.time_step
        now = time.perf_counter()
        last, self._last = self._last, now
        # The first update, or one after a long stall, integrates one nominal millisecond.
        return 1e-3 if last is None or now - last > 0.01 else now - last

    def _hand_target(self, dt: float) -> None:
        previous = self._hand
        if self._trajectory is not None:
            self._hand, self._buttons = self._trajectory.at(self.elapsed)
        else:
            status, value = self.hand.read()
            if status is NEW_DATA:
                target, _ = unstamped(value)
                transform = getattr(target, "transform", None)  # a FramePose / TransformSample
                if transform is not None:
                    target = transform[:3, 3]
                hand = (float(target[0]), float(target[1]), float(target[2]))
                if all(map(math.isfinite, hand)):
                    self._hand = hand
                else:  # a tracker that lost the hand: one NaN would put the handle at NaN for good
                    self.record_refusal("a hand target", HapticDeviceError(
                        f"non-finite hand target {hand}; the last finite one kept"))
        if dt > 0.0:
            self._hand_velocity = ((self._hand[0] - previous[0]) / dt, (self._hand[1] - previous[1]) / dt,
                                   (self._hand[2] - previous[2]) / dt)

    def on_update(self) -> None:
        dt = self._time_step()
        self.elapsed += dt
        self._hand_target(dt)
        status, value = self.force.read()
        if status is not NO_DATA:
            if math.isfinite(sum(value.force)):
                self._rendered = value.force
            else:  # a real device must never be commanded NaN; the simulated one refuses it the same way
                self._rendered = (0.0, 0.0, 0.0)
                self.record_refusal("a force", HapticDeviceError(f"non-finite force {value.force}; "
                                                                 "zero force applied"))
        fx, fy, fz = self._rendered
        magnitude = math.sqrt(fx * fx + fy * fy + fz * fz)
        if magnitude > self.max_force:
            scale = self.max_force / magnitude
            fx, fy, fz = fx * scale, fy * scale, fz * scale
        kc, bc, b, m = self.coupling_stiffness, self.coupling_damping, self.damping, self.mass
        (hx, hy, hz), (hvx, hvy, hvz) = self._hand, self._hand_velocity
        ax = (fx + kc * (hx - self.x) + bc * (hvx - self.vx) - b * self.vx) / m
        ay = (fy + kc * (hy - self.y) + bc * (hvy - self.vy) - b * self.vy) / m
        az = (fz + kc * (hz - self.z) + bc * (hvz - self.vz) - b * self.vz) / m
        self.vx, self.vy, self.vz = self.vx + ax * dt, self.vy + ay * dt, self.vz + az * dt
        x, y, z = self.x + self.vx * dt, self.y + self.vy * dt, self.z + self.vz * dt
        cx, cy, cz = self._clamp(x, y, z)
        if cx != x:
            self.vx = 0.0
        if cy != y:
            self.vy = 0.0
        if cz != z:
            self.vz = 0.0
        self.x, self.y, self.z = cx, cy, cz
        self.state.write(HapticDeviceState((cx, cy, cz), (self.vx, self.vy, self.vz), self._buttons,
                                           time.perf_counter()))
        trajectory = self._trajectory
        if (self.stop_at_end and trajectory is not None and not self._stop_requested
                and self.elapsed > trajectory.duration and self.app is not None):
            self._stop_requested = True
            self.app.request_stop(f"{self.name}: the hand trajectory is over")

    @property
    def hand_position(self) -> tuple[float, float, float]:
        return self._hand
