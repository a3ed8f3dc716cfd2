"""Figure 1: one small message through CoCo ports, per connection policy, against an rclpy topic.

A *round* is one ``OutputPort.write`` followed by one ``InputPort.read`` on two components wired with
``Application.connect``: 3 buffer policies x 3 sync policies. The anchor is rclpy in one process:
publish a sensor_msgs/JointState with 19 joints, then ``spin_once`` until the subscriber's callback
has fired. The floor is the least a latest-value hand-off can cost in Python: ``deque(maxlen=1)``
append and read, each under a ``threading.Lock``. Goals (issue 34): every port round >= 200x
cheaper than rclpy and <= 1.5x the floor, its messages still stamped (the stamp is made when read).

The port rounds and the floor run in this thread alone, so they are measured a second time on the
thread's CPU clock, which the other processes of a shared machine do not inflate; the floor goal is
judged on that ratio, the rclpy goal (whose round waits for Fast DDS's threads) on wall time.

With ``--expose`` every variant is measured a second time beside itself, its writer's port
mirrored on a ROS topic (``coco_ros.mirror``, as the ROS launcher's ``--expose all`` does) that no
one subscribes to: a mirror without a subscriber must cost a write nothing.

    PYTHONPATH=coco_core .venv/bin/python bench/bench_ports.py [--json PATH] [--no-plot] [--expose]
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass
from itertools import repeat
from typing import Any

import _report
from _ros import Loopback, RosContext  # sets ROS_DOMAIN_ID before rclpy is imported
from _table import Table, fmt_ratio, fmt_time_ns, verdict
from _timing import Loop, Samples, measure, measure_cpu

import numpy as np
from sensor_msgs.msg import JointState

from coco_core.application import Application
from coco_core.component import Component
from coco_core.policy import NEW_DATA, BufferPolicy, ConnectionPolicy, SyncPolicy
from coco_core.ports import InputPort, OutputPort

JOINTS = 19
GOAL = 200.0
"""Each port round must be at least this many times cheaper than the rclpy round."""
FLOOR_GOAL = 1.5
"""Each port round may cost at most this many times the floor's round."""
BUFFER_SIZE = 8
ANCHOR, FLOOR = "rclpy JointState", "deque(maxlen=1) + Lock"


@dataclass(frozen=True)
class JointSample:
    """The CoCo payload: the same 19-joint data as the JointState, as a small Python object."""

    names: tuple[str, ...]
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray


class Writer(Component):
    out = OutputPort(JointSample)


class Reader(Component):
    inp = InputPort(JointSample)


def joint_data() -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(7)
    names = [f"arm_joint_{i + 1}" for i in range(JOINTS)]
    return names, rng.normal(size=JOINTS), rng.normal(size=JOINTS), rng.normal(size=JOINTS)


def port_loop(out: OutputPort, inp: InputPort, payload: Any) -> Loop:
    write, read = out.write, inp.read

    def loop(n: int) -> None:
        for _ in repeat(None, n):
            write(payload)
            read()

    return loop


def floor_loop(payload: Any) -> Loop:
    box: deque[Any] = deque(maxlen=1)
    append, lock = box.append, threading.Lock()

    def loop(n: int) -> None:
        for _ in repeat(None, n):
            with lock:
                append(payload)
            with lock:
                box[-1]

    return loop


def policies() -> list[ConnectionPolicy]:
    return [ConnectionPolicy(data, sync, 1 if data is BufferPolicy.DATA else BUFFER_SIZE)
            for data in (BufferPolicy.DATA, BufferPolicy.BUFFER, BufferPolicy.CIRCULAR)
            for sync in (SyncPolicy.LOCKED, SyncPolicy.LOCK_FREE, SyncPolicy.UNSYNC)]


MIRRORED = ", mirrored"
"""The suffix of a variant whose writer's port is mirrored on a topic without a subscriber."""


def build_variants(payload: JointSample, suffix: str = "") -> tuple[Application, dict[str, Loop]]:
    """One writer/reader pair per policy, wired by an application (never started: no threads)."""
    app = Application(f"bench_ports{suffix}")
    variants: dict[str, Loop] = {} if suffix else {FLOOR: floor_loop(payload)}
    for policy in policies():
        tag = f"{policy.data.value}_{policy.sync.value}".lower()
        writer, reader = app.add(Writer(f"w_{tag}")), app.add(Reader(f"r_{tag}"))
        app.connect(writer.out, reader.inp, policy)
        writer.out.write(payload)
        status, value = reader.inp.read()
        if status is not NEW_DATA or value is not payload:
            raise AssertionError(f"{policy}: read back {status!r} {value!r}, not the payload just written")
        variants[f"{policy}{suffix}"] = port_loop(writer.out, reader.inp, payload)
    return app, variants


def mirrored_variants(payload: JointSample, context: Any) -> tuple[dict[str, Loop], Any]:
    """The variants again, each writer's port mirrored on a JointState topic that no one subscribes
    to; the mirrors (a context manager, entered) and their node, to close after the measurement."""
    from coco_core.model import AppSpec, TopicMirrorSpec
    from coco_ros.mirror import PortMirrors
    from rclpy.node import Node

    app, variants = build_variants(payload, MIRRORED)
    topics = [TopicMirrorSpec(name, "out", type="sensor_msgs/msg/JointState")
              for name, component in app.components.items() if isinstance(component, Writer)]
    node = Node("bench_ports_mirrors", context=context)
    mirrors = PortMirrors(node, app, AppSpec(name=app.name, topics=topics)).__enter__()
    return variants, (mirrors, node)


def table(samples: dict[str, Samples], cpu: dict[str, Samples]) -> tuple[Table, dict[str, Any]]:
    anchor, floor, cpu_floor = samples[ANCHOR], samples[FLOOR], cpu[FLOOR]
    t = Table("Figure 1 - one 19-joint message, write + read (per round, median of repeats)",
              ["variant", "time/round", "vs rclpy (x cheaper)", "vs floor (x dearer)", "thread CPU/round",
               "vs floor, CPU", f"goal >= {GOAL:g}x rclpy, <= {FLOOR_GOAL:g}x floor (CPU)"])
    results: dict[str, Any] = {}
    for name, s in samples.items():
        cheaper, dearer = s.ratio_to(anchor), floor.ratio_to(s)
        on_cpu = cpu.get(name)
        dearer_cpu = cpu_floor.ratio_to(on_cpu) if on_cpu is not None else float("nan")
        ok = None if name in (ANCHOR, FLOOR) else cheaper >= GOAL and dearer_cpu <= FLOOR_GOAL
        label = name if name in (ANCHOR, FLOOR) else f"CoCo {name}"
        t.add(label, fmt_time_ns(s.median), fmt_ratio(cheaper), fmt_ratio(dearer),
              "-" if on_cpu is None else fmt_time_ns(on_cpu.median), "-" if on_cpu is None else fmt_ratio(dearer_cpu),
              verdict(ok))
        results[name] = {**s.to_json(), "x_cheaper_than_rclpy": cheaper, "x_floor": dearer, "goal_met": ok,
                         "rclpy_goal_met": None if ok is None else cheaper >= GOAL,
                         "floor_goal_met": None if ok is None else dearer_cpu <= FLOOR_GOAL}
        if on_cpu is not None:
            results[name].update(cpu_per_op_ns=on_cpu.per_op_ns, cpu_median_ns=on_cpu.median, x_floor_cpu=dearer_cpu)
    t.notes += [f"BUFFER and CIRCULAR have size {BUFFER_SIZE}; ratios are medians of per-round ratios "
                "(every variant measured in each round, side by side).",
                "thread CPU: the same rounds again on this thread's CPU clock (the rclpy round, whose work "
                "is in Fast DDS's threads too, is not); the floor goal is judged on it.",
                "CoCo hands the payload over by reference; rclpy serialises, sends it through DDS "
                "and deserialises a new message."]
    return t, results


def draw(samples: dict[str, Samples]):
    def figure(plt: Any) -> Any:
        names = list(samples)
        values = [samples[n].median / 1e3 for n in names]
        colors = ["tab:red" if n == ANCHOR else "tab:gray" if n == FLOOR else "tab:blue" for n in names]
        fig, ax = plt.subplots(figsize=(8, 4.8))
        ax.barh(names, values, color=colors)
        ax.set_xscale("log")
        ax.invert_yaxis()
        ax.axvline(samples[ANCHOR].median / 1e3 / GOAL, color="tab:green", linestyle="--",
                   label=f"goal: rclpy / {GOAL:g}")
        ax.axvline(samples[FLOOR].median / 1e3 * FLOOR_GOAL, color="tab:purple", linestyle=":",
                   label=f"goal: floor x {FLOOR_GOAL:g}")
        for y, v in enumerate(values):
            ax.text(v * 1.08, y, f"{v:.3g} us", va="center", fontsize=8)
        ax.set_xlabel("time per write + read round (us, log scale)")
        ax.set_title("One 19-joint message: CoCo ports vs rclpy topic (one process)")
        ax.legend(loc="upper right")
        ax.set_xlim(0.1, max(values) * 4)
        return fig

    return figure


def main() -> None:
    parser = _report.parser("bench_ports", __doc__.splitlines()[0])
    parser.add_argument("--expose", action="store_true",
                        help="measure every variant also with its port mirrored on a topic without subscriber")
    args = parser.parse_args()
    names, position, velocity, effort = joint_data()
    payload = JointSample(tuple(names), position, velocity, effort)
    variants = build_variants(payload)[1]
    with RosContext() as context:
        mirrored = None
        if args.expose:
            extra, mirrored = mirrored_variants(payload, context)
            variants = {**variants, **extra}
        ros = Loopback(context, JointState, "bench_joint_states")
        msg = JointState(name=names, position=position.tolist(), velocity=velocity.tolist(),
                         effort=effort.tolist())
        msg.header.frame_id = "base"
        ros.wait_matched(msg)
        variants[ANCHOR] = lambda n: ros.rounds(msg, n)
        try:
            samples = measure(variants, repeats=7, target_s=0.05)
            alone = {name: loop for name, loop in variants.items() if name != ANCHOR}
            cpu = measure_cpu(alone, {name: samples[name].ops_per_repeat for name in alone}, repeats=7)
        finally:
            ros.destroy()
            if mirrored is not None:
                mirrored[0].__exit__(None, None, None)
                mirrored[1].destroy_node()
    t, results = table(samples, cpu)
    _report.emit("bench_ports", args, [t], results)
    _report.save_plot(args, draw(samples))


if __name__ == "__main__":
    main()
