"""Baxter data for CoCo: real joint naming, joint_recorder CSV import, a generated teleoperation session.

- :mod:`.joints`: the order and names a real Baxter publishes on ``/robot/joint_states``, and the
  joint_recorder gripper percentage -> URDF finger joints mapping.
- :mod:`.importer`: a Baxter SDK ``joint_recorder`` CSV -> a bag with ``/robot/joint_states``
  (CLI ``baxter-import``).
- :mod:`.session`: a seeded, generated pick-and-place teleoperation session as a bag, the arm
  motion solved with Pinocchio IK on the real Baxter URDF (CLI ``baxter-session``).
"""

from .joints import (
    ARM_JOINTS,
    BAXTER_JOINT_NAMES,
    FINGER_JOINTS,
    GRIPPER_COLUMNS,
    ROBOT_JOINT_NAMES,
    gripper_to_fingers,
)

__all__ = [
    "ARM_JOINTS",
    "BAXTER_JOINT_NAMES",
    "FINGER_JOINTS",
    "GRIPPER_COLUMNS",
    "ROBOT_JOINT_NAMES",
    "gripper_to_fingers",
]
