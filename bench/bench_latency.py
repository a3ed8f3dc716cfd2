"""Figure 6: the teleop app's stamp-to-output latency over DDS, CoCo ROS launcher vs a plain rclpy node.

A driver (this process) publishes joint states (sensor_msgs/JointState, the 21 names the Baxter
tools write, stamped with the wall clock at publish time) at 100 Hz, to each pipeline on topics of
its own, after a bowl pose (2 Hz until every pipeline answered, then no more) (``<prefix>/joint_states``, ``<prefix>/bowl_pose``; the launchers remap
the app's ``/robot/joint_states`` and ``/bowl/pose``). The pipelines run in the same run, each in
its own process, fed in turns (``Driver.turns``): 1.5 s of input to one, then the next, the order
reversed every round. Fed all at once, they competed for the two cores, and the order in which DDS
delivered to them weighed on the result: the same plain node, started after the launchers, was
1.10-1.16x slower at p50 than when started first. The pipelines:

- *CoCo*: the installed ROS launcher runs ``test/data/interop_teleop.xml``: ROSInterface ->
  TransformationInterface (the Baxter URDF in the transformation graph, Pinocchio) ->
  EndEffectorDistance -> ROSInterface, publishing ``gripper_pose`` and ``distance`` (topics under
  ``/coco``, ``/coco_single``, ``/coco_multi``, ``/coco_one``); four times: one activity per stage
  hosted by the launcher (its default: each activity waits on its own entities in a thread of its
  own, an :class:`coco_ros.wait_set.ActivityWaitSet`, the activities in parallel; a pipeline of
  triggered activities runs in the callback that brought its data), the same as callback groups of
  one single-threaded executor (``--executor-threads 1``) and of a multi-threaded one
  (``--executor-threads 4``, the default before the wait sets), and the whole pipeline in one
  triggered activity (``one_activity:=true``);
- *anchor*: a plain rclpy node (this script with ``--plain-node``): subscribe, Pinocchio forward
  kinematics of ``left_gripper``, distance to the bowl, publish ``/plain/gripper_pose`` and
  ``/plain/distance`` (std_msgs/Float64, as the app), spun by a SingleThreadedExecutor; and the same
  node spun by rclpy's ``EventsExecutor`` (``rclpy.experimental``, the strongest anchor of the Jazzy
  wheels), publishing under ``/plain_events``. Goal (issue 12): the default layout within p50 1.0x
  and p99 1.5x of the first.

The driver measures publish -> receive of each output in its own clock. A distance (Float64)
carries no stamp, so outputs are matched to their input by value, all outputs of all pipelines
alike: the driver sweeps ``left_s0`` through ``--postures`` distinct postures, and
every posture gives a distinct gripper position and bowl distance (checked at start). The first output per
published joint state counts (a bowl pose update repeats the last distance). After the run, the
launchers' profiles give the in-app latencies: EndEffectorDistance's (read of its triggering input ->
outputs written) and the bridge's (that read -> the distance handed to DDS).

Sensor to display (``--display``, a table and a plot of its own): the Baxter teleop replay app
(config/baxter_teleop_replay.xml, in one process, no DDS) replays the generated session in real time
with the display on, once per setting in ``DISPLAY_RUNS``. GLManager stamps every frame
with the oldest input it is the first to show and measures from that input's emission by the replay
to the frame read back; TeleopSummary reports those latencies (``display_latency_ms`` in
summary.json). Side by side, from the same run: emission -> CSV row (the data path without
rendering), the display's render time per frame (its profile), the goal (median under 20 ms) and the
paper's 89 ms (teleoperation, sensor to display).

    .venv/bin/python bench/bench_latency.py [--seconds 10] [--json PATH] [--no-plot]
    .venv/bin/python bench/bench_latency.py --display [--json PATH] [--plot PATH]
"""

from __future__ import annotations

import argparse
import json
import re
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np

import _report
from _ros import RosContext  # sets ROS_DOMAIN_ID before rclpy is imported
from _table import Table, fmt_ratio, fmt_time_ns
from coco_core.cpu import process_cpu
from coco_core.interrupt import interrupt

if str(_report.REPO / "coco_ros") not in sys.path:
    sys.path.insert(0, str(_report.REPO / "coco_ros"))

RATE_HZ = 100.0
BOWL_HZ = 2.0
BOWL = (0.06, -3.0, -0.2)
"""Bowl far to the robot's right: the distance grows monotonically as left_s0 sweeps (checked)."""
S0_RANGE = (-0.6, 0.6)
TURN_S = 1.5
"""Seconds a pipeline gets the input before the next one does (see ``Driver.turns``)."""
TELEOP_APP = _report.REPO / "test" / "data" / "interop_teleop.xml"
LAUNCHER = _report.REPO / "install" / "coco_ros" / "lib" / "coco_ros" / "launcher"
ONE_ACTIVITY = "CoCo ROS launcher, one activity"
EVENTS = "plain rclpy node, EventsExecutor"
SINGLE = "CoCo ROS launcher --executor-threads 1"
MULTI = "CoCo ROS launcher --executor-threads 4"
PIPELINES = {"plain rclpy node": "/plain", EVENTS: "/plain_events", "CoCo ROS launcher": "/coco",
             SINGLE: "/coco_single", MULTI: "/coco_multi", ONE_ACTIVITY: "/coco_one"}


def _renamed(prefix: str) -> list[str]:
    """ROS arguments giving a launcher of the app its own node name, input and output topics."""
    return ["--ros-args", "-r", f"__node:=interop_teleop{prefix.replace('/', '_')}",
            "-r", f"/robot/joint_states:={prefix}/joint_states", "-r", f"/bowl/pose:={prefix}/bowl_pose",
            "-r", f"/coco/gripper_pose:={prefix}/gripper_pose", "-r", f"/coco/distance:={prefix}/distance"]


LAUNCHED = {"CoCo ROS launcher": _renamed(PIPELINES["CoCo ROS launcher"]),
            SINGLE: ["--executor-threads", "1", *_renamed(PIPELINES[SINGLE])],
            MULTI: ["--executor-threads", "4", *_renamed(PIPELINES[MULTI])],
            ONE_ACTIVITY: ["one_activity:=true", *_renamed(PIPELINES[ONE_ACTIVITY])]}
"""One activity per stage, each in a wait set of its own (the default), the same as callback groups of
a single-threaded executor and of a multi-threaded one (the default before the wait sets: one thread
per activity and one more), and the whole pipeline in one triggered activity."""
ANCHOR = "plain rclpy node"
OUTPUTS = ("gripper_pose", "distance")
MATCH_TOLERANCE = 1e-6
"""An output matches a posture when within this (m) of its gripper position or bowl distance."""


class GripperFk:
    """Pinocchio forward kinematics of the Baxter's ``left_gripper`` in ``base``, by joint name."""

    def __init__(self) -> None:
        import pinocchio as pin
        from coco_core.transforms.resources import resolve
        from coco_ros.baxter.ik import BAXTER_URDF

        self.pin = pin
        self.model = pin.buildModelFromUrdf(str(resolve(BAXTER_URDF)))
        self.data = self.model.createData()
        self.base, self.gripper = self.model.getFrameId("base"), self.model.getFrameId("left_gripper")
        self.index = {name: self.model.joints[self.model.getJointId(name)].idx_q
                      for name in self.model.names[1:] if self.model.joints[self.model.getJointId(name)].nq == 1}

    def pose(self, names: Any, positions: Any) -> np.ndarray:
        """``T_base_left_gripper`` (4x4); names the URDF does not move are ignored."""
        q = self.pin.neutral(self.model)
        index = self.index
        for name, value in zip(names, positions):
            i = index.get(name)
            if i is not None:
                q[i] = value
        self.pin.framesForwardKinematics(self.model, self.data, q)
        return self.data.oMf[self.base].actInv(self.data.oMf[self.gripper]).homogeneous


# --- the anchor: a plain rclpy node, run as its own process -----------------------------------------

def plain_node(events: bool) -> int:
    """What a user writes by hand: subscribe, FK, distance, publish; until Ctrl-C. Spun by a
    SingleThreadedExecutor (``rclpy.spin``), or with ``events`` by rclpy's EventsExecutor
    (``rclpy.experimental``), the fastest executor of the Jazzy wheels."""
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from rclpy.executors import ExternalShutdownException
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64

    fk = GripperFk()
    rclpy.init()
    prefix = PIPELINES[EVENTS if events else ANCHOR]
    node = rclpy.create_node("plain_teleop_events" if events else "plain_teleop")
    pose_out = node.create_publisher(PoseStamped, f"{prefix}/gripper_pose", QoSProfile(depth=50))
    distance_out = node.create_publisher(Float64, f"{prefix}/distance", QoSProfile(depth=50))
    bowl: list[np.ndarray] = []

    def on_bowl(msg: PoseStamped) -> None:
        p = msg.pose.position
        bowl[:] = [np.array([p.x, p.y, p.z])]

    def on_joints(msg: JointState) -> None:
        T = fk.pose(msg.name, msg.position)
        pose = PoseStamped()
        pose.header.stamp, pose.header.frame_id = msg.header.stamp, "base"
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (float(v) for v in T[:3, 3])
        x, y, z, w = fk.pin.Quaternion(T[:3, :3]).coeffs()
        pose.pose.orientation.x, pose.pose.orientation.y, pose.pose.orientation.z, pose.pose.orientation.w = x, y, z, w
        pose_out.publish(pose)
        if bowl:
            distance_out.publish(Float64(data=float(np.linalg.norm(T[:3, 3] - bowl[0]))))

    node.create_subscription(JointState, f"{prefix}/joint_states", on_joints, QoSProfile(depth=50))
    node.create_subscription(PoseStamped, f"{prefix}/bowl_pose", on_bowl, QoSProfile(depth=10))
    try:
        if events:
            from rclpy.experimental import EventsExecutor

            rclpy.spin(node, executor=EventsExecutor())
        else:
            rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


# --- the driver ---------------------------------------------------------------------------------

@dataclass
class Postures:
    """The swept postures: joint positions, and the gripper position and bowl distance of each."""

    names: list[str]
    positions: list[list[float]]
    gripper: np.ndarray
    distance: np.ndarray

    @classmethod
    def sweep(cls, count: int) -> Postures:
        from coco_ros.baxter.ik import NEUTRAL
        from coco_ros.baxter.joints import BAXTER_JOINT_NAMES

        fk = GripperFk()
        names = list(BAXTER_JOINT_NAMES)
        arm = dict(zip(("left_s0", "left_s1", "left_e0", "left_e1", "left_w0", "left_w1", "left_w2"), NEUTRAL["left"]))
        positions, grippers = [], []
        for s0 in np.linspace(*S0_RANGE, count):
            values = {**arm, "left_s0": float(s0)}
            row = [values.get(name, 0.0) for name in names]
            positions.append(row)
            grippers.append(fk.pose(names, row)[:3, 3])
        gripper = np.array(grippers)
        distance = np.linalg.norm(gripper - np.array(BOWL), axis=1)
        spacing = min(np.min(np.linalg.norm(np.diff(gripper, axis=0), axis=1)), np.min(np.abs(np.diff(distance))))
        if spacing < 100 * MATCH_TOLERANCE:
            raise RuntimeError(f"postures too close to tell apart ({spacing:.2g} m): use fewer --postures")
        return cls(names, positions, gripper, distance)

    def match(self, values: np.ndarray, key: np.ndarray) -> int | None:
        """Index of the posture whose ``key`` (gripper rows or distances) is ``values``, or None."""
        errors = np.abs(key - values) if key.ndim == 1 else np.linalg.norm(key - values, axis=1)
        i = int(np.argmin(errors))
        return i if errors[i] < MATCH_TOLERANCE else None


@dataclass
class Track:
    """Latencies of one output topic of one pipeline."""

    pending: dict[int, float] = field(default_factory=dict)
    latencies: list[float] = field(default_factory=list)
    unmatched: int = 0


class Driver:
    """Publishes the joint states and the bowl, receives every pipeline's outputs, times them."""

    def __init__(self, context: Any, postures: Postures) -> None:
        from geometry_msgs.msg import PoseStamped
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from rclpy.qos import QoSProfile
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64

        self.postures = postures
        self.node = Node("bench_latency_driver", context=context)
        self.joints_out = {pipeline: self.node.create_publisher(JointState, f"{prefix}/joint_states", QoSProfile(depth=50))
                           for pipeline, prefix in PIPELINES.items()}
        self.bowl_out = {pipeline: self.node.create_publisher(PoseStamped, f"{prefix}/bowl_pose", QoSProfile(depth=10))
                         for pipeline, prefix in PIPELINES.items()}
        self.JointState, self.PoseStamped = JointState, PoseStamped
        self.tracks = {(pipeline, output): Track() for pipeline in PIPELINES for output in OUTPUTS}
        for pipeline, prefix in PIPELINES.items():
            self.node.create_subscription(PoseStamped, f"{prefix}/gripper_pose",
                                          self._receiver(pipeline, "gripper_pose", self._position),
                                          QoSProfile(depth=50))
            self.node.create_subscription(Float64, f"{prefix}/distance",
                                          self._receiver(pipeline, "distance", self._distance), QoSProfile(depth=50))
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.sent = 0

    def _position(self, msg: Any) -> int | None:
        p = msg.pose.position
        return self.postures.match(np.array([p.x, p.y, p.z]), self.postures.gripper)

    def _distance(self, msg: Any) -> int | None:
        return self.postures.match(np.array(msg.data), self.postures.distance)

    def _receiver(self, pipeline: str, output: str, match: Callable[[Any], int | None]) -> Callable[[Any], None]:
        track = self.tracks[(pipeline, output)]

        def receive(msg: Any) -> None:
            now = time.perf_counter()
            index = match(msg)
            if index is None:
                track.unmatched += 1
                return
            sent = track.pending.pop(index, None)
            if sent is not None:  # later outputs of the same joint state (a bowl update) do not count
                track.latencies.append(now - sent)

        return receive

    def _publish_joints(self, pipelines: Iterable[str]) -> None:
        index = self.sent % len(self.postures.positions)
        msg = self.JointState(name=self.postures.names, position=self.postures.positions[index])
        msg.header.stamp = self.node.get_clock().now().to_msg()  # wall clock at publish time
        for pipeline in pipelines:
            now = time.perf_counter()
            for output in OUTPUTS:
                self.tracks[(pipeline, output)].pending[index] = now
            self.joints_out[pipeline].publish(msg)
        self.sent += 1

    def _publish_bowl(self, pipelines: Iterable[str]) -> None:
        msg = self.PoseStamped()
        msg.header.stamp, msg.header.frame_id = self.node.get_clock().now().to_msg(), "base"
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = BOWL
        msg.pose.orientation.w = 1.0
        for pipeline in pipelines:
            self.bowl_out[pipeline].publish(msg)

    def run(self, seconds: float, pipelines: Iterable[str], until: Callable[[], bool] | None = None,
            bowl: bool = True) -> None:
        """Publish to ``pipelines`` at RATE_HZ (and with ``bowl`` the bowl at BOWL_HZ) on absolute
        deadlines, receiving in between."""
        pipelines = list(pipelines)
        start = time.perf_counter()
        period, bowl_every = 1.0 / RATE_HZ, round(RATE_HZ / BOWL_HZ)
        tick = 0
        while time.perf_counter() - start < seconds and not (until and until()):
            if bowl and tick % bowl_every == 0:
                self._publish_bowl(pipelines)
            self._publish_joints(pipelines)
            tick += 1
            deadline = start + tick * period
            while (remaining := deadline - time.perf_counter()) > 0:
                self.executor.spin_once(timeout_sec=remaining)

    def turns(self, seconds: float, pipelines: list[str], turn: float = TURN_S) -> None:
        """``seconds`` of input for each of ``pipelines``, one at a time in turns of ``turn`` seconds,
        their order reversed every round: no pipeline competes with another for the two cores, and
        none is always first or last after a change of load. No bowl pose: the pipelines have it
        (``run``), and one at the start of a turn would time the distance from the gripper pose of
        the pipeline's previous turn (the launchers' in-app latency)."""
        rounds = max(1, round(seconds / turn))
        for number in range(rounds):
            for pipeline in (pipelines if number % 2 == 0 else pipelines[::-1]):
                self.run(seconds / rounds, [pipeline], bowl=False)
            print(f"\r  round {number + 1}/{rounds}", end="", file=sys.stderr, flush=True)
        print(file=sys.stderr)

    def reset(self) -> None:
        for track in self.tracks.values():
            track.latencies.clear()
            track.unmatched = 0

    def destroy(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()


STARTUP_LIMIT_S = 240.0
"""The longest the pipelines get to start and give a first output."""
STALLED_S, STALLED_CPU_S = 10.0, 0.1
"""A silent pipeline whose process used less than STALLED_CPU_S of CPU in the last STALLED_S is hung
(a launcher still starting uses far more: imports, the URDF, DDS discovery)."""
EVENTS_WAIT_S = 30.0
"""How long the EventsExecutor node gets, at least, once the others answered."""


class Startup:
    """Waits until every pipeline gave its first output, judging a silent one by its progress, not
    by a fixed time: six processes start at once on two cores beside the EventsExecutor node, which
    spins a core while it delivers nothing, so a launcher may need well over 30 s to start (the
    last one started, the one-activity launcher, stopped the run at a fixed 30 s in 3 runs of 3 on
    a loaded machine) while a hung one uses no CPU at all."""

    def __init__(self, driver: Driver, processes: dict[str, subprocess.Popen[str]], required: list[str]) -> None:
        self.driver, self.processes, self.required = driver, processes, required
        self.began = time.perf_counter()
        self.answered_after: dict[str, float] = {}
        self.hung: list[str] = []
        self._checked = 0.0
        self._progress: dict[str, tuple[float, float]] = {}
        """Pipeline -> (its process's CPU seconds, when they last grew by STALLED_CPU_S)."""

    def answered(self, pipeline: str) -> bool:
        return bool(self.driver.tracks[(pipeline, "distance")].latencies)

    def ready(self) -> bool:
        return all(map(self.answered, self.required))

    def done(self) -> bool:
        """Whether to stop waiting: all answered (the EventsExecutor node too, or it had its time),
        a process exited, a silent one is hung, or the limit passed."""
        now = time.perf_counter()
        for pipeline in PIPELINES:
            if pipeline not in self.answered_after and self.answered(pipeline):
                self.answered_after[pipeline] = now - self.began
        if now - self._checked >= 1.0:
            self._checked = now
            self._watch(now)
        if self.ready() and (self.answered(EVENTS) or now - self.began >= EVENTS_WAIT_S):
            return True
        return (bool(self.hung) or now - self.began >= STARTUP_LIMIT_S
                or any(p.poll() is not None for p in self.processes.values()))

    def _watch(self, now: float) -> None:
        for pipeline in self.required:
            if self.answered(pipeline):
                continue
            use = process_cpu(self.processes[pipeline].pid)
            seconds = use.seconds if use is not None else 0.0
            last, since = self._progress.get(pipeline, (-1.0, now))
            if seconds - last >= STALLED_CPU_S:
                self._progress[pipeline] = (seconds, now)
            elif now - since >= STALLED_S:
                self.hung.append(pipeline)

    def failure(self) -> str:
        """Why the wait ended without every required pipeline's output."""
        silent = [name for name in self.required if not self.answered(name)]
        states = []
        for name in silent:
            use = process_cpu(self.processes[name].pid)
            cpu = f"{use.seconds:.1f} CPU s" if use is not None else "gone"
            why = (f"hung: less than {STALLED_CPU_S:g} CPU s in {STALLED_S:g} s" if name in self.hung
                   else f"exit {self.processes[name].poll()}" if self.processes[name].poll() is not None
                   else "still starting")
            states.append(f"{name} ({why}; {cpu})")
        return (f"no output after {time.perf_counter() - self.began:.0f} s from " + ", ".join(states)
                + "; answered after: " + ", ".join(f"{n} {t:.1f} s" for n, t in self.answered_after.items()))


def start(command: list[str]) -> subprocess.Popen[str]:
    """A pipeline process, its output kept for the profile it prints at the end."""
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=_report.REPO)


PROFILED = {"distance": "EndEffectorDistance", "bridge": "bridge: distance published"}
"""Components whose latency the launcher's profile reports, and the row label of each."""


def profiled_latency(launcher_output: str, component: str) -> tuple[float, float] | None:
    """``component``'s recorded latency (mean, max in s) from the launcher's last profile, if any."""
    found = re.findall(rf"^{component}\s.*?([0-9.]+) / ([0-9.]+)\s*$", launcher_output, re.M)
    return (float(found[-1][0]) / 1e3, float(found[-1][1]) / 1e3) if found else None


# --- report ---------------------------------------------------------------------------------------

def percentiles(values: list[float]) -> dict[str, float]:
    if not values:
        return {"p50": float("nan"), "p90": float("nan"), "p99": float("nan"), "max": float("nan")}
    p50, p90, p99 = np.percentile(values, [50, 90, 99])
    return {"p50": float(p50), "p90": float(p90), "p99": float(p99), "max": float(max(values))}


def table(driver: Driver, profiles: dict[tuple[str, str], tuple[float, float] | None],
          args: Any) -> tuple[Table, dict[str, Any]]:
    t = Table("Figure 6 - teleop app over DDS: joint state published -> output received (driver's clock)",
              ["pipeline", "output", "samples", "p50", "p90", "p99", "max", "p50 vs plain node", "p99 vs plain node",
               "p50 vs EventsExecutor", "p99 vs EventsExecutor", "goal p50 <= 1.0x, p99 <= 1.5x"])
    results: dict[str, Any] = {}
    for output in OUTPUTS:
        anchor = percentiles(driver.tracks[(ANCHOR, output)].latencies)
        events = percentiles(driver.tracks[(EVENTS, output)].latencies)
        for pipeline in PIPELINES:
            track = driver.tracks[(pipeline, output)]
            stats = percentiles(track.latencies)
            ratio = {k: stats[k] / anchor[k] if anchor[k] > 0 else float("nan") for k in ("p50", "p99")}
            to_events = {k: stats[k] / events[k] if events[k] > 0 else float("nan") for k in ("p50", "p99")}
            times = (fmt_time_ns(stats[k] * 1e9) for k in ("p50", "p90", "p99", "max"))
            goal = "-" if pipeline != "CoCo ROS launcher" else \
                ("PASS" if ratio["p50"] <= 1.0 and ratio["p99"] <= 1.5 else "MISS")
            t.add(pipeline, output, len(track.latencies), *times, fmt_ratio(ratio["p50"]), fmt_ratio(ratio["p99"]),
                  fmt_ratio(to_events["p50"]), fmt_ratio(to_events["p99"]), goal)
            results[f"{pipeline}: {output}"] = {**stats, "samples": len(track.latencies),
                                                "unmatched": track.unmatched, "x_anchor": ratio,
                                                "x_events_executor": to_events}
    for (name, component), profile in profiles.items():
        if profile is None:
            continue
        t.add(f"{name}: profiler (in app)", PROFILED[component], "-", f"mean {fmt_time_ns(profile[0] * 1e9)}", "-",
              "-", fmt_time_ns(profile[1] * 1e9), "-", "-", "-", "-", "-")
        results[f"{name}: profiler {component}"] = {"mean": profile[0], "max": profile[1]}
    t.notes += [f"{args.seconds:g} s measured per pipeline after {args.warmup:g} s warm-up each; joint states at "
                f"{RATE_HZ:g} Hz (the bowl pose before: {BOWL_HZ:g} Hz until every pipeline answered). All "
                "pipelines run in the same run, each fed in "
                f"turns of {TURN_S:g} s, the order reversed every round: one pipeline at a time gets input, so none "
                "waits for another's work on the two cores (fed all at once, the same plain node started after "
                "the launchers was 1.10-1.16x slower at p50 than the one started first), and machine noise hits "
                "them alike.",
                "By default the launcher gives each activity a wait set of its own on a thread of its own "
                "(ActivityWaitSet); --executor-threads N: callback groups of one executor with N threads; a pipeline "
                "of triggered activities runs in the callback that brought its data either way; 'one activity': "
                "the whole pipeline in one triggered activity (one_activity:=true). Ratios > 1: slower than the plain node by that factor, "
                "< 1: faster. The profiler rows are inside the app, mean and max: EndEffectorDistance's interval "
                "(read of its triggering pose -> outputs written) and the bridge's (that read -> the distance "
                "handed to DDS).",
                f"{args.postures} postures swept; an output matches its joint state by value (within "
                f"{MATCH_TOLERANCE:g} m); the first output per joint state counts."]
    if not driver.tracks[(EVENTS, "distance")].latencies:
        t.notes.append("plain rclpy node, EventsExecutor: no output while the pipelines started (at least "
                       f"{EVENTS_WAIT_S:g} s), so it was left out (rclpy.experimental.EventsExecutor of these Jazzy "
                       "wheels spun a core and ran no callback); its ratios are n/a")
    return t, results


def draw(driver: Driver) -> Callable[[Any], Any]:
    def figure(plt: Any) -> Any:
        fig, ax = plt.subplots(figsize=(8, 4.6))
        rows = [(f"{pipeline}: {output}", percentiles(driver.tracks[(pipeline, output)].latencies))
                for output in OUTPUTS for pipeline in PIPELINES]
        height = 0.25
        anchor = percentiles(driver.tracks[(ANCHOR, "distance")].latencies)["p99"] * 1e3
        limit = 3 * anchor if anchor > 0 else None  # a tail far beyond is written, not drawn to scale
        for k, (key, color) in enumerate((("p50", "tab:blue"), ("p90", "tab:orange"), ("p99", "tab:red"))):
            ys = [y + (k - 1) * height for y in range(len(rows))]
            values = [stats[key] * 1e3 for _, stats in rows]
            ax.barh(ys, [min(v, limit) if limit else v for v in values], height=height, color=color, label=key)
            for y, value in zip(ys, values):
                if limit and value > limit:
                    ax.text(limit, y, f" {value:.0f} ms", va="center", ha="right", fontsize=7, color="white")
        if limit:
            ax.set_xlim(0, limit)
        ax.set_yticks(range(len(rows)), [label for label, _ in rows], fontsize=8)
        ax.invert_yaxis()
        ax.set_xlabel("joint state published -> output received (ms; axis cut at 3x the plain node's p99)")
        ax.set_title("Teleop app latency over DDS: CoCo ROS launcher vs plain rclpy node")
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0))
        return fig

    return figure


# --- sensor to display ------------------------------------------------------------------------------

DISPLAY_APP = _report.REPO / "config" / "baxter_teleop_replay.xml"
COCO_LAUNCH = _report.REPO / "install" / "coco_core" / "lib" / "coco_core" / "coco-launch"
BAXTER_SESSION = _report.REPO / "install" / "coco_ros" / "lib" / "coco_ros" / "baxter-session"
SESSION = _report.REPO / "out" / "baxter_session"
DISPLAY_RUNS = {"app's view, display period 50 ms": ("50", "0.25"),
                "app's view, display period 20 ms": ("20", "0.25"),
                "Baxter at 10% of its triangles, period 20 ms": ("20", "0.1"),
                "Baxter at 5% of its triangles, period 20 ms": ("20", "0.05")}
"""(display_period, baxter_simplify) of each run: the app as it is, a period shorter than a frame takes
(it renders as fast as it can), and lighter robots (the render time is the latency's floor)."""
DISPLAY_GOAL_MS = 20.0
PAPER_DISPLAY_MS = 89.0
"""The CoCo paper's sensor-to-display latency for teleoperation."""


def display_run(period_ms: str, simplify: str, output: Path) -> dict[str, Any]:
    """One run of the teleop app with the display at ``period_ms``: its summary and render time."""
    done = subprocess.run([str(COCO_LAUNCH), str(DISPLAY_APP), f"bag:={SESSION}", f"output:={output}",
                           f"display_period:={period_ms}", f"baxter_simplify:={simplify}", "--profile", "3600",
                           "--log-level", "WARNING"],
                          cwd=_report.REPO, capture_output=True, text=True, timeout=300)
    if done.returncode != 0:
        raise RuntimeError(f"the teleop app failed (exit {done.returncode}):\n{done.stderr[-3000:]}")
    summary = json.loads((output / "summary.json").read_text())
    # The profile's component row: "[process] display display execs total_ms compute_mean_us ..." (the
    # process column is there when the view runs in a process of its own, the app's default).
    render = re.findall(r"^(?:\S+\s+)?display\s+display\s+\d+\s+[0-9.]+\s+([0-9.]+)", done.stdout + done.stderr,
                        re.M)
    summary["render_mean_ms"] = float(render[-1]) / 1e3 if render else float("nan")
    return summary


def display_table(runs: dict[str, dict[str, Any]]) -> tuple[Table, dict[str, Any]]:
    t = Table("Sensor to display - teleop replay app: replay emission -> rendered frame read back",
              ["view", "frames", "p50", "p90", "max", "render mean", "emission -> CSV row, mean",
               f"p50 vs goal {DISPLAY_GOAL_MS:g} ms", f"p50 vs paper {PAPER_DISPLAY_MS:g} ms"])
    results: dict[str, Any] = {}
    for name, summary in runs.items():
        shown, row = summary["display_latency_ms"], summary["latency_ms"]
        ms = lambda value: fmt_time_ns(value * 1e6) if value is not None else "-"  # noqa: E731
        t.add(name, shown["frames"], ms(shown["median"]), ms(shown["p90"]), ms(shown["max"]),
              ms(summary["render_mean_ms"]), ms(row["mean"]), fmt_ratio(shown["median"] / DISPLAY_GOAL_MS),
              fmt_ratio(shown["median"] / PAPER_DISPLAY_MS))
        results[name] = {"display_latency_ms": shown, "csv_row_latency_ms": row,
                                                  "render_mean_ms": summary["render_mean_ms"]}
    t.notes += ["The generated Baxter session (12 s, joint states at 100 Hz, bowl poses at 30 Hz) replayed in real "
                "time; the view (Baxter, table, bowls) at 640x480, headless EGL (llvmpipe: a "
                "CPU renderer) in its periodic activity, recorded to MP4 as in the main job.",
                "A frame's latency runs from the replay's emission of the oldest input the frame is the first to "
                "show (joint state through the graph, bowl pose, distance colour) to the frame read back; frames "
                "that show nothing new are not counted. Ratios > 1: over the goal (or the paper) by that factor."]
    return t, results


def draw_display(runs: dict[str, dict[str, Any]]) -> Callable[[Any], Any]:
    def figure(plt: Any) -> Any:
        fig, ax = plt.subplots(figsize=(7, 3))
        labels = list(runs)
        for k, (key, color) in enumerate((("median", "tab:blue"), ("p90", "tab:orange"), ("max", "tab:red"))):
            ax.barh([y + (k - 1) * 0.25 for y in range(len(runs))],
                    [summary["display_latency_ms"][key] for summary in runs.values()], height=0.25, color=color,
                    label=key)
        ax.axvline(DISPLAY_GOAL_MS, color="green", linestyle="--", label=f"goal {DISPLAY_GOAL_MS:g} ms")
        ax.axvline(PAPER_DISPLAY_MS, color="grey", linestyle=":", label=f"paper {PAPER_DISPLAY_MS:g} ms")
        ax.set_yticks(range(len(runs)), labels)
        ax.invert_yaxis()
        ax.set_xlabel("replay emission -> rendered frame read back (ms)")
        ax.set_title("Sensor-to-display latency, teleop replay app")
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0))
        return fig

    return figure


def display_main(args: Any) -> None:
    if args.plot == str(_report.IMG_DIR / "bench_latency.png"):  # the default: the DDS figure's
        args.plot = str(_report.IMG_DIR / "bench_latency_display.png")
    if not (SESSION / "metadata.yaml").is_file():
        subprocess.run([str(BAXTER_SESSION), str(SESSION)], check=True, cwd=_report.REPO)
    with tempfile.TemporaryDirectory() as folder:
        runs = {name: display_run(period, simplify, Path(folder) / f"run_{index}")
                for index, (name, (period, simplify)) in enumerate(DISPLAY_RUNS.items())}
    t, results = display_table(runs)
    _report.emit("bench_latency_display", args, [t], results)
    _report.save_plot(args, draw_display(runs))


def main() -> None:
    p = _report.parser("bench_latency", __doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=15.0, help="seconds measured (default 15)")
    p.add_argument("--warmup", type=float, default=5.0, help="seconds of outputs discarded after the first "
                   "(default 5: the launcher drains what queued while it started)")
    p.add_argument("--postures", type=int, default=600, help="postures swept (default 600: 6 s at 100 Hz)")
    p.add_argument("--plain-node", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--events", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--display", action="store_true", help="measure sensor-to-display latency instead (the teleop "
                   "replay app with its display; see the module docstring)")
    args = p.parse_args()
    if args.plain_node:
        sys.exit(plain_node(args.events))
    if args.display:
        display_main(args)
        return

    postures = Postures.sweep(args.postures)
    with RosContext() as context:
        driver = Driver(context, postures)
        script = [sys.executable, str(Path(__file__).resolve()), "--plain-node"]
        # The EventsExecutor of the Jazzy wheels may deliver nothing (seen: it spins a core, never runs
        # a callback and ignores SIGINT): fed with the others until they all answered, and left out
        # of the measurement (which it would load) if it did not. Not probed alone before the others
        # start: a participant started after it was killed received nothing from the driver (seen
        # here); nor after they started: their first output would then date from 15 s back.
        processes = {ANCHOR: start(script), EVENTS: start([*script, "--events"])}
        for name, options in LAUNCHED.items():
            processes[name] = start([sys.executable, str(LAUNCHER), str(TELEOP_APP), "--profile", "3600",
                                     "--log-level", "WARNING", *options])
        outputs: dict[str, str] = {}
        try:
            required = [pipeline for pipeline in PIPELINES if pipeline != EVENTS]
            startup = Startup(driver, processes, required)
            driver.run(STARTUP_LIMIT_S, PIPELINES, until=startup.done)
            if not startup.ready():
                raise RuntimeError(startup.failure())
            print("first output after: " + ", ".join(f"{n} {t:.1f} s" for n, t in startup.answered_after.items()),
                  file=sys.stderr)
            if startup.answered(EVENTS):
                required.insert(1, EVENTS)
            else:
                interrupt(processes.pop(EVENTS), timeout=2.0)
                print(f"{EVENTS}: no output in {time.perf_counter() - startup.began:.0f} s: left out of the run",
                      file=sys.stderr)
            driver.turns(args.warmup, required)
            driver.reset()
            driver.turns(args.seconds, required)
        finally:
            for name, process in processes.items():
                outputs[name] = interrupt(process)[1]
            driver.destroy()
    for name, out in outputs.items():
        if processes[name].returncode not in (0, 130, -signal.SIGINT):
            print(f"warning: {name} exited {processes[name].returncode}:\n{out[-3000:]}", file=sys.stderr)
    t, results = table(driver, {(name, component): profiled_latency(outputs[name], component)
                                for name in LAUNCHED for component in PROFILED}, args)
    results["first_output_s"] = startup.answered_after
    t.notes.append("start: every pipeline's process started at once; first output after "
                   + ", ".join(f"{n} {s:.1f} s" for n, s in startup.answered_after.items())
                   + f" (a silent one is waited for while its process uses CPU, up to {STARTUP_LIMIT_S:g} s)")
    _report.emit("bench_latency", args, [t], results)
    _report.save_plot(args, draw(driver))


if __name__ == "__main__":
    main()
