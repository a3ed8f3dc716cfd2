"""Figure 4: transform lookups in CoCo's TransformGraph against pytransform3d, and a Baxter update.

4a. *Cached lookup*: ``graph.lookup(a, b)`` over a 10-hop chain of static edges with nothing changed,
   against ``TransformManager.get_transform`` (which caches the path but multiplies the chain on every
   call). Floor: a bare ``dict.get``, the least a cache hit costs. Goal: CoCo < 5 us.
4b. *Lookup after a change*: one edge in the middle of the chain gets a new value (CoCo
   ``set_transform`` on a dynamic edge, pytransform3d ``add_transform`` of the same edge), then the
   chain is looked up. Floor: the bare numpy product of the 10 matrices. Goal: CoCo at most
   pytransform3d with ``check=False`` (which does not check the matrix; CoCo does).
4c. *Baxter*: one JointState (the 17 names of a recorded Baxter ``/robot/joint_states``, which include
   ``head_nod`` and ``torso_t0``, fixed joints in the URDF, plus the model's two gripper finger joints:
   19 names) with fresh random values within the limits, then ``T_base_left_gripper``. CoCo:
   ``graph.set_joints`` + ``graph.lookup``; anchor: pytransform3d ``UrdfTransformManager``
   (``set_joint`` per known joint + ``get_transform``); floor: Pinocchio's bare ``forwardKinematics``
   + ``updateFramePlacement``. Goal: CoCo within 10x of that floor; the JointState also given as
   names + positions array (``set_joint_array``), as a TransformationInterface applies it.

Before timing, every figure checks that the libraries return the same matrices (to 1e-9).

    PYTHONPATH=coco_core .venv/bin/python bench/bench_transforms.py [--json PATH] [--no-plot]
"""

from __future__ import annotations

import ast
import logging
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import reduce
from itertools import cycle, islice, repeat
from pathlib import Path
from typing import Any, Callable

import _report
from _table import Table, fmt_ratio, fmt_time_ns, verdict
from _timing import Loop, Samples, measure

import numpy as np
import pinocchio
from pytransform3d.transform_manager import TransformManager
from pytransform3d.urdf import UrdfTransformManager

from coco_core.transforms import se3
from coco_core.transforms.graph import TransformGraph
from coco_core.transforms.resources import resolve
from coco_core.transforms.urdf import load_urdf

HOPS = 10
CHANGED = HOPS // 2 - 1
"""Index of the edge that figure 2 changes: f4 -> f5, in the middle of the chain."""
POOL = 256
"""Distinct inputs cycled through by the write loops: every iteration writes a new value."""
TOLERANCE = 1e-9
GOAL_CACHED_NS = 5_000.0
REPEATS, TARGET_S = 9, 0.05
BAXTER_URDF = "package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"
JOINT_STATE = Path("/work/shared/data/baxter/hand_calib_pos.dat")
"""A recorded /robot/joint_states message of a real Baxter (``name: [...]`` / ``position: [...]``)."""
EXTRA_JOINTS = ("l_gripper_l_finger_joint", "r_gripper_l_finger_joint")
"""Moving joints of the URDF that the recorded message lacks; added so that every joint gets a value."""
RECORDED_NAMES = ["head_nod", "head_pan", "left_e0", "left_e1", "left_s0", "left_s1", "left_w0", "left_w1",
                  "left_w2", "right_e0", "right_e1", "right_s0", "right_s1", "right_w0", "right_w1",
                  "right_w2", "torso_t0"]
"""The names of that message, used when the file is not there."""
TARGET, SOURCE = "base", "left_gripper"

A1, F1 = "pytransform3d TransformManager", "dict.get (bare cache hit)"
A2, F2 = "pytransform3d add_transform + get_transform", f"numpy product of {HOPS} matrices"
A3, F3 = "pytransform3d UrdfTransformManager", "Pinocchio FK + updateFramePlacement"
A1_FAST, A2_FAST, A3_FAST = f"{A1}(check=False)", "pytransform3d (check=False)", f"{A3}(check=False)"
"""pytransform3d with its input checks off: its fastest setting, shown next to its default."""
C1 = "CoCo lookup (cached)"
C2, C2_SET = "CoCo set_transform + lookup", "CoCo set_transform alone"
C3, C3_SET = "CoCo set_joints + lookup", "CoCo set_joints alone"
C3_ARRAY = "CoCo set_joint_array + lookup"
"""The JointState as it arrives (names + positions array), kept an array down to Pinocchio's q."""
GOAL_BAXTER_X_FLOOR = 10.0


def random_transforms(rng: np.random.Generator, count: int) -> list[np.ndarray]:
    """Rigid transforms with uniform random rotations (normalised Gaussian quaternions)."""
    out = []
    for _ in range(count):
        quaternion = rng.normal(size=4)
        out.append(se3.from_pose(rng.uniform(-0.5, 0.5, 3), quaternion / np.linalg.norm(quaternion)))
    return out


def close(a: np.ndarray, b: np.ndarray) -> float:
    """Largest absolute difference of two matrices."""
    return float(np.abs(np.asarray(a) - np.asarray(b)).max())


# --- figures 1 and 2: a chain of HOPS edges ------------------------------------------------------
def frame(i: int) -> str:
    return f"f{i}"


def build_chain(edges: list[np.ndarray], check: bool = True) -> tuple[TransformGraph, TransformManager]:
    """f0 -> f1 -> ... -> f10 in both libraries. CoCo's ``T_parent_child`` (child coordinates to the
    parent) is pytransform3d's ``add_transform(child, parent, A2B)``. The edge that figure 2 changes
    is a dynamic edge in CoCo (created by its first ``set_transform``), the others static."""
    graph, tm = TransformGraph(), TransformManager(check=check)
    for i, matrix in enumerate(edges):
        if i == CHANGED:
            graph.set_transform(frame(i), frame(i + 1), matrix)
        else:
            graph.add_static(frame(i), frame(i + 1), matrix)
        tm.add_transform(frame(i + 1), frame(i), matrix)
    return graph, tm


def chain_variants(rng: np.random.Generator) -> tuple[dict[str, Loop], dict[str, Loop], dict[str, float]]:
    edges = random_transforms(rng, HOPS)
    changes = random_transforms(rng, POOL)
    target, source = frame(0), frame(HOPS)
    a, b = frame(CHANGED), frame(CHANGED + 1)

    # Figure 1: two chains, untouched by figure 2.
    graph, tm = build_chain(edges)
    tm_fast = build_chain(edges, check=False)[1]
    expected = reduce(np.matmul, edges)
    errors = {"cached: CoCo vs product": close(graph.lookup(target, source), expected),
              "cached: pytransform3d vs product": close(tm.get_transform(source, target), expected),
              "cached: pytransform3d check=False vs product": close(tm_fast.get_transform(source, target), expected)}
    cache = {(target, source): graph.lookup(target, source)}

    def coco_cached(n: int) -> None:
        lookup = graph.lookup
        for _ in repeat(None, n):
            lookup(target, source)

    def pt3d_cached(n: int) -> None:
        get = tm.get_transform
        for _ in repeat(None, n):
            get(source, target)

    def pt3d_fast_cached(n: int) -> None:
        get = tm_fast.get_transform
        for _ in repeat(None, n):
            get(source, target)

    def dict_hit(n: int) -> None:
        get, key = cache.get, (target, source)
        for _ in repeat(None, n):
            get(key)

    # Figure 2: separate chains, whose middle edge keeps changing.
    graph2, tm2 = build_chain(edges)
    tm2_fast = build_chain(edges, check=False)[1]
    for change in changes[:3]:  # all see the same writes, then must agree
        graph2.set_transform(a, b, change)
        tm2.add_transform(b, a, change)
        tm2_fast.add_transform(b, a, change)
        coco, pt3d = graph2.lookup(target, source), tm2.get_transform(source, target)
        product = reduce(np.matmul, edges[:CHANGED] + [change] + edges[CHANGED + 1:])
        for what, error in (("CoCo vs pytransform3d", close(coco, pt3d)), ("CoCo vs product", close(coco, product)),
                            ("pytransform3d check=False vs product",
                             close(tm2_fast.get_transform(source, target), product))):
            errors[f"changed: {what}"] = max(errors.get(f"changed: {what}", 0.0), error)
    errors["cached: CoCo vs pytransform3d"] = close(graph.lookup(target, source), tm.get_transform(source, target))
    for what, error in errors.items():
        assert error < TOLERANCE, f"figures 1-2: {what} differ by {error:.3g}"

    def coco_changed(n: int) -> None:
        set_transform, lookup = graph2.set_transform, graph2.lookup
        for change in islice(cycle(changes), n):
            set_transform(a, b, change)
            lookup(target, source)

    def pt3d_changed(n: int) -> None:
        add, get = tm2.add_transform, tm2.get_transform
        for change in islice(cycle(changes), n):
            add(b, a, change)
            get(source, target)

    def pt3d_fast_changed(n: int) -> None:
        add, get = tm2_fast.add_transform, tm2_fast.get_transform
        for change in islice(cycle(changes), n):
            add(b, a, change)
            get(source, target)

    def coco_set_only(n: int) -> None:
        set_transform = graph2.set_transform
        for change in islice(cycle(changes), n):
            set_transform(a, b, change)

    factors = [list(edges) for _ in range(POOL)]
    for i, change in enumerate(changes):
        factors[i][CHANGED] = change

    def numpy_product(n: int) -> None:
        for matrices in islice(cycle(factors), n):
            reduce(np.matmul, matrices)

    figure1 = {A1: pt3d_cached, A1_FAST: pt3d_fast_cached, C1: coco_cached, F1: dict_hit}
    figure2 = {A2: pt3d_changed, A2_FAST: pt3d_fast_changed, C2: coco_changed, C2_SET: coco_set_only, F2: numpy_product}
    return figure1, figure2, errors


# --- figure 3: Baxter ------------------------------------------------------------------------------
def recorded_joint_state() -> tuple[list[str], list[float] | None]:
    """Names and positions of the recorded Baxter JointState (the names alone when it is missing)."""
    try:
        fields = dict(line.split(":", 1) for line in JOINT_STATE.read_text().splitlines() if ":" in line)
        return list(ast.literal_eval(fields["name"].strip())), list(ast.literal_eval(fields["position"].strip()))
    except (OSError, KeyError, ValueError, SyntaxError):
        return list(RECORDED_NAMES), None


def moving_joints(urdf: str) -> dict[str, tuple[float, float]]:
    """Moving joints of a URDF and their limits, read from the XML (for the anchor and the values)."""
    joints = {}
    for joint in ET.fromstring(urdf).findall("joint"):
        if joint.get("type") in ("revolute", "prismatic", "continuous"):
            limit = joint.find("limit")
            lower = float(limit.get("lower", "-3.14")) if limit is not None else -math.pi
            upper = float(limit.get("upper", "3.14")) if limit is not None else math.pi
            joints[joint.get("name", "")] = (lower, upper)
    return joints


def baxter_variants(rng: np.random.Generator) -> tuple[dict[str, Loop], dict[str, Any]]:
    path = resolve(BAXTER_URDF)
    text = path.read_text()
    graph = TransformGraph()
    model = load_urdf(graph, BAXTER_URDF)
    tm, tm_fast = UrdfTransformManager(), UrdfTransformManager(check=False)
    tm.load_urdf(text, mesh_path=None)
    tm_fast.load_urdf(text, mesh_path=None)
    limits = moving_joints(text)
    mimics = set(model.mimic_joints)
    names, recorded = recorded_joint_state()
    names = names + [name for name in EXTRA_JOINTS if name not in names]

    def joint_state(values: dict[str, float]) -> dict[str, float]:
        return {name: float(values[name]) for name in names}

    pool = [joint_state({name: rng.uniform(*limits.get(name, (-1.0, 1.0))) for name in names}) for _ in range(POOL)]
    known = {name for name in limits if name not in mimics}  # what the anchor may set_joint

    # Pinocchio's own model and data, so that the floor leaves CoCo's model alone.
    pin_model = model.model
    pin_data = pin_model.createData()
    gripper_id = pin_model.getFrameId(SOURCE, pinocchio.BODY)

    def q_of(mapping: dict[str, float]) -> np.ndarray:
        q = pinocchio.neutral(pin_model)
        for name, value in mapping.items():
            if name in known:
                q[pin_model.joints[pin_model.getJointId(name)].idx_q] = value
        for name in mimics:  # follower = multiplier * leader + offset (unused on the left arm's path)
            leader, multiplier, offset = model.mimic_joints[name]
            q[pin_model.joints[pin_model.getJointId(name)].idx_q] = multiplier * mapping[leader] + offset
        return q

    qs = [q_of(mapping) for mapping in pool]

    # Check: both libraries, for the recorded pose and a few random ones.
    checks: dict[str, Any] = {"names": names, "model_ignores": [], "poses": 0, "coco_vs_pt3d": 0.0,
                              "coco_vs_pinocchio": 0.0, "coco_vs_pt3d_check_false": 0.0}
    logging.getLogger("coco.transforms").setLevel(logging.ERROR)  # the ignored names, reported below
    poses = pool[:8]
    if recorded:
        poses = [joint_state({**dict.fromkeys(names, 0.0), **dict(zip(names, recorded))})] + poses
    for mapping in poses:
        checks["model_ignores"] = graph.set_joints(mapping)
        coco = graph.lookup(TARGET, SOURCE)
        for name, value in mapping.items():
            if name in known:
                tm.set_joint(name, value)
                tm_fast.set_joint(name, value)
        pt3d = tm.get_transform(SOURCE, TARGET)  # maps left_gripper coordinates to base: T_base_gripper
        checks["coco_vs_pt3d_check_false"] = max(checks["coco_vs_pt3d_check_false"],
                                                 close(coco, tm_fast.get_transform(SOURCE, TARGET)))
        pinocchio.forwardKinematics(pin_model, pin_data, q_of(mapping))
        pin = pinocchio.updateFramePlacement(pin_model, pin_data, gripper_id).homogeneous
        checks["coco_vs_pt3d"] = max(checks["coco_vs_pt3d"], close(coco, pt3d))
        checks["coco_vs_pinocchio"] = max(checks["coco_vs_pinocchio"], close(coco, pin))
        checks["poses"] += 1
    wrong_order = close(graph.lookup(TARGET, SOURCE), tm.get_transform(TARGET, SOURCE))
    checks["pt3d_other_order_differs_by"] = wrong_order
    print(f"Baxter check: T_{TARGET}_{SOURCE} over {checks['poses']} poses "
          f"({'recorded + ' if recorded else ''}random): CoCo vs pytransform3d get_transform"
          f"({SOURCE!r}, {TARGET!r}) max |diff| = {checks['coco_vs_pt3d']:.2g}, CoCo vs Pinocchio "
          f"{checks['coco_vs_pinocchio']:.2g} (the other argument order differs by {wrong_order:.2g}); "
          f"{len(names)} names, ignored by the model: {', '.join(checks['model_ignores'])}")
    for what in ("coco_vs_pt3d", "coco_vs_pinocchio", "coco_vs_pt3d_check_false"):
        assert checks[what] < TOLERANCE, f"figure 3: {what} differ by {checks[what]:.3g}"

    def coco(n: int) -> None:
        set_joints, lookup = graph.set_joints, graph.lookup
        for mapping in islice(cycle(pool), n):
            set_joints(mapping)
            lookup(TARGET, SOURCE)

    def coco_set_only(n: int) -> None:
        set_joints = graph.set_joints
        for mapping in islice(cycle(pool), n):
            set_joints(mapping)

    names_tuple = tuple(names)
    arrays = [np.array([mapping[name] for name in names]) for mapping in pool]
    graph.set_joint_array(names_tuple, arrays[0])
    np.testing.assert_allclose(graph.lookup(TARGET, SOURCE), (graph.set_joints(pool[0]), graph.lookup(TARGET, SOURCE))[1],
                               atol=TOLERANCE)

    def coco_array(n: int) -> None:
        set_array, lookup = graph.set_joint_array, graph.lookup
        for positions in islice(cycle(arrays), n):
            set_array(names_tuple, positions)
            lookup(TARGET, SOURCE)

    def pt3d(n: int) -> None:
        set_joint, get = tm.set_joint, tm.get_transform
        for mapping in islice(cycle(pool), n):
            for name, value in mapping.items():
                if name in known:
                    set_joint(name, value)
            get(SOURCE, TARGET)

    def pt3d_fast(n: int) -> None:
        set_joint, get = tm_fast.set_joint, tm_fast.get_transform
        for mapping in islice(cycle(pool), n):
            for name, value in mapping.items():
                if name in known:
                    set_joint(name, value)
            get(SOURCE, TARGET)

    def floor(n: int) -> None:
        fk, place = pinocchio.forwardKinematics, pinocchio.updateFramePlacement
        for q in islice(cycle(qs), n):
            fk(pin_model, pin_data, q)
            place(pin_model, pin_data, gripper_id)

    return {A3: pt3d, A3_FAST: pt3d_fast, C3: coco, C3_ARRAY: coco_array, C3_SET: coco_set_only, F3: floor}, checks


# --- tables and plot -------------------------------------------------------------------------------
@dataclass
class Goal:
    """A goal column: its header, the rows it judges, the figure it judges them on and the test of it.

    The goal cell prints the figure beside the verdict, so that the verdict is always the one the
    printed figure gives: a ratio is a median of per-round ratios (``Samples.ratio_to``), the same
    figure as the ratio columns, never a ratio of two medians (which differ on a noisy machine: a row
    once read "11.2x" beside a PASS for a <= 10x goal).
    """

    header: str
    rows: tuple[str, ...]
    figure: Callable[[Samples], float]
    met: Callable[[float], bool]
    show: Callable[[float], str] = fmt_ratio

    def cell(self, name: str, samples: Samples) -> tuple[str, bool | None]:
        """The goal cell of a row and whether the goal is met (None for a row the goal does not judge)."""
        if name not in self.rows:
            return "-", None
        value = self.figure(samples)
        ok = self.met(value)
        return f"{self.show(value)}: {verdict(ok)}", ok


def cached_goal() -> Goal:
    """4a: CoCo's cached lookup under an absolute time (the median, as printed)."""
    return Goal(f"goal < {GOAL_CACHED_NS / 1e3:g} us", (C1,), lambda s: s.median, lambda ns: ns < GOAL_CACHED_NS,
                fmt_time_ns)


def changed_goal(samples: dict[str, Samples]) -> Goal:
    """4b: CoCo's write + lookup at least as cheap as pytransform3d's without checks (paired ratio >= 1)."""
    return Goal("goal <= pytransform3d check=False (x cheaper than it)", (C2,),
                lambda s: s.ratio_to(samples[A2_FAST]), lambda ratio: ratio >= 1.0)


def baxter_goal(samples: dict[str, Samples]) -> Goal:
    """4c: CoCo's Baxter update within GOAL_BAXTER_X_FLOOR times Pinocchio's, judged on the 'vs floor' column."""
    return Goal(f"goal <= {GOAL_BAXTER_X_FLOOR:g}x Pinocchio (vs floor)", (C3, C3_ARRAY),
                lambda s: samples[F3].ratio_to(s), lambda ratio: ratio <= GOAL_BAXTER_X_FLOOR)


def table(title: str, samples: dict[str, Samples], anchor: str, floor: str, goal: Goal | None,
          notes: list[str]) -> tuple[Table, dict[str, Any]]:
    a, f = samples[anchor], samples[floor]
    columns = ["variant", "time/op", "vs pytransform3d (x cheaper)", "vs floor (x dearer)"]
    if goal:
        columns.append(goal.header)
    t = Table(title, columns, notes=notes)
    results: dict[str, Any] = {}
    for name, s in samples.items():
        cheaper, dearer = s.ratio_to(a), f.ratio_to(s)
        cell, ok = goal.cell(name, s) if goal else ("-", None)
        cells = [name, fmt_time_ns(s.median), fmt_ratio(cheaper), fmt_ratio(dearer)]
        t.add(*cells, *([cell] if goal else []))
        results[name] = {**s.to_json(), "x_cheaper_than_pytransform3d": cheaper, "x_floor": dearer, "goal_met": ok}
    return t, results


def draw(figures: list[tuple[str, dict[str, Samples], str, str, float | None]]):
    def figure(plt: Any) -> Any:
        fig, axes = plt.subplots(len(figures), 1, figsize=(8.5, 7.5), sharex=True)
        for ax, (title, samples, anchor, floor, goal_ns) in zip(axes, figures):
            names = list(samples)
            values = [samples[n].median / 1e3 for n in names]
            colors = ["tab:red" if n == anchor else "lightcoral" if n.startswith("pytransform3d")
                      else "tab:gray" if n == floor else "tab:blue" for n in names]
            ax.barh(names, values, color=colors)
            ax.set_xscale("log")
            ax.invert_yaxis()
            for y, v in enumerate(values):
                ax.text(v * 1.1, y, fmt_time_ns(v * 1e3), va="center", fontsize=8, zorder=3,
                        bbox={"facecolor": "white", "edgecolor": "none", "pad": 0.5})
            if goal_ns is not None:
                ax.axvline(goal_ns / 1e3, color="tab:green", linestyle="--", label=f"goal < {goal_ns / 1e3:.3g} us")
                ax.legend(loc="lower right", fontsize=8)
            ax.set_title(title, fontsize=10)
            ax.tick_params(axis="y", labelsize=8)
        axes[-1].set_xlabel("time per operation (us, log scale)")
        lows = [s.median / 1e3 for _, samples, *_ in figures for s in samples.values()]
        axes[-1].set_xlim(min(lows) / 2, max(lows) * 6)
        fig.suptitle("Transform lookups: CoCo TransformGraph vs pytransform3d (one process)")
        fig.tight_layout()
        return fig

    return figure


def main() -> None:
    args = _report.parser("bench_transforms", __doc__.splitlines()[0]).parse_args()
    rng = np.random.default_rng(11)
    figure1, figure2, chain_errors = chain_variants(rng)
    figure3, baxter_checks = baxter_variants(rng)
    with _report.LoadMeter() as load:
        s1 = measure(figure1, repeats=REPEATS, target_s=TARGET_S)
        s2 = measure(figure2, repeats=REPEATS, target_s=TARGET_S)
        s3 = measure(figure3, repeats=REPEATS, target_s=TARGET_S)
    others = "n/a" if load.others is None else f"{load.others:.0%}"
    same = f"values checked equal to {TOLERANCE:g} before timing"

    t1, r1 = table(f"Figure 4a - lookup over a {HOPS}-hop chain, nothing changed (per lookup, median of repeats)",
                   s1, A1, F1, cached_goal(),
                   [f"pytransform3d keeps the path but multiplies the {HOPS} matrices on every call (and, with "
                    "check=True, its default, re-checks each one); CoCo returns the value cached with the path "
                    f"until an edge on it changes; {same}.",
                    f"Ratios are medians of per-round ratios ({REPEATS} interleaved rounds), goals judged on the "
                    "figure printed in their cell; other processes "
                    f"used {others} of the {_report.machine()['cpus']} cores meanwhile."])
    t2, r2 = table(f"Figure 4b - one edge of the {HOPS}-hop chain changed, then the lookup (per write + lookup)",
                   s2, A2, F2, changed_goal(s2),
                   [f"The edge f{CHANGED}->f{CHANGED + 1} gets a new value each iteration ({POOL} random "
                    f"transforms in turn); CoCo's is a dynamic edge (stamped sample, matrix checked: 4x4, finite, "
                    "orthonormal, det +1); pytransform3d checks it too by default (check=True), not with "
                    f"check=False; {same}. CoCo keeps the products of the path before and after the changed "
                    "edge, so a change costs two matrix products, not one per hop.",
                    f"Floor: reduce(np.matmul) over the {HOPS} matrices, no write, no check."])
    t3, r3 = table(f"Figure 4c - Baxter: JointState of {len(baxter_checks['names'])} names + T_{TARGET}_{SOURCE} "
                   "(per update)", s3, A3, F3, baxter_goal(s3),
                   [f"A fresh mapping each iteration ({POOL} in turn, values uniform within the limits); "
                    f"{', '.join(baxter_checks['model_ignores'])} are fixed joints in the URDF: CoCo returns "
                    "them as ignored, the anchor skips them (set_joint would warn).",
                    f"CoCo vs pytransform3d get_transform('{SOURCE}', '{TARGET}') max |diff| "
                    f"{baxter_checks['coco_vs_pt3d']:.1g}, vs Pinocchio {baxter_checks['coco_vs_pinocchio']:.1g} "
                    f"over {baxter_checks['poses']} poses (recorded + random).",
                    f"{C3_ARRAY}: the names and positions array of the JointState, as a TransformationInterface "
                    "applies a JointSample (one gather/scatter into q, planned once per name list); "
                    f"{C3}: a name -> value mapping.",
                    "Floor: Pinocchio forwardKinematics + updateFramePlacement on a ready q vector (no names)."])
    _report.emit("bench_transforms", args, [t1, t2, t3],
                 {"cached": r1, "changed": r2, "baxter": r3, "checks": {"chain": chain_errors, "baxter": baxter_checks},
                  "others_cpu": load.others})
    _report.save_plot(args, draw([
        (f"4a. cached lookup, {HOPS}-hop chain", s1, A1, F1, GOAL_CACHED_NS),
        (f"4b. one edge changed + lookup, {HOPS}-hop chain", s2, A2, F2, None),
        (f"4c. Baxter: JointState of {len(baxter_checks['names'])} names + T_{TARGET}_{SOURCE}", s3, A3, F3,
         GOAL_BAXTER_X_FLOOR * s3[F3].median)]))


if __name__ == "__main__":
    main()
