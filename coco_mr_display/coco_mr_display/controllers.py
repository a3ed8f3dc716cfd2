"""Camera controllers: peers of a GLCameraManager that move its camera from window input.

Both are :class:`~coco_mr_display.events.EventHandler` components nested in the camera
(``<components>`` of the GLCameraManager in the XML): GLManager hands them the window's events, then
steps them. They act on the camera's pose only, so they suit a free camera (not one that follows a
graph frame or a pose port, which would override them every frame).

- :class:`FPSCamera`: first-person flight. W/S forward/back along the view direction, A/D sideways,
  E/Q up/down along the world's up; Shift moves ``fast_factor`` times faster; dragging with
  ``look_button`` turns (yaw about the world's up, pitch about the camera's x axis); scrolling
  steps forward/back.
- :class:`ArcBallCamera`: Shoemake's arcball around a target point. Dragging with ``rotate_button``
  turns the scene as if the cursor rolled a ball under the window; ``pan_button`` slides camera
  and target in the view plane (the point under the cursor stays under it); scrolling zooms.
"""

from __future__ import annotations

import math
import time

import numpy as np

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import WrongTypeError
from coco_core.transforms import se3

from .camera import GLCameraManager
from .events import Action, EventHandler, EventKind, InputEvent, MouseButton

_BUTTONS = {"left": MouseButton.LEFT, "right": MouseButton.RIGHT, "middle": MouseButton.MIDDLE}
_MOD_SHIFT = 0x0001
"""GLFW's MOD_SHIFT bit."""


class CameraController(EventHandler, Component):
    """What both controllers share: the camera they drive, and drags with one mouse button."""

    def init(self) -> None:
        self._drags: dict[int, tuple[float, float]] = {}
        """Buttons held, with the cursor position of the last event of their drag."""

    @property
    def camera(self) -> GLCameraManager:
        """The camera this controller moves: its owner (checked in ``on_config``)."""
        return self.owner  # type: ignore[return-value]

    def on_config(self) -> None:
        if not isinstance(self.owner, GLCameraManager):
            raise WrongTypeError(f"{type(self).__name__} {self.name} must be a peer of a GLCameraManager, not of "
                                 f"{self.owner.name if self.owner else 'nothing'}")

    def handle_event(self, event: InputEvent) -> None:
        if event.kind is EventKind.MOUSE_BUTTON:
            if event.action is Action.PRESS:
                self._drags[event.button] = (event.x, event.y)
            else:
                self._drags.pop(event.button, None)
        elif event.kind is EventKind.CURSOR:
            for button, (x, y) in list(self._drags.items()):
                self._drags[button] = (event.x, event.y)
                self.drag(button, (x, y), (event.x, event.y), event.size)

    def drag(self, button: int, start: tuple[float, float], end: tuple[float, float], size: tuple[int, int]) -> None:
        """The cursor moved from ``start`` to ``end`` (window pixels) while ``button`` was held."""


class FPSCamera(CameraController):
    """First-person (fly) camera: keys move, dragging turns."""

    speed = Attribute(float, 1.0, "metres per second while a move key is held", min=0.0)
    fast_factor = Attribute(float, 4.0, "speed multiplier while Shift is held", min=0.0)
    sensitivity = Attribute(float, 0.004, "radians turned per pixel dragged", min=0.0)
    scroll_step = Attribute(float, 0.25, "metres moved forward per scroll unit")
    look_button = Attribute(str, "left", "mouse button that turns the camera", choices=tuple(_BUTTONS))

    MOVES = {"W": (0, -1.0), "S": (0, 1.0), "D": (1, 1.0), "A": (1, -1.0), "E": (2, 1.0), "Q": (2, -1.0)}
    """Key -> (axis: 0 view direction, 1 camera x, 2 world up; sign, on the camera's +Z / x / up)."""

    MAX_PITCH = math.radians(89.0)

    def init(self) -> None:
        super().init()
        self._held: set[str] = set()
        self._fast = False
        self._last_update: float | None = None

    def handle_event(self, event: InputEvent) -> None:
        if event.kind is EventKind.KEY:
            if event.key in ("LEFT_SHIFT", "RIGHT_SHIFT"):  # X reports the modifiers as they were before
                self._fast = event.action is not Action.RELEASE
            else:
                self._fast = bool(event.mods & _MOD_SHIFT)
            if event.key in self.MOVES:
                if event.action is Action.RELEASE:
                    self._held.discard(event.key)
                else:
                    self._held.add(event.key)
        elif event.kind is EventKind.SCROLL:
            pose = self.camera.camera_pose
            pose[:3, 3] -= pose[:3, 2] * self.scroll_step * event.y
            self.camera.camera_pose = pose
        else:
            super().handle_event(event)

    def on_update(self) -> None:
        """Move for the time since the last update while keys are held (frame-rate independent)."""
        now = time.perf_counter()
        elapsed = min(now - self._last_update, 0.1) if self._last_update is not None else 0.0
        self._last_update = now
        if not self._held or elapsed <= 0.0:
            return
        pose = self.camera.camera_pose
        axes = (pose[:3, 2], pose[:3, 0], self._up())
        velocity = np.zeros(3)
        for key in self._held:
            axis, sign = self.MOVES[key]
            velocity += sign * axes[axis]
        pose[:3, 3] += velocity * self.speed * (self.fast_factor if self._fast else 1.0) * elapsed
        self.camera.camera_pose = pose

    def _up(self) -> np.ndarray:
        up = np.asarray(self.camera.up, float)
        return up / np.linalg.norm(up)

    def drag(self, button: int, start: tuple[float, float], end: tuple[float, float], size: tuple[int, int]) -> None:
        if button != _BUTTONS[self.look_button]:
            return
        pose, up = self.camera.camera_pose, self._up()
        yaw = -(end[0] - start[0]) * self.sensitivity  # dragging right turns right
        pitch = -(end[1] - start[1]) * self.sensitivity  # dragging down looks down
        forward = -pose[:3, 2]
        current = math.asin(float(np.clip(forward @ up, -1.0, 1.0)))
        pitch = float(np.clip(current + pitch, -self.MAX_PITCH, self.MAX_PITCH)) - current
        rotation = se3.axis_angle(up, yaw) @ se3.axis_angle(pose[:3, 0], pitch)
        pose[:3, :3] = rotation @ pose[:3, :3]
        self.camera.camera_pose = pose


class ArcBallCamera(CameraController):
    """Orbit, pan and zoom around a target point."""

    target: Attribute[list[float]] = Attribute(list[float], [], "point orbited around (world frame); empty: the camera's look_at",
                       check=lambda v: None if len(v) in (0, 3) else f"expected 3 numbers or nothing, got {len(v)}")
    rotate_button = Attribute(str, "left", "mouse button that rotates", choices=tuple(_BUTTONS))
    pan_button = Attribute(str, "right", "mouse button that pans", choices=tuple(_BUTTONS))
    zoom_factor = Attribute(float, 1.1, "distance divided by this per scroll unit (towards the target)", min=1.0)
    min_distance = Attribute(float, 0.01, "closest the camera gets to the target (m)", min=0.0)

    def on_config(self) -> None:
        super().on_config()
        self.centre = np.asarray(self.target or self.camera.look_at, float)
        """The current target: panning moves it."""

    @staticmethod
    def sphere_point(x: float, y: float, size: tuple[int, int]) -> np.ndarray:
        """Shoemake's mapping of a window pixel to the unit ball (camera axes: x right, y up, z back)."""
        width, height = size
        radius = min(width, height) / 2.0
        p = np.array([(x - width / 2.0) / radius, (height / 2.0 - y) / radius, 0.0])
        squared = p[0] ** 2 + p[1] ** 2
        if squared <= 1.0:
            p[2] = math.sqrt(1.0 - squared)
        else:
            p /= math.sqrt(squared)
        return p

    def handle_event(self, event: InputEvent) -> None:
        if event.kind is EventKind.SCROLL:
            pose = self.camera.camera_pose
            offset = pose[:3, 3] - self.centre
            distance = np.linalg.norm(offset)
            wanted = max(distance / self.zoom_factor ** event.y, self.min_distance)
            pose[:3, 3] = self.centre + offset * (wanted / distance if distance > 0 else 1.0)
            self.camera.camera_pose = pose
        else:
            super().handle_event(event)

    def drag(self, button: int, start: tuple[float, float], end: tuple[float, float], size: tuple[int, int]) -> None:
        if button == _BUTTONS[self.rotate_button]:
            self._rotate(self.sphere_point(*start, size), self.sphere_point(*end, size))
        elif button == _BUTTONS[self.pan_button]:
            self._pan(end[0] - start[0], end[1] - start[1], size[1])

    def _rotate(self, p0: np.ndarray, p1: np.ndarray) -> None:
        axis = np.cross(p0, p1)
        norm = np.linalg.norm(axis)
        if norm < 1e-12:
            return
        angle = math.atan2(norm, float(p0 @ p1))
        pose = self.camera.camera_pose
        # The scene turns by +angle about the axis (camera coordinates): the camera orbits the other way.
        orbit = se3.axis_angle(pose[:3, :3] @ (axis / norm), -angle)
        pose[:3, :3] = orbit @ pose[:3, :3]
        pose[:3, 3] = self.centre + orbit @ (pose[:3, 3] - self.centre)
        self.camera.camera_pose = pose

    def _pan(self, dx: float, dy: float, height: int) -> None:
        pose = self.camera.camera_pose
        # Metres per pixel at the target's depth: the dragged point stays under the cursor.
        depth = float(-(pose[:3, :3].T @ (self.centre - pose[:3, 3]))[2])
        scale = 2.0 * max(depth, self.min_distance) * math.tan(math.radians(self.camera.fov_y) / 2) / height
        shift = (-dx * pose[:3, 0] + dy * pose[:3, 1]) * scale
        pose[:3, 3] += shift
        self.centre = self.centre + shift
        self.camera.camera_pose = pose
