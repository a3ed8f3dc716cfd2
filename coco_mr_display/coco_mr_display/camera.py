"""GLCameraManager: where the eyes are, and the RenderViews GLManager draws each frame.

Two projections:

- ``perspective``: a camera pose (from attributes, a followed graph frame, the ``pose`` port or a
  controller peer) and a symmetric frustum (``fov_y``, ``near``, ``far``).
- ``oblique``: Kooima's off-axis projection for a physical screen (three corners in the world frame)
  seen from a tracked eye (``eye`` port, ``eye_frame`` in the graph, or the ``eye_position``
  attribute): what the viewer sees is co-located with the real scene behind/in front of the screen.

Stereo puts the two eyes ``eye_separation`` apart along the camera's x axis (the head's x axis for a
tracked head pose, the screen's right axis for a tracked point); in oblique mode each eye gets its
own frustum through the same screen, in perspective mode the eyes look in parallel (zero disparity at
infinity, ``f * b / z`` pixels at depth ``z``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import SetupError
from coco_core.operations import operation
from coco_core.ports import InputPort
from coco_core.policy import NEW_DATA
from coco_core.transforms import se3
from coco_core.transforms.samples import FramePose, TransformSample

from . import projection as proj
from .poses import as_transform
from .shown import ShownInputs
from .view import Eye, RenderView

OPTICAL_TO_GL = se3.make(np.diag([1.0, -1.0, -1.0]))
"""A camera optical frame (ROS REP 103: z forward, y down) expressed in the GL camera's axes."""


def _vector3(value: list[float]) -> str | None:
    return None if len(value) == 3 else f"expected 3 numbers (x y z), got {len(value)}"


def _quaternion(value: list[float]) -> str | None:
    return None if len(value) in (0, 4) else f"expected 4 numbers (x y z w) or nothing, got {len(value)}"


class GLCameraManager(Component):
    """The camera peer of a GLManager: provides one RenderView per eye every frame."""

    projection = Attribute(str, "perspective", "perspective | oblique (off-axis, for a physical screen)",
                           choices=("perspective", "oblique"))
    position = Attribute(list[float], [3.0, 0.0, 1.0], "initial camera position in the world frame (m)",
                         check=_vector3)
    look_at = Attribute(list[float], [0.0, 0.0, 0.5], "initial point looked at (unless orientation is given)",
                        check=_vector3)
    up = Attribute(list[float], [0.0, 0.0, 1.0], "world direction shown upwards (look_at and the controllers)",
                   check=_vector3)
    orientation: Attribute[list[float]] = Attribute(list[float], [], "initial orientation as a quaternion x y z w of the GL camera "
                            "(-Z forward, +Y up) in the world; empty: from look_at", check=_quaternion)
    follow_frame = Attribute(str, "", "transformation-graph frame whose pose is the camera pose every frame")
    frame_convention = Attribute(str, "optical", "axes of follow_frame and of the pose port: optical (ROS "
                                 "camera frame, z forward, y down) or opengl (-z forward, y up)",
                                 choices=("optical", "opengl"))
    fov_y = Attribute(float, 45.0, "vertical field of view in degrees (perspective)", min=1.0, max=179.0)
    near = Attribute(float, 0.05, "near clipping distance (m)", min=1e-6)
    far = Attribute(float, 100.0, "far clipping distance (m)", min=1e-6)
    screen_lower_left = Attribute(list[float], [-0.26, 0.0, 0.0], "oblique: lower-left screen corner in the "
                                  "world frame (m)", check=_vector3)
    screen_lower_right = Attribute(list[float], [0.26, 0.0, 0.0], "oblique: lower-right screen corner",
                                   check=_vector3)
    screen_upper_left = Attribute(list[float], [-0.26, 0.0, 0.32], "oblique: upper-left screen corner",
                                  check=_vector3)
    eye_position = Attribute(list[float], [0.0, -0.6, 0.16], "oblique: eye (head centre) position in the world "
                             "frame until the eye port or eye_frame gives one", check=_vector3)
    eye_frame = Attribute(str, "", "oblique: transformation-graph frame of the tracked head (head tracking)")

    pose = InputPort(object, doc="camera pose in the world frame: FramePose, TransformSample or 4x4 "
                     "(axes per frame_convention)")
    eye = InputPort(object, doc="oblique: tracked head pose in the world frame (FramePose, TransformSample, "
                    "4x4) or a 3-vector position")

    def init(self) -> None:
        self.shown = ShownInputs()
        """The origins of the camera and head poses the next frame shows first."""
        self._pose = np.eye(4)
        self._head = np.eye(4)
        self._head_oriented = False
        """Whether the head's axes are known (a tracked pose), or only its position."""
        self.reset_pose()

    # --- pose -----------------------------------------------------------------------------------
    def reset_pose(self) -> None:
        """Camera pose and eye back to what the attributes say."""
        if self.orientation:
            self._pose = se3.make(se3.quaternion_to_matrix(self.orientation), self.position)
        else:
            self._pose = proj.look_at(self.position, self.look_at, self.up)
        self._head = se3.make(translation=self.eye_position)
        self._head_oriented = False

    @property
    def camera_pose(self) -> np.ndarray:
        """Camera -> world (GL axes: -Z forward, +Y up); a copy."""
        return self._pose.copy()

    @camera_pose.setter
    def camera_pose(self, pose: np.ndarray) -> None:
        """Set the camera -> world pose in GL axes (what controllers do)."""
        self._pose = np.array(pose, dtype=float)

    @operation
    def set_pose(self, pose: Any) -> None:
        """Set the camera pose from another thread (FramePose, TransformSample or 4x4 in the configured
        frame_convention)."""
        self._pose = self._to_gl(as_transform(pose))

    @property
    def head_position(self) -> np.ndarray:
        """Where the (tracked) head is, in the world frame."""
        return self._head[:3, 3].copy()

    def _to_gl(self, pose: np.ndarray) -> np.ndarray:
        return pose @ OPTICAL_TO_GL if self.frame_convention == "optical" else pose

    def on_config(self) -> None:
        if self.far <= self.near:
            raise SetupError(f"camera {self.name}: far ({self.far}) must be larger than near ({self.near})")
        if self.projection == "oblique":
            proj.screen_basis(self.screen_lower_left, self.screen_lower_right, self.screen_upper_left)
        self.reset_pose()  # attributes may have changed since init()

    def on_update(self) -> None:
        # The newest pose is used; the ones skipped count as dropped on their connections.
        status, value = self.pose.read_newest()
        if status is NEW_DATA:
            self._pose = self._to_gl(as_transform(value))
            self.shown.add(self.pose.origin)
        graph = self.transform_graph
        if self.follow_frame:
            self._pose = self._to_gl(graph.lookup(self._world(), self.follow_frame))
            self.shown.add_graph(graph.query(self._world(), self.follow_frame).dependencies)
        status, value = self.eye.read_newest()
        if status is NEW_DATA:
            self._set_head(value)
            self.shown.add(self.eye.origin)
        if self.eye_frame:
            self._head, self._head_oriented = graph.lookup(self._world(), self.eye_frame), True
            self.shown.add_graph(graph.query(self._world(), self.eye_frame).dependencies)

    def _set_head(self, value: Any) -> None:
        if np.size(value) == 3 and not isinstance(value, (FramePose, TransformSample)):
            self._head, self._head_oriented = se3.make(translation=np.asarray(value, float)), False
        else:
            self._head, self._head_oriented = as_transform(value), True

    def _world(self) -> str:
        owner = self.owner
        return getattr(owner, "world", "world") if owner is not None else "world"

    # --- views ----------------------------------------------------------------------------------
    def render_views(self, size: tuple[int, int], stereo: bool, eye_separation: float,
                     frame: str) -> list[RenderView]:
        """The views of one frame for a framebuffer of ``size``: one (mono) or left and right halves."""
        width, height = size
        if not stereo:
            return [self._view(Eye.MONO, 0.0, (0, 0, width, height), frame)]
        half = width // 2
        return [self._view(Eye.LEFT, -eye_separation / 2, (0, 0, half, height), frame),
                self._view(Eye.RIGHT, eye_separation / 2, (half, 0, width - half, height), frame)]

    def _view(self, eye: Eye, offset: float, viewport: tuple[int, int, int, int], frame: str) -> RenderView:
        aspect = viewport[2] / viewport[3]
        if self.projection == "oblique":
            axis = self._head[:3, 0] if self._head_oriented else \
                proj.screen_basis(self.screen_lower_left, self.screen_lower_right, self.screen_upper_left)[:, 0]
            view, projection = proj.off_axis(self.screen_lower_left, self.screen_lower_right, self.screen_upper_left,
                                             self._head[:3, 3] + offset * axis, self.near, self.far)
        else:
            pose = self._pose @ se3.make(translation=(offset, 0.0, 0.0)) if offset else self._pose
            view, projection = se3.inverse(pose), proj.perspective(self.fov_y, aspect, self.near, self.far)
        return RenderView(view, projection, viewport, eye, frame)
