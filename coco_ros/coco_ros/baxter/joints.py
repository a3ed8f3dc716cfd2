"""How a real Baxter names and orders its joints, and how joint_recorder's gripper column maps to
the URDF's finger joints.

Joint order
    :data:`ROBOT_JOINT_NAMES` is the ``name`` field of a real ``/robot/joint_states`` message
    (osrf/baxter_demos, ``hand_calib_pos.dat``; a copy is in ``shared/data/baxter/``): alphabetical,
    with ``head_nod`` and ``torso_t0``, which are *fixed* joints in example-robot-data's URDF (a
    consumer ignores them, as robot_state_publisher does). :func:`parse_joint_state_dump` reads such
    a dump so a test can check the constant against the file.

    That message came from a Baxter without electric grippers. With grippers the finger joints are
    on the topic too; :data:`BAXTER_JOINT_NAMES` (what this package writes) is the 17 real names in
    their real order followed by the four finger joints, left hand first.

Gripper mapping
    joint_recorder writes ``left_gripper`` / ``right_gripper`` as the gripper position in percent
    (0 = closed, 100 = fully open, baxter_interface's ``Gripper.position()``). In the URDF the
    electric gripper has a prismatic ``?_gripper_l_finger_joint`` (limits 0 .. 0.020833 m, axis +y)
    and ``?_gripper_r_finger_joint`` that mimics it with multiplier -1 (limits -0.020833 .. 0). A
    larger ``l_finger`` value moves the two fingers apart (the l finger tip sits at y = 0.01575 + q,
    the r finger tip at y = -0.01575 - q), so the mapping is linear::

        l_finger = clamp(percent, 0, 100) / 100 * 0.020833     (0 closed .. 0.020833 open)
        r_finger = -1.0 * l_finger                               (the URDF's mimic multiplier)
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

from coco_core.errors import RecordingError

ROBOT_JOINT_NAMES: tuple[str, ...] = (
    # Copied from a real Baxter's /robot/joint_states: osrf/baxter_demos, hand_calib_pos.dat
    # (Apache-2.0). Alphabetical; head_nod and torso_t0 are fixed joints in the URDF.
    "head_nod",
    "head_pan",
    "left_e0",
    "left_e1",
    "left_s0",
    "left_s1",
    "left_w0",
    "left_w1",
    "left_w2",
    "right_e0",
    "right_e1",
    "right_s0",
    "right_s1",
    "right_w0",
    "right_w1",
    "right_w2",
    "torso_t0",
)

ARM_JOINTS: dict[str, tuple[str, ...]] = {
    # The kinematic order (shoulder to wrist), as joint_recorder writes its columns.
    side: tuple(f"{side}_{j}" for j in ("s0", "s1", "e0", "e1", "w0", "w1", "w2"))
    for side in ("left", "right")
}

FINGER_JOINTS: dict[str, tuple[str, str]] = {
    # joint_recorder gripper column -> (driven finger joint, mimic finger joint) in the URDF.
    "left": ("l_gripper_l_finger_joint", "l_gripper_r_finger_joint"),
    "right": ("r_gripper_l_finger_joint", "r_gripper_r_finger_joint"),
}

GRIPPER_COLUMNS: dict[str, str] = {"left_gripper": "left", "right_gripper": "right"}
"""joint_recorder's gripper columns -> the arm side."""

FINGER_UPPER = 0.020833
"""Upper limit (m) of ``?_gripper_l_finger_joint`` in the URDF (lower: 0); fully open."""
FINGER_MIMIC_MULTIPLIER = -1.0
"""``?_gripper_r_finger_joint`` = multiplier * ``?_gripper_l_finger_joint`` (URDF ``<mimic>``)."""

BAXTER_JOINT_NAMES: tuple[str, ...] = ROBOT_JOINT_NAMES + FINGER_JOINTS["left"] + FINGER_JOINTS["right"]
"""What this package publishes on /robot/joint_states: the real order, then the finger joints."""


def gripper_to_fingers(percent: float) -> tuple[float, float]:
    """joint_recorder's gripper percent (0 closed .. 100 open) -> (l_finger, r_finger) positions (m)."""
    fraction = min(max(float(percent), 0.0), 100.0) / 100.0
    left = fraction * FINGER_UPPER
    return left, FINGER_MIMIC_MULTIPLIER * left


def fingers_to_gripper(l_finger: float) -> float:
    """Inverse of :func:`gripper_to_fingers`: the driven finger position (m) -> percent open."""
    return min(max(l_finger / FINGER_UPPER, 0.0), 1.0) * 100.0


def parse_joint_state_dump(path: str | Path) -> dict[str, list]:
    """Read a ``rostopic echo``-style dump of a JointState (``name: [...]``, ``position: [...]``...)."""
    result: dict[str, list] = {}
    text = Path(path).read_text(encoding="utf-8")
    for line_number, line in enumerate(text.splitlines(), 1):
        match = re.match(r"\s*(\w+)\s*:\s*(\[.*\])\s*$", line)
        if match:
            try:
                result[match.group(1)] = list(ast.literal_eval(match.group(2)))
            except (ValueError, SyntaxError):
                raise RecordingError(f"{path}:{line_number}: expected a Python-style list after "
                                     f"'{match.group(1)}:'") from None
    if "name" not in result:
        raise RecordingError(f"{path}: no 'name: [...]' line (expected a dump of a sensor_msgs/JointState)")
    return result
