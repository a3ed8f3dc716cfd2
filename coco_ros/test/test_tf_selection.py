"""What a TF bridge broadcasts from the transformation graph: lookups and the moving edges under a
root on /tf (only when changed, with the graph's stamps), static edges on /tf_static (the whole set,
again when one is added), never what came from ROS; unknown frames are named with the known ones."""

from __future__ import annotations

import numpy as np
import pytest
from coco_core.transforms import se3
from coco_core.transforms.graph import TransformError, TransformGraph
from coco_core.transforms.urdf import load_urdf
from coco_ros.tf.selection import TFSelection, check_pairs, parse_pair

BAXTER_URDF = "package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"


class Clock:
    """A ROS clock stand-in the test advances by hand."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def pose(x: float, yaw: float = 0.0) -> np.ndarray:
    return se3.make(se3.axis_angle((0, 0, 1), yaw), (x, 0.5, -0.25))


@pytest.fixture
def graph() -> TransformGraph:
    """world -static-> table -dynamic-> cup; world -axis-> arm -static-> tool; a loose camera."""
    g = TransformGraph()
    g.add_static("world", "table", pose(1.0))
    g.add_dynamic("table", "cup")
    g.add_axis("world", "arm", "shoulder", "revolute", pose(0.1), (0, 0, 1))
    g.add_static("arm", "tool", pose(0.3))
    g.add_static("elsewhere", "camera", pose(2.0))
    return g


def test_pairs_are_parsed_and_checked() -> None:
    assert parse_pair(" base : left_gripper ") == ("base", "left_gripper")
    for bad in ("base", "base:", ":tool", "a:b:c", "a:a"):
        with pytest.raises(ValueError, match="frame pair"):
            parse_pair(bad)
    assert check_pairs(["a:b", "c:d"]) is None
    assert "must look like parent:child" in check_pairs(["a:b", "oops"])


def test_unknown_frames_are_named_with_the_known_ones(graph: TransformGraph) -> None:
    with pytest.raises(TransformError, match=r"unknown frame\(s\) 'wrld', 'nowhere'.*did you mean 'world'\? "
                                             r"valid: arm, camera, cup, elsewhere, table, tool, world"):
        TFSelection(graph, [("wrld", "cup"), ("world", "nowhere")]).check()
    with pytest.raises(TransformError, match="unknown frame.*'base'"):
        TFSelection(graph, root="base").check()
    TFSelection(graph, [("world", "cup")], root="world").check()


def test_a_lookup_is_sent_when_it_changes_with_its_newest_sample_stamp(graph: TransformGraph) -> None:
    clock = Clock()
    selection = TFSelection(graph, [("world", "cup")], static=False, clock=clock)
    assert selection.moving() == []  # no sample yet: nothing to send, no error
    graph.set_transform("table", "cup", pose(0.2), stamp=10.0)
    (first,) = selection.moving()
    assert (first.parent, first.child, first.stamp) == ("world", "cup", 10.0)
    np.testing.assert_allclose(first.transform, pose(1.0) @ pose(0.2), atol=1e-15)
    assert selection.moving() == []  # unchanged
    graph.set_transform("table", "cup", pose(0.2), stamp=11.0)  # same place, new measurement
    assert [s.stamp for s in selection.moving()] == [11.0]
    graph.set_transform("table", "cup", pose(0.4), stamp=12.0)
    graph.set_transform("table", "cup", pose(0.3), stamp=11.5)  # late sample: the newest still counts
    (moved,) = selection.moving()
    assert moved.stamp == 12.0
    np.testing.assert_allclose(moved.transform, pose(1.0) @ pose(0.4), atol=1e-15)
    assert selection.children == frozenset({"cup"})


def test_joint_driven_transforms_carry_the_clock_time(graph: TransformGraph) -> None:
    clock = Clock()
    graph.set_transform("table", "cup", pose(0.2), stamp=10.0)
    selection = TFSelection(graph, [("cup", "tool")], static=False, clock=clock)  # via table, world, arm
    assert [s.stamp for s in selection.moving()] == [100.0]
    clock.now = 101.0
    assert selection.moving() == []  # the clock alone changes nothing
    graph.set_joint("shoulder", 0.5)
    (moved,) = selection.moving()
    assert moved.stamp == 101.0
    expected = se3.inverse(pose(1.0) @ pose(0.2)) @ pose(0.1) @ se3.make(se3.axis_angle((0, 0, 1), 0.5)) @ pose(0.3)
    np.testing.assert_allclose(moved.transform, expected, atol=1e-12)


def test_root_sends_the_moving_edges_it_reaches_and_their_static_ones(graph: TransformGraph) -> None:
    clock = Clock()
    selection = TFSelection(graph, root="world", clock=clock)
    graph.set_transform("table", "cup", pose(0.2), stamp=10.0)
    moving = {(s.parent, s.child): s for s in selection.moving()}
    assert set(moving) == {("table", "cup"), ("world", "arm")}  # each edge in its own direction
    assert moving[("table", "cup")].stamp == 10.0 and moving[("world", "arm")].stamp == 100.0
    np.testing.assert_allclose(moving[("table", "cup")].transform, pose(0.2), atol=1e-15)
    static = selection.static()
    assert {(s.parent, s.child) for s in static} == {("world", "table"), ("arm", "tool")}  # not the camera
    assert {s.stamp for s in static} == {100.0}
    assert selection.static() is None  # sent once
    assert selection.children == frozenset({"cup", "arm", "table", "tool"})
    assert sorted(selection.broadcast[:2]) == ["table:cup", "world:arm"]  # /tf first, then /tf_static
    assert sorted(selection.broadcast[2:]) == ["arm:tool", "world:table"]


def test_the_static_set_is_sent_whole_again_when_one_is_added_or_changes(graph: TransformGraph) -> None:
    clock = Clock()
    selection = TFSelection(graph, clock=clock)  # no root: every static edge of the graph
    assert {(s.parent, s.child) for s in selection.static()} == {("world", "table"), ("arm", "tool"),
                                                                 ("elsewhere", "camera")}
    assert selection.static() is None
    graph.add_static("tool", "tip", pose(0.05))
    clock.now = 105.0
    again = selection.static()
    assert len(again) == 4 and {s.stamp for s in again} == {105.0}
    graph.set_static("world", "table", pose(1.5))  # a new calibration
    changed = {(s.parent, s.child): s for s in selection.static()}
    np.testing.assert_allclose(changed[("world", "table")].transform, pose(1.5), atol=1e-15)
    assert TFSelection(graph, static=False).static() is None


def test_edges_that_came_from_ros_are_never_sent(graph: TransformGraph) -> None:
    from_ros = {("world", "table"), ("table", "cup")}
    selection = TFSelection(graph, root="world", ingested=lambda pair: pair in from_ros, clock=Clock())
    graph.set_transform("table", "cup", pose(0.2), stamp=10.0)
    assert [(s.parent, s.child) for s in selection.moving()] == [("world", "arm")]
    assert [(s.parent, s.child) for s in selection.static()] == [("arm", "tool")]
    assert "cup" not in selection.children and "table" not in selection.children


def test_a_urdf_robot_under_a_root_moving_joints_on_tf_fixed_ones_static() -> None:
    graph = TransformGraph()
    model = load_urdf(graph, BAXTER_URDF)
    selection = TFSelection(graph, root="base", clock=Clock())
    moving = {(s.parent, s.child): s for s in selection.moving()}
    static = {(s.parent, s.child): s for s in selection.static()}
    joints = {joint.name: joint for joint in model.joints.values()}
    moving_joints = {(j.parent, j.child) for j in joints.values() if j.moving}
    assert set(moving) == moving_joints and len(moving) >= 15  # two arms (7 each) and the head pan
    assert set(static) == {(j.parent, j.child) for j in joints.values() if not j.moving}
    graph.set_joints({"left_s0": 0.3})
    (changed,) = selection.moving()
    assert (changed.parent, changed.child) == (joints["left_s0"].parent, joints["left_s0"].child)
    np.testing.assert_allclose(changed.transform, model.relative(changed.parent, changed.child), atol=1e-15)
