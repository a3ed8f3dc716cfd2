"""The transformation graph: paths in any graph shape, cached versioned lookups, axis and
Denavit-Hartenberg edges, callbacks, timestamped histories, declared (strict) structure, concurrent
readers and the JSON description.

Expected values are built independently of the graph (hand-made matrices and products along the
path); pytransform3d-style checks of the SE(3) helpers themselves are in test_transforms_se3.py and
URDF specifics in test_transforms_urdf.py.
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time

import numpy as np
import pytest

from coco_core.transforms import (
    AxisEdge,
    DynamicEdge,
    EdgeKind,
    ExtrapolationError,
    JointType,
    StaticEdge,
    TransformError,
    TransformGraph,
    se3,
)
from coco_core.transforms.urdf import load_urdf
from geometry import rot_x, rot_z, homogeneous

TOL = 1e-12


# --- helpers ----------------------------------------------------------------------------------------


def trans(x=0.0, y=0.0, z=0.0) -> np.ndarray:
    return homogeneous(None, (x, y, z))


def rodrigues(axis, angle) -> np.ndarray:
    x, y, z = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def textbook_dh(d, theta, r, alpha) -> np.ndarray:
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array([[ct, -st * ca, st * sa, r * ct],
                     [st, ct * ca, -ct * sa, r * st],
                     [0.0, sa, ca, d],
                     [0.0, 0.0, 0.0, 1.0]])


def random_transform(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    return homogeneous(se3.quaternion_to_matrix(q / np.linalg.norm(q)), rng.uniform(-2.0, 2.0, size=3))


def product_along(graph: TransformGraph, frames: list[str]) -> np.ndarray:
    """T_frames[0]_frames[-1] composed by hand from the edges' current values."""
    result = np.eye(4)
    for a, b in zip(frames, frames[1:]):
        edge = graph.edge(a, b)
        value = np.asarray(edge.transform())
        result = result @ (value if edge.parent == a else np.linalg.inv(value))
    return result


def assert_read_only(array: np.ndarray) -> None:
    assert not array.flags.writeable
    with pytest.raises(ValueError):
        array[0, 3] = 123.0


def wait_for(predicate, timeout: float = 2.0) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return bool(predicate())
        time.sleep(0.001)
    return True


@pytest.fixture
def chain():
    """A 10-hop chain f0 -> f1 -> ... -> f10 of random static transforms, and the transforms."""
    rng = np.random.default_rng(42)
    graph = TransformGraph()
    values = [random_transform(rng) for _ in range(10)]
    for index, value in enumerate(values):
        graph.add_static(f"f{index}", f"f{index + 1}", value)
    return graph, values


# --- paths and values -------------------------------------------------------------------------------

def test_ten_hop_chain_is_the_product(chain):
    graph, values = chain
    expected = np.eye(4)
    for value in values:
        expected = expected @ value
    np.testing.assert_allclose(graph.lookup("f0", "f10"), expected, atol=1e-12)
    assert graph.path("f0", "f10") == [f"f{i}" for i in range(11)]
    # a sub-chain
    np.testing.assert_allclose(graph.lookup("f3", "f7"), values[3] @ values[4] @ values[5] @ values[6], atol=1e-12)
    # a point in f10 expressed in f0
    point = np.array([0.3, -1.0, 2.0, 1.0])
    np.testing.assert_allclose(graph.lookup("f0", "f10") @ point, expected @ point, atol=1e-12)


def test_reverse_lookup_is_the_inverse(chain):
    graph, values = chain
    forward = graph.lookup("f0", "f10")
    backward = graph.lookup("f10", "f0")
    np.testing.assert_allclose(backward, np.linalg.inv(forward), atol=1e-12)
    np.testing.assert_allclose(backward @ forward, np.eye(4), atol=1e-12)
    np.testing.assert_allclose(graph.lookup("f5", "f4"), np.linalg.inv(values[4]), atol=1e-12)
    assert graph.path("f10", "f0") == [f"f{i}" for i in range(10, -1, -1)]


def test_lookup_of_a_frame_to_itself_is_the_identity(chain):
    graph, _ = chain
    np.testing.assert_array_equal(graph.lookup("f4", "f4"), np.eye(4))
    np.testing.assert_array_equal(graph.lookup("f4", "f4", time=12.0), np.eye(4))
    graph.add_frame("alone")
    np.testing.assert_array_equal(graph.lookup("alone", "alone"), np.eye(4))


def test_lookup_across_a_branch_walks_edges_both_ways():
    """world -> arm -> hand and world -> table -> cup: hand to cup goes up to world and down again."""
    rng = np.random.default_rng(1)
    graph = TransformGraph()
    t = {name: random_transform(rng) for name in ("arm", "hand", "table", "cup")}
    graph.add_static("world", "arm", t["arm"])
    graph.add_static("arm", "hand", t["hand"])
    graph.add_static("world", "table", t["table"])
    graph.add_static("table", "cup", t["cup"])
    world_hand = t["arm"] @ t["hand"]
    world_cup = t["table"] @ t["cup"]
    np.testing.assert_allclose(graph.lookup("hand", "cup"), np.linalg.inv(world_hand) @ world_cup, atol=1e-12)
    np.testing.assert_allclose(graph.lookup("cup", "hand"), np.linalg.inv(world_cup) @ world_hand, atol=1e-12)
    assert graph.path("hand", "cup") == ["hand", "arm", "world", "table", "cup"]
    # a frame that is the child of two edges (tree drawn upside down): both edges walked backwards
    graph.add_static("sensor", "table", trans(0, 0, 1))
    np.testing.assert_allclose(graph.lookup("sensor", "hand"),
                               trans(0, 0, 1) @ np.linalg.inv(t["table"]) @ world_hand, atol=1e-12)


def test_cycle_a_query_follows_the_fewest_hops_path_consistently():
    """a -> b -> c and a -> c do not agree (the loop does not close): the one-hop path wins, every
    time, and the value is the product along the reported path."""
    graph = TransformGraph()
    graph.add_static("a", "b", trans(1, 0, 0))
    graph.add_static("b", "c", trans(0, 1, 0))
    graph.add_static("a", "c", trans(0, 0, 5))
    for _ in range(3):
        np.testing.assert_allclose(graph.lookup("a", "c"), trans(0, 0, 5), atol=TOL)
        np.testing.assert_allclose(graph.lookup("c", "a"), trans(0, 0, -5), atol=TOL)
        assert graph.path("a", "c") == ["a", "c"]
    # b to c is also one hop (not b -> a -> c)
    np.testing.assert_allclose(graph.lookup("b", "c"), trans(0, 1, 0), atol=TOL)
    # a change on the edge off the path does not change the answer
    graph.set_static("a", "b", trans(7, 7, 7))
    np.testing.assert_allclose(graph.lookup("a", "c"), trans(0, 0, 5), atol=TOL)


def test_random_graph_with_cycles_lookup_is_the_product_along_its_path():
    rng = np.random.default_rng(7)
    graph = TransformGraph()
    frames = [f"n{i}" for i in range(12)]
    for i in range(1, 12):  # a random tree ...
        graph.add_static(frames[int(rng.integers(0, i))], frames[i], random_transform(rng))
    added = 0
    while added < 8:  # ... plus chords that close inconsistent loops
        a, b = rng.choice(12, size=2, replace=False)
        try:
            graph.edge(frames[a], frames[b])
        except TransformError:
            graph.add_static(frames[a], frames[b], random_transform(rng))
            added += 1
    for target in frames:
        for source in frames:
            path = graph.path(target, source)
            assert path[0] == target and path[-1] == source
            np.testing.assert_allclose(graph.lookup(target, source), product_along(graph, path), atol=1e-9)
            assert graph.path(target, source) == path, "the same query keeps its path"


def test_reverse_lookup_in_a_cycle_is_the_inverse():
    """In a square a-b-c and a-d-c whose loop does not close, (a, c) and (c, a) both have two 2-hop
    paths. Whichever is chosen, the reverse query must be the inverse of the forward one; otherwise
    'the pose of c in a' and 'the pose of a in c' contradict each other."""
    graph = TransformGraph()
    graph.add_static("a", "b", trans(1, 0, 0))
    graph.add_static("d", "c", trans(0, 0, 5))
    graph.add_static("a", "d", trans(0, 1, 0))
    graph.add_static("b", "c", trans(0, 2, 0))
    forward, backward = graph.lookup("a", "c"), graph.lookup("c", "a")
    assert graph.path("c", "a") == graph.path("a", "c")[::-1], "both directions walk the same path"
    np.testing.assert_allclose(backward, np.linalg.inv(forward), atol=TOL)


# --- the cache --------------------------------------------------------------------------------------

def test_cache_same_object_until_an_edge_on_the_path_changes():
    graph = TransformGraph()
    graph.add_static("a", "b", trans(1, 0, 0))
    graph.add_static("b", "c", homogeneous(rot_z(0.5), (0, 1, 0)))
    graph.add_static("c", "d", trans(0, 0, 1))
    graph.add_static("x", "y", trans(3, 3, 3))       # elsewhere: static
    graph.set_transform("x", "z", trans(1, 2, 3), stamp=1.0)  # elsewhere: dynamic
    graph.add_axis("y", "w", "elsewhere", "revolute")  # elsewhere: axis

    first = graph.lookup("a", "d")
    assert graph.lookup("a", "d") is first
    assert graph.query("a", "d").current() is first

    graph.set_static("x", "y", trans(4, 4, 4))
    graph.set_transform("x", "z", trans(5, 5, 5), stamp=2.0)
    graph.set_joint("elsewhere", 1.0)
    assert graph.lookup("a", "d") is first, "changes off the path keep the cached value"

    graph.set_static("b", "c", homogeneous(rot_z(-0.25), (0, 2, 0)))
    second = graph.lookup("a", "d")
    assert second is not first
    np.testing.assert_allclose(second, trans(1, 0, 0) @ homogeneous(rot_z(-0.25), (0, 2, 0)) @ trans(0, 0, 1),
                               atol=TOL)
    np.testing.assert_allclose(first, trans(1, 0, 0) @ homogeneous(rot_z(0.5), (0, 1, 0)) @ trans(0, 0, 1),
                               atol=TOL), "the value handed out before is not modified in place"
    assert graph.lookup("a", "d") is second
    # the reverse query has its own cache entry and is up to date too
    np.testing.assert_allclose(graph.lookup("d", "a"), np.linalg.inv(second), atol=TOL)


def test_query_object_is_cached_and_knows_its_path():
    graph = TransformGraph()
    graph.add_static("a", "b", trans(1, 0, 0))
    graph.add_static("c", "b", trans(0, 1, 0))
    query = graph.query("a", "c")
    assert graph.query("a", "c") is query
    assert query.path == ["a", "b", "c"]
    np.testing.assert_allclose(query.current(), trans(1, 0, 0) @ trans(0, -1, 0), atol=TOL)


def _read_only_cases():
    graph = TransformGraph()
    graph.add_static("a", "b", trans(1, 0, 0))
    graph.add_static("b", "c", homogeneous(rot_x(0.3), (0, 1, 0)))
    graph.add_axis("c", "d", "j", "revolute", value=0.4)
    graph.set_transform("c", "e", trans(1, 0, 0), stamp=1.0)
    graph.set_transform("c", "e", trans(3, 0, 0), stamp=3.0)
    return graph, {
        "multi-hop": lambda: graph.lookup("a", "d"),
        "one edge forward": lambda: graph.lookup("a", "b"),
        "one edge backward": lambda: graph.lookup("b", "a"),
        "axis edge forward": lambda: graph.lookup("c", "d"),
        "axis edge backward": lambda: graph.lookup("d", "c"),
        "dynamic edge": lambda: graph.lookup("c", "e"),
        "identity": lambda: graph.lookup("a", "a"),
        "timed multi-hop": lambda: graph.lookup("a", "e", time=2.0),
        "timed one edge forward, interpolated": lambda: graph.lookup("c", "e", time=2.0),
        "timed one edge forward, exact stamp": lambda: graph.lookup("c", "e", time=3.0),
        "timed one edge backward": lambda: graph.lookup("e", "c", time=2.0),
        "timed static edge backward": lambda: graph.lookup("b", "a", time=2.0),
    }


@pytest.mark.parametrize("case", list(_read_only_cases()[1]))
def test_returned_arrays_are_read_only(case):
    graph, cases = _read_only_cases()
    value = cases[case]()
    assert_read_only(value)
    # and the graph is intact
    np.testing.assert_allclose(graph.lookup("a", "b"), trans(1, 0, 0))


# --- axis and Denavit-Hartenberg edges -----------------------------------------------------------------

def test_revolute_edge_analytically():
    graph = TransformGraph()
    origin = homogeneous(rot_x(0.3), (1.0, 2.0, 3.0))
    edge = graph.add_axis("base", "link", "shoulder", "revolute", origin=origin, axis=(0, 0, 1))
    assert edge.kind is EdgeKind.AXIS and edge.joint_type is JointType.REVOLUTE
    np.testing.assert_allclose(graph.lookup("base", "link"), origin, atol=TOL)
    for q in (0.5, -1.2, math.pi):
        graph.set_joint("shoulder", q)
        expected = origin @ homogeneous(rot_z(q))
        np.testing.assert_allclose(graph.lookup("base", "link"), expected, atol=TOL)
        np.testing.assert_allclose(graph.lookup("link", "base"), np.linalg.inv(expected), atol=TOL)
        assert edge.value == q


def test_continuous_edge_normalises_its_axis_and_wraps():
    graph = TransformGraph()
    graph.add_axis("a", "b", "wheel", "continuous", axis=(2.0, 2.0, 0.0), value=0.25)
    unit = np.array([1.0, 1.0, 0.0]) / math.sqrt(2.0)
    assert graph.edge("a", "b").axis == pytest.approx(tuple(unit))
    np.testing.assert_allclose(graph.lookup("a", "b"), homogeneous(rodrigues(unit, 0.25)), atol=TOL)
    graph.set_joint("wheel", 0.25 + 4 * math.pi)  # no limits: several turns
    np.testing.assert_allclose(graph.lookup("a", "b"), homogeneous(rodrigues(unit, 0.25)), atol=1e-12)
    graph.set_joint("wheel", -2.0)
    np.testing.assert_allclose(graph.lookup("a", "b") @ np.r_[unit, 1.0], np.r_[unit, 1.0], atol=1e-12)


def test_prismatic_edge_moves_along_its_axis_in_the_child_frame():
    graph = TransformGraph()
    origin = homogeneous(rot_z(math.pi / 2), (1.0, 0.0, 0.0))
    graph.add_axis("rail", "carriage", "slide", "prismatic", origin=origin, axis=(0.0, 3.0, 4.0))
    for q in (0.0, 2.0, -0.5):
        graph.set_joint("slide", q)
        # the axis (0, 0.6, 0.8) is expressed after the origin's rotation: its y turns into -x
        expected = origin @ trans(0.0, 0.6 * q, 0.8 * q)
        np.testing.assert_allclose(graph.lookup("rail", "carriage"), expected, atol=TOL)
        np.testing.assert_allclose(graph.lookup("rail", "carriage")[:3, 3], [1.0 - 0.6 * q, 0.0, 0.8 * q],
                                   atol=TOL)


def test_axis_edge_checks_its_arguments():
    with pytest.raises(ValueError, match="axis"):
        AxisEdge("a", "b", "j", "revolute", axis=(0, 0, 0))
    with pytest.raises(ValueError):
        AxisEdge("a", "b", "j", "ball")
    with pytest.raises(ValueError, match="orthonormal"):
        AxisEdge("a", "b", "j", "revolute", origin=np.diag([2.0, 1.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="two different frames"):
        AxisEdge("a", "a", "j", "revolute")


@pytest.mark.parametrize("joint_type", ["revolute", "continuous", "prismatic"])
def test_denavit_hartenberg_edge_is_the_dh_matrix_with_the_joint_value_added(joint_type):
    d, theta, r, alpha = 0.3, 0.7, 1.2, -0.9
    graph = TransformGraph()
    edge = graph.add_edge(AxisEdge.from_dh("l0", "l1", "q1", joint_type, d, theta, r, alpha))
    np.testing.assert_allclose(graph.lookup("l0", "l1"), textbook_dh(d, theta, r, alpha), atol=TOL)
    for q in (0.4, -1.1, 2.5):
        graph.set_joint("q1", q)
        if joint_type == "prismatic":
            expected = textbook_dh(d + q, theta, r, alpha)
        else:
            expected = textbook_dh(d, theta + q, r, alpha)
        np.testing.assert_allclose(graph.lookup("l0", "l1"), expected, atol=1e-12)
        np.testing.assert_allclose(graph.lookup("l1", "l0"), np.linalg.inv(expected), atol=1e-12)
        assert edge.value == q


def test_planar_two_link_arm_from_dh_parameters():
    """Forward kinematics of a planar 2R arm: x = l1 cos q1 + l2 cos(q1 + q2), y likewise."""
    l1, l2 = 0.7, 0.4
    graph = TransformGraph()
    graph.add_edge(AxisEdge.from_dh("base", "link1", "q1", "revolute", 0.0, 0.0, l1, 0.0))
    graph.add_edge(AxisEdge.from_dh("link1", "tip", "q2", "revolute", 0.0, 0.0, l2, 0.0))
    for q1, q2 in [(0.0, 0.0), (0.3, 0.9), (-1.0, 2.0), (math.pi / 2, -math.pi / 2)]:
        graph.set_joints({"q1": q1, "q2": q2})
        tip = graph.lookup("base", "tip")
        np.testing.assert_allclose(tip[:3, 3], [l1 * math.cos(q1) + l2 * math.cos(q1 + q2),
                                                l1 * math.sin(q1) + l2 * math.sin(q1 + q2), 0.0], atol=1e-12)
        np.testing.assert_allclose(tip[:3, :3], rot_z(q1 + q2), atol=1e-12)


# --- callbacks --------------------------------------------------------------------------------------

@pytest.fixture
def watched():
    """a -> b (static) -> c (dynamic) -> d (axis 'elbow'), plus edges elsewhere, all created before any
    callback is registered."""
    graph = TransformGraph()
    graph.add_static("a", "b", trans(1, 0, 0))
    graph.set_transform("b", "c", trans(0, 1, 0), stamp=1.0)
    graph.add_axis("c", "d", "elbow", "revolute")
    graph.add_static("x", "y", trans(9, 9, 9))
    graph.set_transform("y", "z", trans(0, 0, 1), stamp=1.0)
    graph.add_axis("z", "w", "wrist", "revolute")
    return graph


def test_callbacks_fire_once_per_change_with_the_new_value(watched):
    graph = watched
    calls: list[np.ndarray] = []
    graph.query("a", "d").on_change(calls.append)
    assert calls == []

    graph.set_transform("b", "c", trans(0, 2, 0), stamp=2.0)
    assert len(calls) == 1
    np.testing.assert_allclose(calls[-1], trans(1, 0, 0) @ trans(0, 2, 0), atol=TOL)
    assert calls[-1] is graph.lookup("a", "d"), "the callback gets the value lookups return"

    graph.set_joint("elbow", 0.5)
    assert len(calls) == 2
    np.testing.assert_allclose(calls[-1], trans(1, 0, 0) @ trans(0, 2, 0) @ homogeneous(rot_z(0.5)), atol=TOL)

    graph.set_static("a", "b", trans(2, 0, 0))
    assert len(calls) == 3
    np.testing.assert_allclose(calls[-1], trans(2, 0, 0) @ trans(0, 2, 0) @ homogeneous(rot_z(0.5)), atol=TOL)

    # one bulk update of two edges on the path is one change
    graph.add_axis("d", "e", "finger", "prismatic", axis=(1, 0, 0))
    calls_on_e: list[np.ndarray] = []
    graph.query("a", "e").on_change(calls_on_e.append)
    graph.set_joints({"elbow": 0.0, "finger": 0.25})
    assert len(calls_on_e) == 1
    np.testing.assert_allclose(calls_on_e[0], trans(2, 0, 0) @ trans(0, 2, 0) @ trans(0.25, 0, 0), atol=TOL)


def test_callbacks_do_not_fire_for_value_changes_elsewhere(watched):
    graph = watched
    calls: list[np.ndarray] = []
    graph.query("a", "d").on_change(calls.append)
    graph.set_static("x", "y", trans(1, 1, 1))
    graph.set_transform("y", "z", trans(0, 0, 2), stamp=2.0)
    graph.set_joint("wrist", 1.0)
    graph.set_joints({"wrist": 2.0})
    assert calls == []


def test_callbacks_do_not_fire_for_new_edges_elsewhere(watched):
    """A tracker that starts publishing a new object (a new dynamic edge) must not make every output
    of the graph fire with an unchanged value."""
    graph = watched
    calls: list[np.ndarray] = []
    graph.query("a", "d").on_change(calls.append)
    graph.set_transform("world", "marker", trans(1, 2, 3), stamp=1.0)  # a new edge, not connected
    graph.add_static("z", "tool", trans(0, 0, 0.1))                    # a new edge, connected elsewhere
    graph.add_frame("lonely")
    assert calls == [], f"{len(calls)} callback(s) fired although nothing on a-b-c-d changed"


def test_unsubscribe_stops_only_that_callback(watched):
    graph = watched
    first: list[np.ndarray] = []
    second: list[np.ndarray] = []
    query = graph.query("a", "d")
    unsubscribe_first = query.on_change(first.append)
    unsubscribe_second = query.on_change(second.append)
    graph.set_joint("elbow", 0.1)
    assert (len(first), len(second)) == (1, 1)
    unsubscribe_first()
    graph.set_joint("elbow", 0.2)
    assert (len(first), len(second)) == (1, 2)
    unsubscribe_first()  # twice is harmless
    unsubscribe_second()
    graph.set_joint("elbow", 0.3)
    assert (len(first), len(second)) == (1, 2)
    np.testing.assert_allclose(graph.lookup("a", "d")[:3, :3], rot_z(0.3), atol=TOL)


def test_a_raising_callback_does_not_break_the_others(watched, caplog):
    graph = watched
    seen: list[np.ndarray] = []
    other_query: list[np.ndarray] = []

    def broken(value):
        raise RuntimeError("callback exploded")

    graph.query("a", "d").on_change(broken)
    graph.query("a", "d").on_change(seen.append)
    graph.query("b", "d").on_change(other_query.append)
    with caplog.at_level(logging.ERROR, logger="coco.transforms"):
        graph.set_joint("elbow", 0.7)  # does not raise
    assert len(seen) == 1 and len(other_query) == 1
    assert "callback exploded" in caplog.text
    np.testing.assert_allclose(graph.lookup("a", "d")[:3, :3], rot_z(0.7), atol=TOL)
    graph.set_joint("elbow", 0.8)
    assert len(seen) == 2


def test_callbacks_run_in_the_writing_thread_and_may_use_the_graph(watched):
    graph = watched
    threads: list[int] = []
    derived: list[np.ndarray] = []

    def follow(value):
        threads.append(threading.get_ident())
        derived.append(graph.lookup("a", "c"))           # a read inside a callback
        graph.set_transform("x", "mirror", value, stamp=len(threads))  # and a write

    graph.set_transform("x", "mirror", np.eye(4), stamp=0.0)  # exists before: the write is no new edge
    graph.query("a", "d").on_change(follow)
    writer = threading.Thread(target=graph.set_joint, args=("elbow", 0.9))
    writer.start()
    writer.join(5.0)
    assert not writer.is_alive()
    assert threads == [writer.ident]
    np.testing.assert_allclose(graph.lookup("x", "mirror"), graph.lookup("a", "d"), atol=TOL)


def test_callback_registered_before_a_first_sample_fires_on_it():
    graph = TransformGraph()
    graph.add_static("map", "odom", trans(1, 0, 0))
    graph.add_dynamic("odom", "robot")
    calls: list[np.ndarray] = []
    graph.query("map", "robot").on_change(calls.append)
    with pytest.raises(ExtrapolationError, match="odom->robot"):
        graph.lookup("map", "robot")
    graph.set_transform("odom", "robot", trans(0, 2, 0), stamp=1.0)
    assert len(calls) == 1
    np.testing.assert_allclose(calls[0], trans(1, 2, 0), atol=TOL)


def test_callbacks_follow_a_new_path():
    graph = TransformGraph()
    graph.add_static("a", "b", trans(1, 0, 0))
    graph.add_static("b", "c", trans(0, 1, 0))
    calls: list[np.ndarray] = []
    graph.query("a", "c").on_change(calls.append)
    graph.remove_edge("b", "c")
    assert calls == [], "no value: nothing to call back with"
    graph.add_static("a", "c", trans(0, 0, 3))
    assert len(calls) == 1
    np.testing.assert_allclose(calls[0], trans(0, 0, 3), atol=TOL)
    graph.set_static("a", "b", trans(5, 0, 0))  # no longer on the path
    assert len(calls) == 1
    graph.set_static("a", "c", trans(0, 0, 4))
    assert len(calls) == 2
    np.testing.assert_allclose(calls[1], trans(0, 0, 4), atol=TOL)


def test_setting_the_same_joint_value_again_changes_nothing():
    graph = TransformGraph()
    graph.add_axis("a", "b", "j1", "revolute")
    graph.add_axis("b", "c", "j2", "prismatic", axis=(1, 0, 0))
    calls: list[np.ndarray] = []
    graph.query("a", "c").on_change(calls.append)
    graph.set_joints({"j1": 0.3, "j2": 1.0})
    assert len(calls) == 1
    value, version = graph.lookup("a", "c"), graph.version
    edge_versions = [graph.edge("a", "b").version, graph.edge("b", "c").version]
    graph.set_joints({"j1": 0.3, "j2": 1.0})
    graph.set_joint("j1", 0.3)
    graph.set_joints({"j2": 1})  # an int equal to the float value
    assert len(calls) == 1
    assert graph.version == version
    assert [graph.edge("a", "b").version, graph.edge("b", "c").version] == edge_versions
    assert graph.lookup("a", "c") is value
    graph.set_joints({"j1": 0.3, "j2": 1.5})  # one of them changes
    assert len(calls) == 2


# --- dynamic edges and time -------------------------------------------------------------------------

def sample(x: float, angle: float) -> np.ndarray:
    return homogeneous(rot_z(angle) @ rot_x(angle / 2), (x, 2 * x, -x))


def test_interpolation_between_samples():
    graph = TransformGraph()
    a, b, c = sample(1.0, 0.2), sample(3.0, 1.4), sample(4.0, -0.5)
    graph.set_transform("world", "object", a, stamp=10.0)
    graph.set_transform("world", "object", b, stamp=12.0)
    graph.set_transform("world", "object", c, stamp=13.0)
    middle = graph.lookup("world", "object", time=11.0)
    np.testing.assert_allclose(middle, se3.interpolate(a, b, 0.5), atol=1e-12)
    np.testing.assert_allclose(middle[:3, 3], (a[:3, 3] + b[:3, 3]) / 2, atol=1e-12)  # linear translation
    quarter = graph.lookup("world", "object", time=12.25)
    np.testing.assert_allclose(quarter, se3.interpolate(b, c, 0.25), atol=1e-12)
    # the rotation is the slerp: a quarter of the way along the geodesic from b to c
    relative = b[:3, :3].T @ c[:3, :3]
    total = math.acos((np.trace(relative) - 1) / 2)
    partial = math.acos(np.clip((np.trace(b[:3, :3].T @ quarter[:3, :3]) - 1) / 2, -1, 1))
    assert partial == pytest.approx(total / 4, abs=1e-9)
    # the reverse direction at a time is the inverse
    np.testing.assert_allclose(graph.lookup("object", "world", time=11.0), np.linalg.inv(middle), atol=1e-12)
    # without a time: the newest sample
    np.testing.assert_array_equal(graph.lookup("world", "object"), c)


def test_exact_stamps_return_the_samples():
    graph = TransformGraph()
    values = {float(stamp): sample(stamp, 0.1 * stamp) for stamp in range(5)}
    for stamp, value in values.items():
        graph.set_transform("w", "o", value, stamp=stamp)
    for stamp, value in values.items():
        np.testing.assert_array_equal(graph.lookup("w", "o", time=stamp), value)


def test_out_of_order_samples_are_sorted_by_stamp():
    ordered, shuffled = TransformGraph(), TransformGraph()
    values = {stamp: sample(stamp, 0.3 * stamp) for stamp in (1.0, 2.0, 3.0, 4.0, 5.0)}
    for stamp in sorted(values):
        ordered.set_transform("w", "o", values[stamp], stamp=stamp)
    for stamp in (3.0, 1.0, 5.0, 2.0, 4.0):
        shuffled.set_transform("w", "o", values[stamp], stamp=stamp)
    for t in np.linspace(1.0, 5.0, 17):
        np.testing.assert_allclose(shuffled.lookup("w", "o", time=t), ordered.lookup("w", "o", time=t), atol=1e-12)
    np.testing.assert_array_equal(shuffled.lookup("w", "o"), values[5.0]), "current = newest stamp, not last written"
    assert shuffled.edge("w", "o").time_range == (1.0, 5.0)


def test_history_is_bounded():
    graph = TransformGraph(history=4)
    for stamp in range(10):
        graph.set_transform("w", "o", trans(stamp), stamp=float(stamp))
    edge = graph.edge("w", "o")
    assert isinstance(edge, DynamicEdge) and edge.capacity == 4
    assert edge.time_range == (6.0, 9.0)
    assert edge.describe()["samples"] == 4
    with pytest.raises(ExtrapolationError):
        graph.lookup("w", "o", time=5.5)
    np.testing.assert_allclose(graph.lookup("w", "o", time=6.5), trans(6.5), atol=TOL)
    # a late sample inside the window replaces the oldest one; one older than the window is dropped
    graph.set_transform("w", "o", trans(100), stamp=6.5)
    assert edge.time_range == (6.5, 9.0) and edge.describe()["samples"] == 4
    np.testing.assert_allclose(graph.lookup("w", "o", time=6.5), trans(100), atol=TOL)
    graph.set_transform("w", "o", trans(-1), stamp=1.0)
    assert edge.time_range == (6.5, 9.0)
    # an explicit capacity
    small = graph.add_dynamic("w", "p", capacity=2)
    for stamp in range(5):
        graph.set_transform("w", "p", trans(stamp), stamp=float(stamp))
    assert small.time_range == (3.0, 4.0)
    with pytest.raises(ValueError, match="capacity"):
        DynamicEdge("a", "b", capacity=0)


def test_a_dropped_sample_is_not_a_change():
    """A sample older than a full history is dropped: lookups keep their cached value and no
    callback reports a 'change' with the same value."""
    graph = TransformGraph(history=2)
    graph.set_transform("w", "o", trans(1), stamp=1.0)
    graph.set_transform("w", "o", trans(2), stamp=2.0)
    calls: list[np.ndarray] = []
    graph.query("w", "o").on_change(calls.append)
    before = graph.lookup("w", "o")
    graph.set_transform("w", "o", trans(0), stamp=0.5)
    assert graph.lookup("w", "o") is before
    assert calls == []


def test_a_second_sample_with_the_same_stamp_is_seen_consistently():
    """Two samples stamped alike (a corrected measurement): the current value and the value at that
    stamp must be the same sample."""
    graph = TransformGraph()
    graph.set_transform("w", "o", trans(1), stamp=5.0)
    graph.set_transform("w", "o", trans(2), stamp=5.0)
    np.testing.assert_array_equal(graph.lookup("w", "o", time=5.0), graph.lookup("w", "o"))


def test_extrapolation_error_names_the_edge_and_the_range():
    graph = TransformGraph()
    graph.add_static("map", "odom", trans(1, 0, 0))
    for stamp in (1.0, 2.0, 3.0):
        graph.set_transform("odom", "base_link", trans(stamp), stamp=stamp)
    for time_ in (0.5, 3.5):
        with pytest.raises(ExtrapolationError) as raised:
            graph.lookup("map", "base_link", time=time_)
        message = str(raised.value)
        assert "odom->base_link" in message
        assert "1.0" in message and "3.0" in message, message
        assert f"{time_}" in message
    # both directions and through a query in the other direction
    with pytest.raises(ExtrapolationError, match=r"odom->base_link.*1\.0+ \.\. 3\.0+"):
        graph.lookup("base_link", "map", time=10.0)
    assert isinstance(ExtrapolationError("x"), LookupError)


def test_dynamic_edge_without_samples():
    graph = TransformGraph()
    graph.add_dynamic("w", "o")
    with pytest.raises(ExtrapolationError, match=r"w->o .*no sample"):
        graph.lookup("w", "o")
    with pytest.raises(ExtrapolationError, match=r"w->o .*no sample"):
        graph.lookup("o", "w", time=1.0)
    graph.set_transform("w", "o", trans(1), stamp=1.0)
    np.testing.assert_allclose(graph.lookup("w", "o"), trans(1))


def test_time_lookup_over_a_path_mixing_static_axis_and_dynamic_edges():
    """map -> odom (dynamic) -> base (dynamic) -> camera (static) -> wrist (axis) and marker -> camera
    (dynamic, walked backwards)."""
    graph = TransformGraph()
    odom = {1.0: sample(0.0, 0.0), 3.0: sample(2.0, 0.6)}
    base = {0.0: homogeneous(rot_z(0.1), (0.5, 0, 0)), 2.0: homogeneous(rot_z(0.9), (1.5, 0, 0)),
            4.0: homogeneous(rot_z(1.7), (2.5, 0, 0))}
    marker = {1.5: sample(1.0, -0.4), 2.5: sample(-1.0, 0.4)}
    camera = homogeneous(rot_x(-math.pi / 2), (0.1, 0, 0.4))
    for stamp, value in odom.items():
        graph.set_transform("map", "odom", value, stamp=stamp)
    for stamp, value in base.items():
        graph.set_transform("odom", "base", value, stamp=stamp)
    for stamp, value in marker.items():
        graph.set_transform("marker", "camera", value, stamp=stamp)
    graph.add_static("base", "camera_mount", camera)
    graph.add_static("camera_mount", "camera", np.eye(4))
    graph.add_axis("camera", "wrist", "pan", "revolute", value=0.3)

    t = 2.2
    at = {
        "odom": se3.interpolate(odom[1.0], odom[3.0], (t - 1.0) / 2.0),
        "base": se3.interpolate(base[2.0], base[4.0], (t - 2.0) / 2.0),
        "marker": se3.interpolate(marker[1.5], marker[2.5], (t - 1.5) / 1.0),
    }
    map_camera = at["odom"] @ at["base"] @ camera
    np.testing.assert_allclose(graph.lookup("map", "marker", time=t), map_camera @ np.linalg.inv(at["marker"]),
                               atol=1e-12)
    np.testing.assert_allclose(graph.lookup("map", "wrist", time=t), map_camera @ homogeneous(rot_z(0.3)),
                               atol=1e-12)
    np.testing.assert_allclose(graph.lookup("marker", "map", time=t),
                               at["marker"] @ np.linalg.inv(map_camera), atol=1e-12)
    # 1.2 is inside odom's and base's history but not the marker's
    np.testing.assert_allclose(graph.lookup("map", "camera", time=1.2),
                               se3.interpolate(odom[1.0], odom[3.0], 0.1)
                               @ se3.interpolate(base[0.0], base[2.0], 0.6) @ camera, atol=1e-12)
    with pytest.raises(ExtrapolationError, match="marker->camera"):
        graph.lookup("map", "marker", time=1.2)
    # timed lookups do not disturb the cached current value
    current = graph.lookup("map", "wrist")
    graph.lookup("map", "wrist", time=t)
    assert graph.lookup("map", "wrist") is current
    np.testing.assert_allclose(current, odom[3.0] @ base[4.0] @ camera @ homogeneous(rot_z(0.3)), atol=1e-12)


def test_samples_without_a_stamp_use_the_wall_clock():
    graph = TransformGraph()
    before = time.time()
    graph.set_transform("w", "o", trans(1))
    after = time.time()
    start, end = graph.edge("w", "o").time_range
    assert before <= start == end <= after


# --- errors: unknown frames, no path --------------------------------------------------------------------

def test_unknown_frame_error_suggests_the_closest_name():
    graph = TransformGraph()
    graph.add_static("base_link", "camera_link", trans(1))
    graph.add_static("base_link", "gripper", trans(2))
    for call in (lambda: graph.lookup("base_lnik", "gripper"),
                 lambda: graph.lookup("gripper", "base_lnik"),
                 lambda: graph.lookup("base_lnik", "gripper", time=1.0),
                 lambda: graph.path("gripper", "base_lnik"),
                 lambda: graph.edge("base_lnik", "gripper")):
        with pytest.raises(TransformError) as raised:
            call()
        message = str(raised.value)
        assert "unknown frame 'base_lnik'" in message
        assert "did you mean 'base_link'" in message
        assert "camera_link" in message and "gripper" in message, "the valid names are listed"


def test_no_path_error_lists_the_reachable_frames():
    graph = TransformGraph()
    graph.add_static("a", "b", trans(1))
    graph.add_static("c", "b", trans(2))
    graph.add_static("x", "y", trans(3))
    with pytest.raises(TransformError) as raised:
        graph.lookup("a", "y")
    message = str(raised.value)
    assert "no path from a to y" in message
    assert "a, b, c" in message
    assert "x" not in message.split("reaches", 1)[1]
    with pytest.raises(TransformError, match="no path from y to a"):
        graph.lookup("y", "a", time=1.0)


# --- declared structure ------------------------------------------------------------------------------

@pytest.fixture
def strict():
    graph = TransformGraph(strict=True)
    graph.add_static("world", "table", trans(1, 0, 0))
    graph.add_dynamic("table", "cup")
    graph.add_axis("world", "arm", "shoulder", "revolute")
    return graph


def test_strict_undeclared_edge_is_an_error_naming_it_and_the_declared_ones(strict):
    frames_before = strict.frames
    with pytest.raises(TransformError) as raised:
        strict.set_transform("table", "plate", trans(0, 1, 0), stamp=1.0)
    message = str(raised.value)
    assert "table->plate" in message and "not declared" in message
    for declared in ("world->table", "table->cup", "world->arm"):
        assert declared in message
    assert strict.frames == frames_before, "nothing was created"
    with pytest.raises(TransformError):
        strict.lookup("table", "plate")


def test_strict_axis_edge_write_names_the_joint(strict):
    with pytest.raises(TransformError) as raised:
        strict.set_transform("world", "arm", trans(1), stamp=1.0)
    message = str(raised.value)
    assert "world->arm" in message and "shoulder" in message and "axis" in message
    strict.set_joint("shoulder", 0.5)  # the right way
    np.testing.assert_allclose(strict.lookup("world", "arm"), homogeneous(rot_z(0.5)), atol=TOL)


def test_strict_reverse_direction_is_an_error(strict):
    with pytest.raises(TransformError, match=r"cup->table.*declared as table->cup"):
        strict.set_transform("cup", "table", trans(1), stamp=1.0)
    with pytest.raises(ExtrapolationError):
        strict.lookup("table", "cup")  # still no sample
    strict.set_transform("table", "cup", trans(0, 0, 1), stamp=1.0)
    np.testing.assert_allclose(strict.lookup("cup", "table"), trans(0, 0, -1), atol=TOL)


def test_strict_static_edges_take_calibrations_only_through_set_static(strict):
    with pytest.raises(TransformError, match=r"world->table.*static"):
        strict.set_transform("world", "table", trans(5), stamp=1.0)
    np.testing.assert_allclose(strict.lookup("world", "table"), trans(1), atol=TOL)
    strict.set_static("table", "world", trans(-2, 0, 0))  # given in the reverse direction: inverted
    np.testing.assert_allclose(strict.lookup("world", "table"), trans(2), atol=TOL)
    with pytest.raises(TransformError, match="not a static one"):
        strict.set_static("table", "cup", trans(1))


def test_non_strict_first_write_creates_a_dynamic_edge():
    graph = TransformGraph(history=7)
    graph.set_transform("camera", "marker", trans(0, 0, 2), stamp=3.0)
    edge = graph.edge("camera", "marker")
    assert isinstance(edge, DynamicEdge) and edge.kind is EdgeKind.DYNAMIC and edge.capacity == 7
    assert set(graph.frames) == {"camera", "marker"}
    np.testing.assert_allclose(graph.lookup("marker", "camera"), trans(0, 0, -2), atol=TOL)
    # a non-strict graph still refuses the reverse direction and axis edges
    with pytest.raises(TransformError, match="declared as camera->marker"):
        graph.set_transform("marker", "camera", trans(1), stamp=4.0)
    graph.add_axis("camera", "lens", "focus", "prismatic")
    with pytest.raises(TransformError, match="focus"):
        graph.set_transform("camera", "lens", trans(1), stamp=4.0)
    # and a static edge takes a new value directly
    graph.add_static("camera", "mount", trans(1))
    graph.set_transform("camera", "mount", trans(2))
    assert isinstance(graph.edge("camera", "mount"), StaticEdge)
    np.testing.assert_allclose(graph.lookup("camera", "mount"), trans(2), atol=TOL)


def test_a_rejected_write_leaves_the_graph_unchanged():
    graph = TransformGraph()
    graph.add_static("a", "b", trans(1))
    with pytest.raises(ValueError, match="4x4"):
        graph.set_transform("b", "c", np.eye(3), stamp=1.0)
    assert sorted(graph.frames) == ["a", "b"], "a write that failed must not create frames or edges"
    with pytest.raises(TransformError):
        graph.edge("b", "c")


def test_adding_an_edge_twice_or_a_joint_twice_is_refused_and_changes_nothing():
    graph = TransformGraph()
    graph.add_static("a", "b", trans(1))
    graph.add_axis("b", "c", "j", "revolute")
    with pytest.raises(TransformError, match="already joined"):
        graph.add_static("b", "a", trans(2))
    with pytest.raises(TransformError, match="joint j already drives edge b->c"):
        graph.add_axis("x", "y", "j", "revolute")
    assert sorted(e.name for e in graph.edges) == ["a->b", "b->c"], "the refused edge must not be added"
    with pytest.raises(TransformError):
        graph.lookup("x", "y")


def test_remove_edge_invalidates_the_paths_through_it():
    graph = TransformGraph()
    graph.add_static("a", "b", trans(1, 0, 0))
    graph.add_static("b", "c", trans(0, 1, 0))
    graph.add_static("a", "d", trans(0, 0, 1))
    graph.add_static("d", "e", trans(0, 0, 2))
    graph.add_static("e", "c", trans(0, 5, 0))
    np.testing.assert_allclose(graph.lookup("a", "c"), trans(1, 1, 0), atol=TOL)
    graph.remove_edge("c", "b")  # either direction names the edge
    assert graph.path("a", "c") == ["a", "d", "e", "c"]
    np.testing.assert_allclose(graph.lookup("a", "c"), trans(0, 5, 3), atol=TOL)
    graph.remove_edge("d", "e")
    with pytest.raises(TransformError, match="no path from a to c"):
        graph.lookup("a", "c")
    assert {"a", "b", "c", "d", "e"} <= set(graph.frames), "frames stay"
    with pytest.raises(TransformError, match="no edge joins d and e"):
        graph.remove_edge("d", "e")


def test_removing_an_axis_edge_frees_its_joint_name():
    graph = TransformGraph()
    graph.add_axis("a", "b", "j", "revolute")
    graph.remove_edge("a", "b")
    with pytest.raises(TransformError, match="unknown joint 'j'"):
        graph.set_joint("j", 1.0)
    graph.add_axis("a", "c", "j", "prismatic", axis=(1, 0, 0))
    graph.set_joint("j", 2.0)
    np.testing.assert_allclose(graph.lookup("a", "c"), trans(2), atol=TOL)


# --- joints --------------------------------------------------------------------------------------------

def test_set_joints_returns_and_logs_unknown_names_once(caplog):
    graph = TransformGraph()
    graph.add_axis("a", "b", "elbow", "revolute")
    with caplog.at_level(logging.WARNING, logger="coco.transforms"):
        unknown = graph.set_joints({"elbow": 0.5, "head_nod": 0.0, "torso_t0": 1.0})
        assert sorted(unknown) == ["head_nod", "torso_t0"]
        np.testing.assert_allclose(graph.lookup("a", "b"), homogeneous(rot_z(0.5)), atol=TOL)
        warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
        assert len(warnings) == 1
        assert "head_nod" in warnings[0].getMessage() and "torso_t0" in warnings[0].getMessage()

        assert sorted(graph.set_joints({"elbow": 0.6, "head_nod": 0.0, "torso_t0": 1.0})) == ["head_nod", "torso_t0"]
        assert len([r for r in caplog.records if r.levelno == logging.WARNING]) == 1, "logged once"

        assert graph.set_joints({"head_nod": 0.0, "gripper": 0.1}) == ["head_nod", "gripper"]
        warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
        assert len(warnings) == 2
        assert "gripper" in warnings[1].getMessage() and "head_nod" not in warnings[1].getMessage()
    assert graph.set_joints({"elbow": 0.7}) == []


def test_set_joint_with_an_unknown_name_is_an_error():
    graph = TransformGraph()
    graph.add_axis("a", "b", "elbow", "revolute")
    graph.add_axis("b", "c", "wrist", "revolute")
    with pytest.raises(TransformError, match=r"unknown joint 'elbw'.*did you mean 'elbow'"):
        graph.set_joint("elbw", 1.0)
    assert sorted(graph.joint_names) == ["elbow", "wrist"]


def test_a_value_that_is_not_a_number_leaves_lookups_consistent():
    """set_joints({'j1': 1.0, 'j2': 'oops'}) fails; whatever it did to j1, lookups must agree with the
    edges' own values (no stale cached value) — and ideally nothing changed at all."""
    graph = TransformGraph()
    graph.add_axis("a", "b", "j1", "prismatic", axis=(1, 0, 0))
    graph.add_axis("b", "c", "j2", "prismatic", axis=(1, 0, 0))
    np.testing.assert_allclose(graph.lookup("a", "c"), np.eye(4))
    with pytest.raises((TypeError, ValueError)):
        graph.set_joints({"j1": 1.0, "j2": "oops"})
    np.testing.assert_allclose(graph.lookup("a", "c"), product_along(graph, ["a", "b", "c"]), atol=TOL)
    assert graph.edge("a", "b").value == 0.0, "a failed bulk update should change no joint"


# --- concurrency ---------------------------------------------------------------------------------------

def run_readers(count: int, read, writer_done: threading.Event):
    """Start ``count`` threads calling ``read()`` until the writer is done (and at least 20 times
    each); ``read`` returns an error text or None. Returns (errors, per-thread counts, threads) once
    every reader is running."""
    errors: list[str] = []
    counts = [0] * count
    start = threading.Barrier(count + 1)

    def loop(index: int) -> None:
        start.wait()
        while not writer_done.is_set() or counts[index] < 20:
            try:
                problem = read()
            except Exception as error:  # noqa: BLE001 - reported below
                problem = f"{type(error).__name__}: {error}"
            if problem:
                errors.append(problem)
                return
            counts[index] += 1

    threads = [threading.Thread(target=loop, args=(i,), daemon=True) for i in range(count)]
    for thread in threads:
        thread.start()
    start.wait()
    return errors, counts, threads


def join_all(threads, timeout=20.0) -> None:
    deadline = time.monotonic() + timeout
    for thread in threads:
        thread.join(max(0.0, deadline - time.monotonic()))
        assert not thread.is_alive(), "a thread did not finish (deadlock?)"


def test_concurrent_readers_never_see_a_half_applied_bulk_update():
    """Eight prismatic joints along x; step k sets every joint to k in one set_joints call, so the
    tip is at x = 8 k (+ the origins). A reader that saw some joints at k and others at k - 1 would
    find a value that is not 8 k for any k."""
    graph = TransformGraph()
    joints = [f"j{i}" for i in range(8)]
    frames = [f"l{i}" for i in range(9)]
    for index, joint in enumerate(joints):
        graph.add_axis(frames[index], frames[index + 1], joint, "prismatic", origin=trans(1, 0, 0), axis=(1, 0, 0))
    steps = 400
    seen_by_callback: list[float] = []
    graph.query("l0", "l8").on_change(lambda value: seen_by_callback.append(value[0, 3]))
    done = threading.Event()

    def read() -> str | None:
        tip = graph.lookup("l0", "l8")
        k = (tip[0, 3] - 8.0) / 8.0
        if k != round(k) or not 0 <= k <= steps:
            return f"torn read: x = {tip[0, 3]}"
        if not np.array_equal(tip[:3, :3], np.eye(3)) or tip[1, 3] != 0 or tip[2, 3] != 0:
            return f"wrong value {tip}"
        back = graph.lookup("l8", "l0")
        if (-back[0, 3] - 8.0) % 8.0 != 0:
            return f"torn reverse read: x = {back[0, 3]}"
        middle = graph.lookup("l2", "l6")
        if (middle[0, 3] - 4.0) % 4.0 != 0:
            return f"torn sub-path read: x = {middle[0, 3]}"
        return None

    errors, counts, threads = run_readers(4, read, done)
    for k in range(1, steps + 1):
        graph.set_joints({joint: float(k) for joint in joints})
    done.set()
    join_all(threads)
    assert errors == []
    assert all(count >= 20 for count in counts)
    np.testing.assert_allclose(graph.lookup("l0", "l8"), trans(8.0 + 8.0 * steps), atol=TOL)
    # the callback ran once per update, in order, each time with the value just written
    assert seen_by_callback == [8.0 + 8.0 * k for k in range(1, steps + 1)]


def test_concurrent_readers_of_timestamped_samples():
    """A writer appends samples T(t) = (translation (t, 0, 0), rotation Rz(0.01 t)) at t = 1, 2, ...;
    a reader asking for any time inside the history must get exactly T(time) back (linear translation
    and slerp about one axis are exact), or an extrapolation error."""
    graph = TransformGraph(history=16)
    graph.add_static("map", "odom", trans(0, 0, 1))
    done = threading.Event()
    rng_lock = threading.Lock()
    rng = np.random.default_rng(3)
    newest = [0]

    def read() -> str | None:
        with rng_lock:
            t = float(rng.uniform(0, newest[0] + 2))
        try:
            value = graph.lookup("map", "robot", time=t)
        except (ExtrapolationError, TransformError):
            return None
        expected = homogeneous(rot_z(0.01 * t), (t, 0, 1))
        if not np.allclose(value, expected, atol=1e-9):
            return f"at {t}: {value} != {expected}"
        current = graph.lookup("map", "robot")
        x = current[0, 3]
        if x != round(x) or not np.allclose(current[:3, :3], rot_z(0.01 * x), atol=1e-12):
            return f"current value is not a sample: {current}"
        return None

    graph.set_transform("odom", "robot", homogeneous(rot_z(0.0), (0, 0, 0)), stamp=0.0)
    errors, counts, threads = run_readers(4, read, done)
    for stamp in range(1, 500):
        graph.set_transform("odom", "robot", homogeneous(rot_z(0.01 * stamp), (stamp, 0, 0)), stamp=float(stamp))
        newest[0] = stamp
    done.set()
    join_all(threads)
    assert errors == []
    assert graph.edge("odom", "robot").time_range == (484.0, 499.0)


URDF_CHAIN = """<?xml version="1.0"?>
<robot name="rail">
  <link name="base"/><link name="s1"/><link name="s2"/><link name="s3"/><link name="s4"/><link name="tool"/>
  <joint name="p1" type="prismatic"><parent link="base"/><child link="s1"/><origin xyz="1 0 0"/>
    <axis xyz="1 0 0"/><limit lower="-1e9" upper="1e9" effort="1" velocity="1"/></joint>
  <joint name="p2" type="prismatic"><parent link="s1"/><child link="s2"/><origin xyz="1 0 0"/>
    <axis xyz="1 0 0"/><limit lower="-1e9" upper="1e9" effort="1" velocity="1"/></joint>
  <joint name="p3" type="prismatic"><parent link="s2"/><child link="s3"/><origin xyz="1 0 0"/>
    <axis xyz="1 0 0"/><limit lower="-1e9" upper="1e9" effort="1" velocity="1"/></joint>
  <joint name="p4" type="prismatic"><parent link="s3"/><child link="s4"/><origin xyz="1 0 0"/>
    <axis xyz="1 0 0"/><limit lower="-1e9" upper="1e9" effort="1" velocity="1"/></joint>
  <joint name="mount" type="fixed"><parent link="s4"/><child link="tool"/><origin xyz="0 0 0.5"/></joint>
</robot>
"""


def test_concurrent_readers_never_see_a_half_applied_urdf_update(tmp_path):
    """A URDF rail of four prismatic joints plus a graph axis edge beyond the tool, all set to k by one
    JointState: tip x = 4 + 5 k. Readers mix model segments and ordinary edges in one path."""
    pytest.importorskip("pinocchio")

    path = tmp_path / "rail.urdf"
    path.write_text(URDF_CHAIN)
    graph = TransformGraph()
    load_urdf(graph, path)
    graph.add_axis("tool", "finger", "p5", "prismatic", axis=(1, 0, 0))
    graph.add_static("world", "base", trans(0, 0, 2))
    done = threading.Event()
    steps = 200

    def read() -> str | None:
        tip = graph.lookup("world", "finger")
        k = (tip[0, 3] - 4.0) / 5.0
        if abs(k - round(k)) > 1e-9 or not -1e-9 <= k <= steps + 1e-9:
            return f"torn read: x = {tip[0, 3]}"
        if abs(tip[2, 3] - 2.5) > 1e-9 or not np.allclose(tip[:3, :3], np.eye(3), atol=1e-12):
            return f"wrong value {tip}"
        inner = graph.lookup("s1", "s3")  # a segment inside the model only
        if abs((inner[0, 3] - 2.0) / 2.0 - round((inner[0, 3] - 2.0) / 2.0)) > 1e-9:
            return f"torn model read: x = {inner[0, 3]}"
        return None

    errors, counts, threads = run_readers(4, read, done)
    for k in range(1, steps + 1):
        unknown = graph.set_joints({"p1": k, "p2": k, "p3": k, "p4": k, "p5": k})
        assert unknown == []
    done.set()
    join_all(threads)
    assert errors == []
    np.testing.assert_allclose(graph.lookup("world", "finger"), trans(4.0 + 5.0 * steps, 0, 2.5), atol=1e-9)


def test_lookups_inside_reading_do_not_deadlock_with_a_waiting_writer():
    """``reading()`` holds the read lock so that several lookups see one state. A writer that starts
    waiting meanwhile must not make a lookup inside the block (which takes the read lock again)
    wait for that writer, which itself waits for the block to end."""
    graph = TransformGraph()
    graph.add_static("a", "b", trans(1))
    graph.add_static("b", "c", trans(2))
    finished = threading.Event()
    results: list[np.ndarray] = []
    writer_thread: list[threading.Thread] = []

    def reader() -> None:
        with graph.reading():
            writer = threading.Thread(target=graph.set_static, args=("a", "b", trans(5)), daemon=True)
            writer_thread.append(writer)
            writer.start()
            if not wait_for(lambda: graph._lock._writers_waiting == 1):
                results.append("the writer never started waiting")
                finished.set()
                return
            results.append(graph.lookup("a", "c"))  # not cached yet
            results.append(graph.lookup("c", "a"))
        finished.set()

    thread = threading.Thread(target=reader, daemon=True)
    thread.start()
    assert finished.wait(2.0), "lookup inside graph.reading() deadlocked with a waiting writer"
    assert not isinstance(results[0], str), results[0]
    writer_thread[0].join(3.0)
    np.testing.assert_allclose(results[0], trans(3), atol=TOL)
    np.testing.assert_allclose(graph.lookup("a", "c"), trans(7), atol=TOL)


# --- description --------------------------------------------------------------------------------------

def test_to_dict_is_json_serialisable_and_complete(tmp_path):
    graph = TransformGraph()
    graph.add_frame("lonely")
    graph.add_static("world", "table", homogeneous(rot_z(0.3), (1, 2, 3)))
    graph.add_dynamic("table", "cup", capacity=5)
    graph.set_transform("world", "robot", trans(0, 1, 0), stamp=1.5)
    graph.set_transform("world", "robot", trans(0, 2, 0), stamp=2.5)
    graph.add_axis("robot", "arm", "shoulder", "revolute", origin=trans(0, 0, 1), axis=(0, 0, 2), value=0.4)
    graph.add_edge(AxisEdge.from_dh("arm", "forearm", "elbow", "prismatic", 0.1, 0.2, 0.3, 0.4))
    path = tmp_path / "rail.urdf"
    path.write_text(URDF_CHAIN)
    model = load_urdf(graph, path, prefix="r_")
    graph.set_joints({"p2": 0.5})
    models = [model.name]

    described = graph.to_dict()
    text = json.dumps(described, default=list)
    again = json.loads(text)
    assert again["version"] == graph.version
    assert set(again["frames"]) == set(graph.frames)
    assert "lonely" in again["frames"]
    assert again["models"] == models
    edges = {(e["parent"], e["child"]): e for e in again["edges"]}
    assert set(edges) == {(e.parent, e.child) for e in graph.edges}
    for (parent, child), entry in edges.items():
        assert entry["kind"] == graph.edge(parent, child).kind.value
        if entry.get("transform") is not None:
            np.testing.assert_allclose(entry["transform"], graph.lookup(parent, child), atol=1e-12)

    assert edges[("world", "table")]["kind"] == "static"
    cup = edges[("table", "cup")]
    assert cup["kind"] == "dynamic" and cup["transform"] is None and cup["samples"] == 0 and cup["capacity"] == 5
    robot = edges[("world", "robot")]
    assert robot["samples"] == 2 and robot["stamp"] == 2.5 and robot["capacity"] == graph.history
    shoulder = edges[("robot", "arm")]
    assert shoulder["kind"] == "axis" and shoulder["joint"] == "shoulder"
    assert shoulder["joint_type"] == "revolute" and shoulder["value"] == 0.4
    assert shoulder["axis"] == [0.0, 0.0, 1.0]
    np.testing.assert_allclose(shoulder["origin"], trans(0, 0, 1))
    elbow = edges[("arm", "forearm")]
    assert elbow["joint"] == "elbow" and elbow["joint_type"] == "prismatic"
    np.testing.assert_allclose(elbow["transform"], textbook_dh(0.1, 0.2, 0.3, 0.4), atol=1e-12)
    if models:
        p2 = edges[("r_s1", "r_s2")]
        assert p2["kind"] == "axis" and p2["joint"] == "p2" and p2["value"] == 0.5 and p2["model"] == models[0]
        assert edges[("r_s4", "r_tool")]["kind"] == "static"


# --- non-finite values are refused (issue 14) ----------------------------------------------------------

def test_non_finite_joint_values_stamps_and_times_are_refused():
    graph = TransformGraph()
    graph.add_axis("base", "arm", "shoulder", "revolute")
    graph.set_transform("world", "base", np.eye(4), 1.0)
    graph.set_transform("world", "base", np.eye(4), 2.0)
    for bad in (math.inf, -math.inf, math.nan):
        with pytest.raises(ValueError, match="joint shoulder: expected a finite number"):
            graph.set_joints({"shoulder": bad})
        with pytest.raises(ValueError, match="stamp must be a finite number of seconds"):
            graph.set_transform("world", "base", np.eye(4), bad)
        with pytest.raises(ValueError, match="time must be a finite number of seconds"):
            graph.lookup("world", "arm", bad)
    assert graph.edge("base", "arm").value == 0.0
    assert graph.edge("world", "base").time_range == (1.0, 2.0)  # the history kept its order and size
    np.testing.assert_array_equal(graph.lookup("world", "arm", 1.5), np.eye(4))


def test_place_static_adds_replaces_or_keeps_a_static_edge():
    graph = TransformGraph()
    moved = np.eye(4)
    moved[0, 3] = 1.0
    assert graph.place_static("base", "tool", moved) is True
    version = graph.version
    assert graph.place_static("base", "tool", moved) is False and graph.version == version
    np.testing.assert_array_equal(graph.lookup("tool", "base")[:3, 3], [-1.0, 0.0, 0.0])
    back = np.linalg.inv(moved)
    back[0, 3] = -2.0
    assert graph.place_static("tool", "base", back) is True  # given in the other direction
    np.testing.assert_allclose(graph.lookup("base", "tool")[:3, 3], [2.0, 0.0, 0.0])
    graph.set_transform("world", "base", np.eye(4), 1.0)
    with pytest.raises(TransformError, match="world->base is a dynamic edge"):
        graph.place_static("world", "base", np.eye(4))


def test_partial_products_follow_any_sequence_of_changes():
    """A lookup after a change reuses the products before and after the changed edge: over random
    sequences (one edge, several, none, the same again, edges off the path, static replacements)
    it always equals the plain product of the path."""
    rng = np.random.default_rng(5)

    def random_transform() -> np.ndarray:
        q = rng.normal(size=4)
        return se3.from_pose(rng.normal(size=3), q / np.linalg.norm(q))

    graph = TransformGraph()
    values = [random_transform() for _ in range(8)]
    dynamic = {1, 4, 6}
    for i, value in enumerate(values):
        if i in dynamic:
            graph.set_transform(f"f{i}", f"f{i + 1}", value, 0.0)
        else:
            graph.add_static(f"f{i}", f"f{i + 1}", value)
    graph.set_transform("f3", "side", random_transform(), 0.0)
    stamp = 1.0
    for _ in range(300):
        for _ in range(int(rng.integers(0, 3))):
            i = int(rng.choice([1, 4, 6, 2, 7, -1]))
            if i == -1:
                graph.set_transform("f3", "side", random_transform(), stamp)
            elif i in dynamic:
                values[i] = random_transform()
                graph.set_transform(f"f{i}", f"f{i + 1}", values[i], stamp)
            else:
                values[i] = random_transform()
                graph.set_static(f"f{i}", f"f{i + 1}", values[i])
            stamp += 1.0
        expected = np.linalg.multi_dot(values)
        np.testing.assert_allclose(graph.lookup("f0", "f8"), expected, atol=1e-9)
        np.testing.assert_allclose(graph.lookup("f8", "f0"), np.linalg.inv(expected), atol=1e-9)
