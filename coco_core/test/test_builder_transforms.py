"""The builder installs the declared ``<transforms>`` structure into the application's graph: frames,
edges of the declared kinds and values, URDF robots attached to a frame, and strictness, all before
any component's ``init()`` runs; what the graph refuses becomes an error at the element's line."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from coco_core import Component
from coco_core.builder import build_application
from coco_core.errors import ConfigErrors
from coco_core.registry import register
from coco_core.transforms import EdgeKind, TransformError, se3
from coco_core.transforms.edges import DynamicEdge
from coco_core.xml import load_application, parse_application_string

TOLERANCE = 1e-12

TINY_URDF = """<?xml version="1.0"?>
<robot name="tiny">
  <link name="base"/>
  <link name="upper"/>
  <link name="tool"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/>
    <child link="upper"/>
    <origin xyz="0 0 0.5" rpy="0 0 0"/>
    <axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <joint name="flange" type="fixed">
    <parent link="upper"/>
    <child link="tool"/>
    <origin xyz="0.3 0 0"/>
  </joint>
</robot>
"""
"""A two-link robot: base -(shoulder, about z, 0.5 up)-> upper -(fixed, 0.3 along x)-> tool."""


@register("TransformsProbe")
class TransformsProbe(Component):
    """Records what the graph holds when its ``init()`` runs."""

    def init(self) -> None:
        graph = self.transform_graph
        self.seen_at_init = graph.lookup("world", "camera").copy()
        self.strict_at_init = graph.strict


APPLICATION = """<package name="cell">
  <transforms history="30">
    <frame name="lab"/>
    <static parent="world" child="camera" xyz="0.1 -0.2 1.2" rpy="0.1 0.3 -0.4"/>
    <static parent="camera" child="optical" quaternion="-0.5 0.5 -0.5 0.5"/>
    <dynamic parent="world" child="bowl" history="200"/>
    <dynamic parent="camera" child="marker"/>
    <axis parent="world" child="arm" joint="j1" type="revolute" xyz="0 0 0.3" rpy="0 0 1.5"
          axis="0 1 0" value="0.25"/>
    <axis parent="arm" child="slider" joint="j2" type="prismatic" axis="1 0 0" value="0.1"/>
    <axis parent="slider" child="wrist" joint="j3" type="continuous" dh="0.1 0.2 0.3 0.4" value="-0.5"/>
  </transforms>
  <components>
    <component><name>probe</name><task>TransformsProbe</task></component>
  </components>
</package>
"""


def build(text: str, **kwargs):
    return build_application(parse_application_string(text, filename="app.xml", **kwargs))


def build_errors(text: str) -> list[tuple[int | None, str]]:
    with pytest.raises(ConfigErrors) as raised:
        build(text)
    return [(e.location.line if e.location else None, e.message) for e in raised.value.errors]


def rotation_about(axis, angle) -> np.ndarray:
    return se3.make(se3.axis_angle(axis, angle))


@pytest.fixture
def app():
    application = build(APPLICATION)
    yield application
    application.stop()


def test_declared_frames_and_edges_have_their_kinds(app):
    graph = app.transforms
    assert set(graph.frames) == {"lab", "world", "camera", "optical", "bowl", "marker", "arm", "slider", "wrist"}
    kinds = {(edge.parent, edge.child): edge.kind for edge in graph.edges}
    assert kinds == {
        ("world", "camera"): EdgeKind.STATIC,
        ("camera", "optical"): EdgeKind.STATIC,
        ("world", "bowl"): EdgeKind.DYNAMIC,
        ("camera", "marker"): EdgeKind.DYNAMIC,
        ("world", "arm"): EdgeKind.AXIS,
        ("arm", "slider"): EdgeKind.AXIS,
        ("slider", "wrist"): EdgeKind.AXIS,
    }
    bowl, marker = graph.edge("world", "bowl"), graph.edge("camera", "marker")
    assert isinstance(bowl, DynamicEdge) and isinstance(marker, DynamicEdge)
    assert (bowl.capacity, marker.capacity, graph.history) == (200, 30, 30)
    assert graph.strict is True
    assert sorted(graph.joint_names) == ["j1", "j2", "j3"]


def test_lookups_equal_the_analytic_transforms(app):
    graph = app.transforms
    camera = se3.make(se3.rpy_to_matrix(0.1, 0.3, -0.4), [0.1, -0.2, 1.2])
    optical = se3.from_pose([0, 0, 0], [-0.5, 0.5, -0.5, 0.5])
    np.testing.assert_allclose(graph.lookup("world", "camera"), camera, atol=TOLERANCE)
    np.testing.assert_allclose(graph.lookup("world", "optical"), camera @ optical, atol=TOLERANCE)

    j1_origin = se3.make(se3.rpy_to_matrix(0, 0, 1.5), [0, 0, 0.3])
    arm = j1_origin @ rotation_about((0, 1, 0), 0.25)
    slider = se3.make(None, [0.1, 0, 0])
    wrist = se3.denavit_hartenberg(0.1, 0.2 - 0.5, 0.3, 0.4)
    np.testing.assert_allclose(graph.lookup("world", "arm"), arm, atol=TOLERANCE)
    np.testing.assert_allclose(graph.lookup("world", "wrist"), arm @ slider @ wrist, atol=TOLERANCE)

    graph.set_joints({"j1": -1.0, "j2": 0.4, "j3": 2.0})
    arm = j1_origin @ rotation_about((0, 1, 0), -1.0)
    slider = se3.make(None, [0.4, 0, 0])
    wrist = se3.denavit_hartenberg(0.1, 0.2 + 2.0, 0.3, 0.4)
    np.testing.assert_allclose(graph.lookup("world", "wrist"), arm @ slider @ wrist, atol=TOLERANCE)


def test_the_structure_is_there_before_components_init(app):
    probe = app.component("probe")
    np.testing.assert_allclose(probe.seen_at_init, app.transforms.lookup("world", "camera"))
    assert probe.strict_at_init is True


def test_strict_graph_refuses_an_undeclared_edge_naming_it_and_the_declared_ones(app):
    graph = app.transforms
    with pytest.raises(TransformError) as raised:
        graph.set_transform("world", "cup", np.eye(4), stamp=1.0)
    message = str(raised.value)
    assert "edge world->cup is not declared" in message
    for declared in ("world->camera", "camera->optical", "world->bowl", "camera->marker", "world->arm",
                     "arm->slider", "slider->wrist"):
        assert declared in message
    assert "cup" not in graph.frames


def test_declared_dynamic_edges_take_samples(app):
    graph = app.transforms
    pose = se3.make(se3.rpy_to_matrix(0, 0, 0.5), [0.4, 0.1, 0.0])
    graph.set_transform("world", "bowl", pose, stamp=1.0)
    np.testing.assert_allclose(graph.lookup("world", "bowl"), pose, atol=TOLERANCE)


def test_writing_a_transform_to_an_axis_edge_names_the_joint(app):
    with pytest.raises(TransformError, match=r"edge world->arm is an? axis edge driven by joint j1"):
        app.transforms.set_transform("world", "arm", np.eye(4))


def test_without_the_section_the_graph_is_not_strict():
    application = build("<package/>")
    graph = application.transforms
    assert graph.strict is False and graph.frames == []
    graph.set_transform("world", "cup", np.eye(4), stamp=1.0)
    assert graph.edge("world", "cup").kind is EdgeKind.DYNAMIC


def test_strict_false_keeps_the_declared_kinds_and_accepts_new_edges():
    application = build("""<package><transforms strict="false">
  <axis parent="world" child="arm" joint="j1" type="revolute"/>
</transforms></package>""")
    graph = application.transforms
    assert graph.strict is False
    graph.set_transform("world", "cup", np.eye(4), stamp=1.0)
    with pytest.raises(TransformError, match="joint j1"):
        graph.set_transform("world", "arm", np.eye(4))


# ----- URDF -------------------------------------------------------------------------------------


@pytest.fixture
def tiny_urdf(tmp_path) -> Path:
    pytest.importorskip("pinocchio")
    path = tmp_path / "robots" / "tiny.urdf"
    path.parent.mkdir()
    path.write_text(TINY_URDF)
    return path


def test_urdf_is_loaded_and_attached_to_its_frame(tmp_path, tiny_urdf):
    (tmp_path / "app.xml").write_text("""<package>
  <paths><path>robots</path></paths>
  <transforms>
    <frame name="world"/>
    <urdf file="tiny.urdf" prefix="r/" attach="world" xyz="1 0 0" rpy="0 0 1.5707963267948966"/>
    <static parent="r/tool" child="pen" xyz="0 0 0.1"/>
  </transforms>
</package>""")
    application = build_application(load_application(tmp_path / "app.xml"))
    graph = application.transforms
    assert {"world", "r/base", "r/upper", "r/tool", "pen"} <= set(graph.frames)
    assert graph.edge("world", "r/base").kind is EdgeKind.STATIC
    assert graph.edge("r/base", "r/upper").kind is EdgeKind.AXIS
    assert graph.edge("r/upper", "r/tool").kind is EdgeKind.STATIC

    graph.set_joints({"shoulder": 0.7})
    attach = se3.make(se3.rpy_to_matrix(0, 0, math.pi / 2), [1, 0, 0])
    expected = (attach @ se3.make(None, [0, 0, 0.5]) @ rotation_about((0, 0, 1), 0.7)
                @ se3.make(None, [0.3, 0, 0]) @ se3.make(None, [0, 0, 0.1]))
    np.testing.assert_allclose(graph.lookup("world", "pen"), expected, atol=1e-9)
    with pytest.raises(TransformError, match="joint shoulder"):
        graph.set_transform("r/base", "r/upper", np.eye(4))
    with pytest.raises(TransformError, match="edge world->r/elbow is not declared"):
        graph.set_transform("world", "r/elbow", np.eye(4))


def test_urdf_with_a_joint_prefix(tiny_urdf):
    application = build(f"""<package><transforms>
  <urdf file="{tiny_urdf}" prefix="left/" joint_prefix="left_" attach="world"/>
  <urdf file="{tiny_urdf}" prefix="right/" joint_prefix="right_" attach="world" xyz="0 -1 0"/>
</transforms></package>""")
    graph = application.transforms
    assert sorted(graph.joint_names) == ["left_shoulder", "right_shoulder"]
    graph.set_joints({"right_shoulder": 0.5})
    expected = se3.make(None, [0, -1, 0.5]) @ rotation_about((0, 0, 1), 0.5)
    np.testing.assert_allclose(graph.lookup("world", "right/upper"), expected, atol=1e-9)
    np.testing.assert_allclose(graph.lookup("world", "left/upper"), se3.make(None, [0, 0, 0.5]), atol=1e-9)


def test_urdf_problems_are_errors_at_the_element():
    errors = build_errors("""<package><transforms>
  <urdf file="package://no_such_package_for_coco_tests/robot.urdf" attach="world"/>
</transforms></package>""")
    assert len(errors) == 1
    line, message = errors[0]
    assert line == 2
    assert message.startswith("<urdf> cannot resolve package://no_such_package_for_coco_tests/robot.urdf: "
                              "package 'no_such_package_for_coco_tests' not found; tried: ")


def test_urdf_joints_clash_with_declared_ones(tiny_urdf):
    errors = build_errors(f"""<package><transforms>
  <axis parent="world" child="arm" joint="shoulder" type="revolute"/>
  <urdf file="{tiny_urdf}"/>
  <static parent="world" child="camera"/>
  <urdf file="{tiny_urdf}" prefix="b/" joint_prefix="b_" attach="camera"/>
  <static parent="b/upper" child="b/tool"/>
</transforms></package>""")
    assert errors[0] == (
        3, f"<urdf> {tiny_urdf}: joint 'shoulder' of the robot is also declared by <axis> world->arm at app.xml:2; "
           "joint names are unique (give the robot a joint_prefix=)")
    (line, message), = errors[1:]
    assert line == 5
    assert message.startswith("<urdf> model b/tiny: joint ")
    assert "would join b/upper and b/tool, already joined by" in message


def test_two_robots_need_distinct_joint_names(tiny_urdf):
    errors = build_errors(f"""<package><transforms>
  <urdf file="{tiny_urdf}" prefix="a/"/>
  <urdf file="{tiny_urdf}" prefix="b/"/>
</transforms></package>""")
    assert errors == [
        (3, f"<urdf> {tiny_urdf}: joint 'shoulder' of the robot is also declared by <urdf> {tiny_urdf} at "
            "app.xml:2; joint names are unique (give the robot a joint_prefix=)"),
    ]
