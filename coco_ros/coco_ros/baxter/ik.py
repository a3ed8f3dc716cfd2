"""Damped least-squares IK for one Baxter arm with Pinocchio, on example-robot-data's Baxter URDF.

:class:`ArmIk` solves the 7 arm joints so that a frame (default ``left_gripper``, the electric
gripper's tip) reaches a pose in the ``base`` frame. Each step is
``dq = J^T (J J^T + lambda^2 I)^-1 e`` with ``e`` the 6D error (``log6`` of the pose error, in the
frame's local coordinates), plus a small null-space pull towards a rest posture; the result is
clamped to the URDF's joint limits after every step. Warm-started from the previous solution, a
trajectory sampled at 100 Hz needs one or two steps per sample.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pinocchio as pin
from coco_core.errors import UrdfError

from .joints import ARM_JOINTS

BAXTER_URDF = "package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"

NEUTRAL = {
    # baxter_interface's "neutral" arm posture (Limb.move_to_neutral), right arm mirrored.
    "left": (0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0),
    "right": (0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0),
}


def load_baxter():
    """The Baxter :class:`~coco_core.transforms.urdf.UrdfModel` (Pinocchio model inside)."""
    from coco_core.transforms.urdf import UrdfModel

    return UrdfModel.load(BAXTER_URDF)


@dataclass
class IkResult:
    q: np.ndarray
    """The arm's 7 joint values."""
    position_error: float
    rotation_error: float
    iterations: int

    @property
    def converged(self) -> bool:
        return self.position_error < 1e-3 and self.rotation_error < 1e-2


class ArmIk:
    """IK on one arm of a Pinocchio model; other joints stay at ``q_full``'s values."""

    def __init__(self, model: "pin.Model", side: str = "left", frame: str | None = None,
                 rest: Sequence[float] | None = None, damping: float = 1e-3, null_gain: float = 0.05) -> None:
        self.model = model
        self.data = model.createData()
        self.frame_id = model.getFrameId(frame or f"{side}_gripper")
        if self.frame_id >= model.nframes:
            raise UrdfError(f"the model has no frame {frame or side + '_gripper'}")
        self.joints = ARM_JOINTS[side]
        ids = [model.getJointId(name) for name in self.joints]
        self.q_index = np.array([model.joints[i].idx_q for i in ids])
        self.v_index = np.array([model.joints[i].idx_v for i in ids])
        self.lower = np.array([model.lowerPositionLimit[i] for i in self.q_index])
        self.upper = np.array([model.upperPositionLimit[i] for i in self.q_index])
        self.q_full = pin.neutral(model)
        self.rest = np.array(rest if rest is not None else NEUTRAL[side], dtype=float)
        self.damping = damping
        self.null_gain = null_gain

    def forward(self, q_arm: Sequence[float] | np.ndarray) -> "pin.SE3":
        """The frame's pose in the model root (``base``) for the arm joint values."""
        q = self.q_full.copy()
        q[self.q_index] = q_arm
        pin.framesForwardKinematics(self.model, self.data, q)
        return self.data.oMf[self.frame_id].copy()

    def solve(self, target: "pin.SE3", q_start: Sequence[float] | np.ndarray, max_iterations: int = 100,
              tolerance: float = 1e-6) -> IkResult:
        """Arm joints placing the frame at ``target`` (base frame), starting from ``q_start``."""
        model, data = self.model, self.data
        q = self.q_full.copy()
        q_arm = np.clip(np.asarray(q_start, dtype=float), self.lower, self.upper)
        eye6 = np.eye(6)
        iterations = 0
        for iterations in range(1, max_iterations + 1):
            q[self.q_index] = q_arm
            pin.framesForwardKinematics(model, data, q)
            current = data.oMf[self.frame_id]
            error = pin.log6(current.actInv(target)).vector
            if error[:3] @ error[:3] < tolerance**2 and error[3:] @ error[3:] < (10 * tolerance) ** 2:
                break
            pin.computeJointJacobians(model, data, q)
            jacobian = pin.getFrameJacobian(model, data, self.frame_id, pin.LOCAL)[:, self.v_index]
            jjt = jacobian @ jacobian.T + self.damping**2 * eye6
            pinv = jacobian.T @ np.linalg.solve(jjt, eye6)
            dq = pinv @ error
            dq += (np.eye(len(q_arm)) - pinv @ jacobian) @ (self.null_gain * (self.rest - q_arm))
            step = np.max(np.abs(dq))
            if step > 0.2:  # keep each step small: the linearisation holds and the arm does not flip
                dq *= 0.2 / step
            q_arm = np.clip(q_arm + dq, self.lower, self.upper)
        q[self.q_index] = q_arm
        pin.framesForwardKinematics(model, data, q)
        error = pin.log6(data.oMf[self.frame_id].actInv(target)).vector
        return IkResult(q_arm, float(np.linalg.norm(error[:3])), float(np.linalg.norm(error[3:])), iterations)
