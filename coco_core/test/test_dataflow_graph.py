"""``--check --graph FILE``: the application's data-flow graph as DOT (and SVG through Graphviz's dot),
with a cluster per process and activity, components as nodes, peers inside their owner, connections
as edges labelled with their policy and filters as nodes on their connection's path."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from coco_core.dataflow_graph import GraphError, check_graph_file, dataflow_dot, quote
from coco_core.deployment import plan_deployment
from coco_core.xml import load_application

CONFIG = Path(__file__).resolve().parents[2] / "config"
DOT = shutil.which("dot")
needs_dot = pytest.mark.skipif(DOT is None, reason="Graphviz's dot is not installed")


def launch(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "coco_core.launcher", *args], capture_output=True, text=True,
                          timeout=120, env=env)


def parsed(text: str) -> dict:
    """The graph as Graphviz reads it (``dot -Tjson``): what it makes of the DOT, not what was meant."""
    done = subprocess.run([DOT, "-Tjson0"], input=text, capture_output=True, text=True, timeout=60, check=True)
    return json.loads(done.stdout)


def clusters(graph: dict) -> dict[str, set[str]]:
    """Each cluster's label and the names of the nodes inside it (nested clusters' too)."""
    objects = graph["objects"]
    found = {}
    for item in objects:
        if item["name"].startswith("cluster_"):
            found[item["label"]] = {objects[index]["name"] for index in item.get("nodes", [])}
    return found


def edges(graph: dict) -> set[tuple[str, str, str]]:
    objects = graph["objects"]
    return {(objects[edge["tail"]]["name"], objects[edge["head"]]["name"], edge["label"])
            for edge in graph.get("edges", [])}


@needs_dot
def test_the_haptic_graph_has_a_cluster_per_process_and_activity_and_every_component_and_connection():
    spec = load_application(CONFIG / "haptic_implicit.xml")
    graph = parsed(dataflow_dot(plan_deployment(spec)))
    groups = clusters(graph)
    assert groups["process haptics"] == {"component:device", "component:renderer", "component:scene",
                                         "component:ball"}
    assert groups["process launcher"] == {"component:recorder"}
    assert groups["activity haptics\\nperiodic 1 ms"] == groups["process haptics"]
    assert groups["activity recording\\nperiodic 100 ms"] == {"component:recorder"}
    assert groups["renderer and its peers"] == {"component:renderer", "component:scene", "component:ball"}
    every = {component.name for component in spec.all_components()}
    assert {item["name"] for item in graph["objects"] if "nodes" not in item} == {f"component:{name}" for name in every}
    assert edges(graph) == {
        ("component:device", "component:renderer", "state -> device\\nDATA/LOCKED"),
        ("component:renderer", "component:device", "force -> force\\nDATA/LOCKED"),
        ("component:renderer", "component:recorder", "sample -> samples\\nBUFFER/LOCKED[4000]\\nbetween processes"),
    }
    assert len(spec.connections) == 3


@needs_dot
def test_a_filter_is_a_node_on_its_connections_path_between_activity_ports():
    graph = parsed(dataflow_dot(plan_deployment(load_application(CONFIG / "flowvr_b_demand_driven.xml"))))
    groups = clusters(graph)
    assert groups["activity produce\\ntriggered"] == {"activity:produce.beginit", "component:producer"}
    assert groups["activity consume\\ntriggered"] == {"activity:consume.endit", "component:consumer"}
    assert edges(graph) == {
        ("component:producer", "component:consumer", "out -> item\\nBUFFER/LOCKED[1]"),
        ("activity:consume.endit", "filter:1", "endit"),
        ("filter:1", "activity:produce.beginit", "beginit\\nLOCKED"),
    }
    [filter_node] = [item for item in graph["objects"] if item["name"] == "filter:1"]
    assert (filter_node["shape"], filter_node["label"]) == ("diamond", "PreSignal\\ntokens=1, buffer 1")


@needs_dot
def test_composite_instances_appear_under_their_scoped_names():
    graph = parsed(dataflow_dot(plan_deployment(load_application(CONFIG / "composite_signals.xml"))))
    assert clusters(graph)["activity fast/filtering\\ntriggered"] == {"component:fast/filter"}
    assert ("component:fast/filter", "component:fast_recorder", "filtered -> values\\nBUFFER/LOCKED[256]") in edges(graph)


def test_names_are_quoted_for_dot():
    assert quote('a "b"\\c\nd') == '"a \\"b\\"\\\\c\\nd"'


def test_check_graph_writes_dot(tmp_path):
    out = tmp_path / "graph.dot"
    done = launch(str(CONFIG / "flowvr_b_demand_driven.xml"), "--check", "--graph", str(out))
    assert done.returncode == 0, done.stderr
    assert f"data-flow graph written to {out}" in done.stdout
    text = out.read_text()
    assert text.startswith('digraph "flowvr_b_demand_driven" {') and '"filter:1" [label="PreSignal' in text


@needs_dot
def test_check_graph_renders_svg_with_its_dot_beside_it(tmp_path):
    out = tmp_path / "graph.svg"
    done = launch(str(CONFIG / "composite_signals.xml"), "--check", "--graph", str(out))
    assert done.returncode == 0, done.stderr
    assert f"data-flow graph written to {tmp_path / 'graph.dot'}, {out}" in done.stdout
    assert out.read_text().lstrip().startswith("<?xml") and "<svg" in out.read_text()
    assert "slow/generator" in out.read_text()


def test_svg_without_graphviz_says_to_install_it(tmp_path):
    env = {**os.environ, "PATH": str(tmp_path)}  # no dot there
    done = launch(str(CONFIG / "flowvr_b_demand_driven.xml"), "--check", "--graph", str(tmp_path / "g.svg"), env=env)
    assert done.returncode == 1
    assert (f"--graph {tmp_path / 'g.svg'}: rendering SVG needs Graphviz's dot program, which is not on PATH; "
            f"install Graphviz (apt install graphviz) or write DOT (--graph {tmp_path / 'g.dot'})") in done.stderr
    assert not (tmp_path / "g.svg").exists() and not (tmp_path / "g.dot").exists()


@pytest.mark.parametrize("name, message", [
    ("missing/g.dot", "--graph {path}: its folder {tmp}/missing does not exist"),
    ("g.txt", "--graph {path}: expected a file name ending in one of .dot, .gv, .svg, .png, .pdf"),
    (".", "--graph {path}: expected a file name ending in one of"),
])
def test_a_bad_graph_path_is_a_clear_error_and_a_failure(tmp_path, name, message):
    path = tmp_path / name
    done = launch(str(CONFIG / "flowvr_b_demand_driven.xml"), "--check", "--graph", str(path))
    assert done.returncode == 1
    assert message.format(path=path, tmp=tmp_path) in done.stderr
    assert "application flowvr_b_demand_driven" not in done.stdout  # refused before anything is read


def test_a_directory_named_like_a_graph_is_refused(tmp_path):
    (tmp_path / "g.dot").mkdir()
    with pytest.raises(GraphError, match="is a directory; expected a file name"):
        check_graph_file(str(tmp_path / "g.dot"))


def test_graph_goes_with_check(tmp_path):
    done = launch(str(CONFIG / "flowvr_b_demand_driven.xml"), "--graph", str(tmp_path / "g.dot"))
    assert done.returncode == 2  # a wrong command line
    assert "--graph goes with --check" in done.stderr
    assert not (tmp_path / "g.dot").exists()
