"""JSON and graphviz DOT exports of the transformation graph."""

from __future__ import annotations

import json
import math
import re
import shutil
import subprocess

import numpy as np
import pytest

from coco_core.transforms import EdgeKind, TransformGraph, se3
from coco_core.transforms.urdf import load_urdf
from coco_core.transforms.export import graph_dict, jsonable, to_dot, to_json, write_dot


ARM_URDF = """<robot name="arm">
  <link name="arm_base"/>
  <link name="arm_tool"/>
  <joint name="slide" type="prismatic">
    <parent link="arm_base"/>
    <child link="arm_tool"/>
    <axis xyz="1 0 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
</robot>
"""
"""A small real URDF robot (arm_base -> arm_tool) whose one joint slides arm_tool along x."""


@pytest.fixture
def graph() -> TransformGraph:
    graph = TransformGraph()
    graph.add_static("world", "base", se3.make(se3.rpy_to_matrix(0.0, 0.0, math.pi / 2), [0.0, 0.0, 1.0]))
    graph.add_axis("base", "link1", "shoulder", "revolute", se3.make(None, [0.0, 0.0, 0.3]), (0, 0, 1), 0.5)
    graph.set_transform("world", "camera", se3.make(None, [1.0, 2.0, 3.0]), stamp=10.0)
    graph.set_transform("world", "camera", se3.make(None, [1.5, 2.0, 3.0]), stamp=11.0)
    graph.add_dynamic("camera", "marker")  # declared, never written: no value yet
    load_urdf(graph, ARM_URDF)
    graph.add_static("link1", "arm_base")
    graph.set_joint("slide", 0.25)
    graph.add_frame("lonely")
    return graph


def test_json_round_trips_every_frame_edge_kind_value_and_stamp(graph: TransformGraph) -> None:
    data = json.loads(to_json(graph))
    assert data["frames"] == graph.frames
    assert data["version"] == graph.version
    assert data["models"] == ["arm"]
    assert isinstance(data["time"], float)
    edges = {(edge["parent"], edge["child"]): edge for edge in data["edges"]}
    assert set(edges) == {(edge.parent, edge.child) for edge in graph.edges}
    for edge in graph.edges:
        exported = edges[(edge.parent, edge.child)]
        assert exported["kind"] == edge.kind.value
        if (edge.parent, edge.child) == ("camera", "marker"):
            continue
        np.testing.assert_allclose(exported["transform"], edge.transform())
        translation, quaternion = se3.to_pose(edge.transform())
        np.testing.assert_allclose(exported["translation"], translation)
        np.testing.assert_allclose(exported["quaternion"], quaternion)

    camera = edges[("world", "camera")]
    assert camera["stamp"] == 11.0 and camera["samples"] == 2
    assert camera["translation"] == [1.5, 2.0, 3.0]
    marker = edges[("camera", "marker")]
    assert marker["transform"] is None and marker["stamp"] is None and "translation" not in marker
    shoulder = edges[("base", "link1")]
    assert (shoulder["joint"], shoulder["joint_type"], shoulder["value"]) == ("shoulder", "revolute", 0.5)
    assert shoulder["axis"] == [0.0, 0.0, 1.0]
    np.testing.assert_allclose(shoulder["origin"], se3.make(None, [0.0, 0.0, 0.3]))
    base = edges[("world", "base")]
    np.testing.assert_allclose(base["quaternion"], [0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)], atol=1e-12)
    slide = edges[("arm_base", "arm_tool")]
    assert (slide["kind"], slide["joint"], slide["model"]) == ("axis", "slide", "arm")
    assert slide["translation"] == [0.25, 0.0, 0.0]


def test_json_follows_changes_and_indents(graph: TransformGraph) -> None:
    graph.set_joint("shoulder", -1.25)
    graph.set_joint("slide", 0.75)
    graph.set_transform("camera", "marker", se3.make(None, [0.0, 0.0, 0.5]), stamp=12.0)
    text = to_json(graph, indent=2)
    assert text.startswith("{\n  ")
    edges = {(edge["parent"], edge["child"]): edge for edge in json.loads(text)["edges"]}
    assert edges[("base", "link1")]["value"] == -1.25
    assert edges[("arm_base", "arm_tool")]["translation"] == [0.75, 0.0, 0.0]
    assert edges[("camera", "marker")]["stamp"] == 12.0
    assert edges[("camera", "marker")]["translation"] == [0.0, 0.0, 0.5]


def test_jsonable_makes_strict_json() -> None:
    value = {"a": np.arange(3), "b": np.float32(1.5), "c": float("nan"), "d": (1, np.int64(2)), "e": EdgeKind.AXIS,
             1: {float("inf")}}
    assert json.loads(json.dumps(jsonable(value), allow_nan=False)) == {
        "a": [0, 1, 2], "b": 1.5, "c": None, "d": [1, 2], "e": "axis", "1": [None]}


def test_empty_graph_exports() -> None:
    empty = TransformGraph()
    assert json.loads(to_json(empty))["frames"] == []
    assert graph_dict(empty)["edges"] == []
    assert re.fullmatch(r'digraph "transforms" \{\n(  [^\n]*;\n)*\}\n', to_dot(empty))


EDGE_LINE = re.compile(r'^  "((?:[^"\\]|\\.)*)" -> "((?:[^"\\]|\\.)*)" \[label="((?:[^"\\]|\\.)*)", '
                       r'style=(\w+)(?:, color=\w+)?\];$')
NODE_LINE = re.compile(r'^  "((?:[^"\\]|\\.)*)";$')


def test_dot_has_every_frame_and_edge_styled_by_kind(graph: TransformGraph) -> None:
    text = to_dot(graph)
    lines = text.splitlines()
    assert lines[0] == 'digraph "transforms" {' and lines[-1] == "}"
    assert text.count("{") == text.count("}") == 1
    nodes = [match.group(1) for match in map(NODE_LINE.match, lines) if match]
    assert nodes == graph.frames
    edges = {(m.group(1), m.group(2)): (m.group(3), m.group(4)) for m in map(EDGE_LINE.match, lines) if m}
    assert set(edges) == {(edge.parent, edge.child) for edge in graph.edges}
    styles = {"static": "solid", "dynamic": "dashed", "axis": "bold"}
    for edge in graph.edges:
        label, style = edges[(edge.parent, edge.child)]
        assert label.startswith(edge.kind.value) and style == styles[edge.kind.value]
    assert edges[("base", "link1")][0] == r"axis\nshoulder = 0.5 (revolute)"
    assert edges[("world", "camera")][0] == r"dynamic\nstamp 11.000"
    assert edges[("camera", "marker")][0] == r"dynamic\nno sample"
    assert edges[("arm_base", "arm_tool")][0] == r"axis\nslide = 0.25\nmodel arm"
    graph.set_joint("shoulder", 1.0)
    assert r'label="axis\nshoulder = 1 (revolute)"' in to_dot(graph)


def test_dot_quotes_awkward_frame_names(tmp_path) -> None:
    graph = TransformGraph()
    graph.add_static('my "odd" frame', "back\\slash")
    text = to_dot(graph)
    assert r'"my \"odd\" frame" -> "back\\slash"' in text
    path = write_dot(graph, tmp_path / "graph.dot")
    assert path.read_text(encoding="utf-8") == text


def test_dot_renders_with_graphviz(graph: TransformGraph, tmp_path) -> None:
    dot = shutil.which("dot")
    if dot is None:
        pytest.skip("graphviz 'dot' is not installed (optional: apt-get install graphviz)")
    graph.add_static('my "odd" frame', "world")
    path = write_dot(graph, tmp_path / "graph.dot")
    result = subprocess.run([dot, "-Tsvg", str(path)], capture_output=True, text=True, timeout=30)
    assert result.returncode == 0, result.stderr
    for frame in graph.frames:
        assert frame.replace('"', "&quot;") in result.stdout
    assert result.stdout.count('class="edge"') == len(graph.edges)
