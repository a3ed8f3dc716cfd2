"""A generated, seeded teleoperation session with the real Baxter URDF: pick a bowl, place it at a target.

The Baxter stands at a table (table top at ``TABLE_Z`` in ``base``). The seed places a bowl and a
target on the table within the left arm's reach (each checked with IK). The left arm goes
home (baxter_interface's neutral posture) -> pre-grasp above the bowl -> grasp (the gripper
closes) -> lift -> above the target -> lower -> release (the gripper opens) -> retreat, then holds.
Every segment is a minimum-jerk Cartesian interpolation (position linear, rotation along the
geodesic) of the ``left_gripper`` frame, solved at every joint-state sample by damped
least-squares IK with Pinocchio (:mod:`.ik`), within the URDF's joint limits.

Bowl pose: the bowl's grasp frame (a point of its rim, ``BOWL_GRASP_HEIGHT`` above the table,
z up, yawed); while grasped it follows the gripper rigidly (the gripper -> bowl offset is taken at
the grasp) and it stays where it is released.

Topics (stamps = log times = ``start_stamp`` + session time):

======================== ============================== ======= =====================================
topic                    type                           rate    notes
======================== ============================== ======= =====================================
/robot/joint_states      sensor_msgs/JointState         ``rate`` all Baxter joints, the real order
/bowl/pose               geometry_msgs/PoseStamped      30 Hz   frame ``base``
/target/pose             geometry_msgs/PoseStamped      1 Hz    frame ``base``, static; transient-local
/operator/wrist_pose     geometry_msgs/PoseStamped      60 Hz   frame ``operator_base``: simulated
                                                                wearable tracker, seeded noise
/head_camera/camera_info sensor_msgs/CameraInfo         10 Hz   640x480, nominal intrinsics
======================== ============================== ======= =====================================

Deterministic: the same arguments give the same message bytes (layout and tracker noise come from
``numpy.random.default_rng`` seeded with ``seed``; the stamps start at a fixed epoch by default;
the bag writer stores messages as canonical zero-padded CDR, see :mod:`coco_ros.bag.writer`).
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import pinocchio as pin
from coco_core.errors import CocoError, SessionError

from .ik import NEUTRAL, ArmIk, load_baxter
from .importer import finite_difference_velocities, joint_state
from .joints import ARM_JOINTS, BAXTER_JOINT_NAMES, FINGER_JOINTS, gripper_to_fingers

DEFAULT_START_NS = 1_700_000_000 * 1_000_000_000
"""Default stamp of session time 0 (2023-11-14T22:13:20Z): fixed, so runs are reproducible."""

TABLE_Z = -0.20
"""Table top height in ``base`` (m): a table of ~0.73 m in front of a Baxter on its pedestal."""
BOWL_GRASP_HEIGHT = 0.05
"""Height of the bowl's grasp frame (its rim) above the table (m)."""
APPROACH_HEIGHT = 0.15
"""Pre-grasp, lift and retreat heights above the grasp point (m)."""
GRIPPER_CLOSED_ON_BOWL = 35.0
"""Gripper percent when closed on the bowl's rim (the fingers stop on it)."""

BOWL_REGION = ((0.60, 0.80), (0.15, 0.45))
TARGET_REGION = ((0.55, 0.80), (0.15, 0.55))
MIN_SEPARATION = 0.15
YAW_RANGE = 0.5

POSE_RATES = {"/bowl/pose": 30.0, "/operator/wrist_pose": 60.0, "/target/pose": 1.0, "/head_camera/camera_info": 10.0}

T_OPERATOR_BASE_ROBOT_BASE = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, math.pi / 2), np.array([0.0, -0.4, 0.95]))
"""Where the robot's ``base`` is in the tracker's ``operator_base`` (the teleoperation mapping)."""
T_GRIPPER_WRIST = pin.SE3(np.eye(3), np.array([0.0, 0.0, -0.12]))
"""The operator's wrist relative to the grasp point the robot's gripper reproduces."""
TRACKER_NOISE = (0.002, 0.01)
"""Standard deviations of the tracker noise: position (m), rotation (rad)."""

CAMERA = {"width": 640, "height": 480, "fx": 405.0, "fy": 405.0, "cx": 319.5, "cy": 239.5, "frame_id": "head_camera"}
"""Baxter head camera: nominal pinhole intrinsics at 640x480 (not a calibration of a particular robot)."""

# (name, nominal duration s, kind)
PHASES = (
    ("home", 0.5, "hold"),
    ("approach", 2.4, "move"),
    ("descend", 1.2, "move"),
    ("grasp", 0.7, "close"),
    ("lift", 1.1, "move"),
    ("transfer", 2.4, "move"),
    ("lower", 1.1, "move"),
    ("release", 0.7, "open"),
    ("retreat", 1.1, "move"),
)
NOMINAL_DURATION = sum(p[1] for p in PHASES) + 0.5


@dataclass
class Phase:
    name: str
    start: float
    end: float
    kind: str
    pose_from: pin.SE3
    pose_to: pin.SE3
    gripper_from: float
    gripper_to: float


@dataclass
class SessionInfo:
    """What :func:`generate_session` made: layout, phase times, message counts."""

    folder: Path
    seed: int
    duration: float
    rate: float
    start_ns: int
    bowl: np.ndarray
    """Initial bowl grasp-frame pose in ``base`` (4x4)."""
    target: np.ndarray
    """Target pose in ``base`` (4x4)."""
    grasp_time: float
    """Session time when the gripper has closed on the bowl (it follows the gripper from then)."""
    release_time: float
    """Session time when the gripper starts opening (the bowl stays from then)."""
    phases: list[tuple[str, float, float]] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)
    max_ik_error: float = 0.0
    """Largest position error (m) of the IK over all samples."""


def min_jerk(tau: float) -> float:
    tau = min(max(tau, 0.0), 1.0)
    return tau**3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)


def interpolate(a: pin.SE3, b: pin.SE3, s: float) -> pin.SE3:
    rotation = a.rotation @ pin.exp3(s * pin.log3(a.rotation.T @ b.rotation))
    return pin.SE3(rotation, a.translation + s * (b.translation - a.translation))


def _down(yaw: float) -> np.ndarray:
    """Gripper rotation pointing down (z towards the table), yawed."""
    return pin.rpy.rpyToMatrix(0.0, 0.0, yaw) @ pin.rpy.rpyToMatrix(math.pi, 0.0, 0.0)


def _grasp_pose(position: np.ndarray, yaw: float, lift: float = 0.0) -> pin.SE3:
    return pin.SE3(_down(yaw), position + np.array([0.0, 0.0, lift]))


def choose_layout(ik: ArmIk, rng: np.random.Generator, tries: int = 100) -> tuple[pin.SE3, pin.SE3]:
    """Seeded bowl and target poses (``base``, z up) whose grasp and approach poses the IK reaches."""
    home = np.array(NEUTRAL["left"])
    z = TABLE_Z + BOWL_GRASP_HEIGHT

    def sample(region):
        return np.array([rng.uniform(*region[0]), rng.uniform(*region[1]), z]), float(rng.uniform(-YAW_RANGE, YAW_RANGE))

    def reachable(position, yaw) -> bool:
        q = home
        for lift in (APPROACH_HEIGHT, 0.0):
            result = ik.solve(_grasp_pose(position, yaw, lift), q, max_iterations=300, tolerance=1e-5)
            if not result.converged:
                return False
            q = result.q
        return True

    for _ in range(tries):
        bowl, bowl_yaw = sample(BOWL_REGION)
        target, target_yaw = sample(TARGET_REGION)
        if np.linalg.norm(bowl[:2] - target[:2]) < MIN_SEPARATION:
            continue
        if reachable(bowl, bowl_yaw) and reachable(target, target_yaw):
            upright = pin.rpy.rpyToMatrix
            return pin.SE3(upright(0, 0, bowl_yaw), bowl), pin.SE3(upright(0, 0, target_yaw), target)
    raise SessionError(f"no reachable bowl/target layout found in {tries} tries")


def plan_phases(home: pin.SE3, bowl: pin.SE3, target: pin.SE3, duration: float) -> list[Phase]:
    if duration < 0.5 * NOMINAL_DURATION:
        raise SessionError(f"duration must be at least {0.5 * NOMINAL_DURATION:.1f} s, got {duration}")
    scale = min(1.0, duration / NOMINAL_DURATION)
    bowl_yaw = pin.rpy.matrixToRpy(bowl.rotation)[2]
    target_yaw = pin.rpy.matrixToRpy(target.rotation)[2]
    above_bowl = _grasp_pose(bowl.translation, bowl_yaw, APPROACH_HEIGHT)
    at_bowl = _grasp_pose(bowl.translation, bowl_yaw)
    above_target = _grasp_pose(target.translation, target_yaw, APPROACH_HEIGHT)
    at_target = _grasp_pose(target.translation, target_yaw)
    poses = {
        "home": (home, home), "approach": (home, above_bowl), "descend": (above_bowl, at_bowl),
        "grasp": (at_bowl, at_bowl), "lift": (at_bowl, above_bowl), "transfer": (above_bowl, above_target),
        "lower": (above_target, at_target), "release": (at_target, at_target), "retreat": (at_target, above_target),
    }
    phases, t, gripper = [], 0.0, 100.0
    for name, nominal, kind in PHASES:
        after = GRIPPER_CLOSED_ON_BOWL if kind == "close" else 100.0 if kind == "open" else gripper
        phases.append(Phase(name, t, t + nominal * scale, kind, *poses[name], gripper, after))
        t, gripper = t + nominal * scale, after
    phases.append(Phase("hold", t, math.inf, "hold", poses["retreat"][1], poses["retreat"][1], gripper, gripper))
    return phases


def _command(phases: Sequence[Phase], t: float) -> tuple[pin.SE3, float]:
    for phase in phases:
        if t < phase.end:
            s = min_jerk((t - phase.start) / (phase.end - phase.start)) if math.isfinite(phase.end) else 1.0
            pose = interpolate(phase.pose_from, phase.pose_to, s)
            return pose, phase.gripper_from + s * (phase.gripper_to - phase.gripper_from)
    last = phases[-1]
    return last.pose_to, last.gripper_to


def _pose_stamped(stamp_ns: int, frame_id: str, pose: pin.SE3):
    from geometry_msgs.msg import PoseStamped

    message = PoseStamped()
    message.header.stamp.sec, message.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
    message.header.frame_id = frame_id
    x, y, z = (float(v) for v in pose.translation)
    message.pose.position.x, message.pose.position.y, message.pose.position.z = x, y, z
    quaternion = pin.Quaternion(pose.rotation)
    quaternion.normalize()
    if quaternion.w < 0:  # one sign for a rotation: reproducible bytes, no flips between messages
        quaternion = pin.Quaternion(-quaternion.w, -quaternion.x, -quaternion.y, -quaternion.z)
    orientation = message.pose.orientation
    orientation.x, orientation.y, orientation.z, orientation.w = (
        float(quaternion.x), float(quaternion.y), float(quaternion.z), float(quaternion.w))
    return message


def _camera_info(stamp_ns: int):
    from sensor_msgs.msg import CameraInfo

    c = CAMERA
    message = CameraInfo()
    message.header.stamp.sec, message.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
    message.header.frame_id = c["frame_id"]
    message.width, message.height = c["width"], c["height"]
    message.distortion_model = "plumb_bob"
    message.d = [0.0] * 5
    message.k = [c["fx"], 0.0, c["cx"], 0.0, c["fy"], c["cy"], 0.0, 0.0, 1.0]
    message.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    message.p = [c["fx"], 0.0, c["cx"], 0.0, 0.0, c["fy"], c["cy"], 0.0, 0.0, 0.0, 1.0, 0.0]
    return message


def _times(rate: float, duration: float) -> np.ndarray:
    return np.arange(int(math.floor(duration * rate + 1e-9)) + 1) / rate


def generate_session(
    folder: str | Path,
    seed: int = 0,
    duration: float = 12.0,
    rate: float = 100.0,
    *,
    start_stamp: int = DEFAULT_START_NS,
    progress: bool | Callable[[int], None] = False,
) -> SessionInfo:
    """Write the session as a new bag folder; returns its :class:`SessionInfo`.

    ``rate``: joint states per second; ``start_stamp``: ns since the epoch of session time 0;
    ``progress``: True for a tqdm bar, or a callable given the number of steps done since its last call.
    """
    from ..bag import BagWriter, Qos

    if rate <= 0 or not math.isfinite(rate):
        raise SessionError(f"rate must be a positive number of Hz, got {rate}")
    layout_rng = np.random.default_rng([int(seed), 0])
    noise_rng = np.random.default_rng([int(seed), 1])

    robot = load_baxter()
    ik = ArmIk(robot.model, "left")
    bowl, target = choose_layout(ik, layout_rng)
    home = ik.forward(NEUTRAL["left"])
    phases = plan_phases(home, bowl, target, duration)
    by_name = {p.name: p for p in phases}
    grasp_time, release_time = by_name["grasp"].end, by_name["release"].start

    times = _times(rate, duration)
    topic_times = {topic: _times(r, duration) for topic, r in POSE_RATES.items()}
    total = len(times) + len(times) + sum(len(t) for t in topic_times.values())
    bar = None
    if progress is True:
        from tqdm import tqdm

        bar = tqdm(total=total, unit="step", desc="baxter-session")
        step: Callable[[int], None] | None = bar.update
    else:
        step = progress or None

    try:
        # 1. The arm: IK at every joint-state sample, warm-started from the previous one.
        q = np.array(NEUTRAL["left"], dtype=float)
        arm = np.empty((len(times), 7))
        grippers = np.empty(len(times))
        max_error = 0.0
        for i, t in enumerate(times):
            pose, gripper = _command(phases, float(t))
            result = ik.solve(pose, q, max_iterations=30, tolerance=1e-5)
            q = result.q
            arm[i], grippers[i] = q, gripper
            max_error = max(max_error, result.position_error)
            if step and i % 50 == 49:
                step(50)
        if step:
            step(len(times) % 50)

        def arm_at(t: float) -> np.ndarray:
            k = min(max(t * rate, 0.0), len(times) - 1.0)
            lo = int(math.floor(k))
            hi = min(lo + 1, len(times) - 1)
            return arm[lo] + (k - lo) * (arm[hi] - arm[lo])

        gripper_at_grasp = ik.forward(arm_at(grasp_time))
        bowl_offset = gripper_at_grasp.actInv(bowl)
        released = ik.forward(arm_at(release_time)) * bowl_offset

        def bowl_at(t: float) -> pin.SE3:
            if t < grasp_time:
                return bowl
            if t >= release_time:
                return released
            return ik.forward(arm_at(t)) * bowl_offset

        # 2. Joint states: the real names and order, velocities by finite differences.
        index = {name: i for i, name in enumerate(BAXTER_JOINT_NAMES)}
        rows = np.zeros((len(times), len(BAXTER_JOINT_NAMES)))
        rows[:, [index[n] for n in ARM_JOINTS["left"]]] = arm
        rows[:, [index[n] for n in ARM_JOINTS["right"]]] = NEUTRAL["right"]
        fingers = np.array([gripper_to_fingers(g) for g in grippers])
        rows[:, [index[n] for n in FINGER_JOINTS["left"]]] = fingers
        rows[:, [index[n] for n in FINGER_JOINTS["right"]]] = gripper_to_fingers(100.0)
        positions = rows.tolist()
        velocities = finite_difference_velocities(times.tolist(), positions)

        # 3. Every message with its log time, written in time order (ties: joint states first).
        def ns(t: float) -> int:
            return start_stamp + int(round(t * 1e9))

        def tracked_wrist(t: float, noise_p: np.ndarray, noise_r: np.ndarray) -> object:
            """The operator's wrist as the tracker reports it: the arm's pose with the tracker's noise."""
            wrist = T_OPERATOR_BASE_ROBOT_BASE * ik.forward(arm_at(t)) * T_GRIPPER_WRIST
            noisy = pin.SE3(wrist.rotation @ pin.exp3(noise_r), wrist.translation + noise_p)
            return _pose_stamped(ns(t), "operator_base", noisy)

        events: list[tuple[int, int, int, str, Callable[[], object]]] = []
        for i, t in enumerate(times):
            events.append((ns(t), 0, i, "/robot/joint_states",
                           partial(joint_state, ns(t), BAXTER_JOINT_NAMES, positions[i], velocities[i])))
        order = {topic: k + 1 for k, topic in enumerate(POSE_RATES)}
        for topic, sample_times in topic_times.items():
            for i, t in enumerate(sample_times):
                t = float(t)
                make: Callable[[], object]
                if topic == "/bowl/pose":
                    make = partial(_pose_stamped, ns(t), "base", bowl_at(t))
                elif topic == "/target/pose":
                    make = partial(_pose_stamped, ns(t), "base", target)
                elif topic == "/head_camera/camera_info":
                    make = partial(_camera_info, ns(t))
                else:
                    noise_p = noise_rng.normal(0.0, TRACKER_NOISE[0], 3)
                    noise_r = noise_rng.normal(0.0, TRACKER_NOISE[1], 3)
                    make = partial(tracked_wrist, t, noise_p, noise_r)
                events.append((ns(t), order[topic], i, topic, make))
        events.sort(key=lambda e: e[:3])

        qos = {"/target/pose": Qos(durability="transient_local", depth=1)}
        written = 0
        with BagWriter(folder, custom_data={"generator": "coco_ros.baxter.session", "seed": str(seed)}) as writer:
            for stamp, _, _, topic, make in events:
                writer.write(topic, make(), stamp, qos=qos.get(topic))
                written += 1
                if step and written % 100 == 0:
                    step(100)
            counts = writer.topic_counts()
        if step:
            step(written % 100)
    finally:
        if bar is not None:
            bar.close()

    return SessionInfo(
        folder=Path(folder), seed=int(seed), duration=float(duration), rate=float(rate), start_ns=start_stamp,
        bowl=bowl.homogeneous, target=target.homogeneous, grasp_time=grasp_time, release_time=release_time,
        phases=[(p.name, p.start, min(p.end, float(duration))) for p in phases], counts=counts,
        max_ik_error=max_error,
    )


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="baxter-session",
        description="Generate a seeded Baxter pick-and-place teleoperation session as a rosbag2 (MCAP) bag.",
    )
    parser.add_argument("bag", help="the bag folder to create (must not exist or be empty)")
    parser.add_argument("--seed", type=int, default=0, help="layout and tracker-noise seed (default 0)")
    parser.add_argument("--duration", type=float, default=12.0, help="session length in seconds (default 12)")
    parser.add_argument("--rate", type=float, default=100.0, help="joint states per second (default 100)")
    parser.add_argument("--start", type=float, default=None,
                        help="epoch seconds of session time 0 (default: a fixed epoch, for reproducibility)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    start = DEFAULT_START_NS if args.start is None else int(round(args.start * 1e9))
    try:
        info = generate_session(args.bag, args.seed, args.duration, args.rate, start_stamp=start,
                                progress=not args.quiet)
    except CocoError as error:
        print(f"baxter-session: {error}", file=sys.stderr)
        return 1
    if not args.quiet:
        counts = ", ".join(f"{topic} {count}" for topic, count in sorted(info.counts.items()))
        print(f"wrote {args.bag}: {counts}; grasp at {info.grasp_time:.2f} s, release at {info.release_time:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
