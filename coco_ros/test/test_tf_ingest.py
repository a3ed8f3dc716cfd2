"""Writing /tf and /tf_static into the transformation graph: dynamic edges at the header stamps,
static edges (replaced by a new value, untouched by a re-sent set), an optional frame prefix, the
echo rule (frames the bridge broadcasts are not ingested) and what the graph refuses."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from coco_core.transforms import se3
from coco_core.transforms.edges import DynamicEdge, StaticEdge
from coco_core.transforms.graph import TransformGraph
from coco_core.transforms.samples import TransformSample
from coco_core.transforms.urdf import load_urdf
from coco_ros.convert import converter_for
from coco_ros.convert.stamps import RosTime
from coco_ros.tf.ingest import TFIngest
from coco_ros.tf.selection import TFSelection

BAXTER_URDF = "package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"


def pose(x: float, yaw: float = 0.0) -> np.ndarray:
    return se3.make(se3.axis_angle((0, 0, 1), yaw), (x, -0.5, 0.25))


def sample(parent: str, child: str, x: float, stamp: float | None = None) -> TransformSample:
    return TransformSample(parent, child, pose(x, yaw=x), stamp)


def test_tf_becomes_dynamic_edges_at_the_header_stamps() -> None:
    graph = TransformGraph()
    ingest = TFIngest(graph)
    # What the subscription hands over: the converter's samples of a real tf2_msgs message.
    tf = converter_for("tf2_msgs/msg/TFMessage")
    msg = tf.to_ros([sample("map", "odom", 0.1, RosTime(50, 250)), sample("odom", "base_link", 0.2, RosTime(50, 250))])
    ingest.dynamic(tf.to_coco(msg))
    ingest.dynamic([sample("odom", "base_link", 0.3, RosTime(50, 500))])
    edge = graph.edge("odom", "base_link")
    assert isinstance(edge, DynamicEdge) and edge.time_range == (50.00000025, 50.0000005)
    np.testing.assert_allclose(graph.lookup("odom", "base_link"), pose(0.3, 0.3), atol=1e-12)
    np.testing.assert_allclose(graph.lookup("odom", "base_link", time=50.00000025), pose(0.2, 0.2), atol=1e-12)
    np.testing.assert_allclose(graph.lookup("map", "base_link"), pose(0.1, 0.1) @ pose(0.3, 0.3), atol=1e-12)
    assert ingest.counts == {"received": 3, "ingested": 3, "echoes": 0, "rejected": 0}
    assert ingest.ingested(("odom", "base_link")) and not ingest.ingested(("base_link", "odom"))


def test_tf_static_becomes_static_edges_a_resent_set_changes_nothing() -> None:
    graph = TransformGraph()
    ingest = TFIngest(graph)
    ingest.static([sample("base_link", "camera", 0.4), sample("base_link", "lidar", 0.5)])
    edge = graph.edge("base_link", "camera")
    assert isinstance(edge, StaticEdge)
    version = edge.version
    ingest.static([sample("base_link", "camera", 0.4), sample("base_link", "lidar", 0.5)])  # re-sent
    assert edge.version == version
    ingest.static([sample("base_link", "camera", 0.45)])  # a new calibration
    assert edge.version == version + 1
    np.testing.assert_allclose(graph.lookup("base_link", "camera"), pose(0.45, 0.45), atol=1e-12)
    assert ingest.counts["ingested"] == 5


def test_a_prefix_renames_the_ingested_frames() -> None:
    graph = TransformGraph()
    ingest = TFIngest(graph, prefix="robot2/")
    ingest.static([sample("base_link", "camera", 0.4)])
    ingest.dynamic([sample("odom", "base_link", 0.1, 3.0)])
    assert sorted(graph.frames) == ["robot2/base_link", "robot2/camera", "robot2/odom"]
    assert ingest.ingested(("robot2/odom", "robot2/base_link"))


def test_frames_the_bridge_broadcasts_are_not_ingested_no_echo() -> None:
    graph = TransformGraph()
    graph.add_static("world", "table", pose(1.0))
    graph.add_dynamic("table", "cup")
    graph.set_transform("table", "cup", pose(0.2), stamp=10.0)
    ingest = TFIngest(graph)
    selection = TFSelection(graph, root="world", ingested=ingest.ingested)
    ingest.broadcast = lambda: selection.children
    sent = selection.moving() + selection.static()
    ingest.dynamic(sent)  # the bridge's own messages come back from DDS
    ingest.static(sent)
    assert ingest.counts == {"received": 4, "ingested": 0, "echoes": 4, "rejected": 0}
    assert isinstance(graph.edge("world", "table"), StaticEdge) and graph.edge("table", "cup").version == 1
    # Another node's frame is welcome, and it is not broadcast back.
    ingest.dynamic([sample("cup", "spoon", 0.05, 11.0)])
    assert ingest.counts["ingested"] == 1
    assert selection.moving() == [] and "spoon" not in selection.children


def test_what_the_graph_refuses_is_counted_and_logged_once(caplog: pytest.LogCaptureFixture) -> None:
    graph = TransformGraph()
    load_urdf(graph, BAXTER_URDF)
    graph.add_dynamic("base", "marker")
    ingest = TFIngest(graph, owner="TFBridge tf")
    with caplog.at_level(logging.ERROR, logger="coco.tf"):
        for _ in range(3):  # a robot_state_publisher of the same robot beside us
            ingest.dynamic([sample("left_upper_shoulder", "left_lower_shoulder", 0.1, 1.0),
                            sample("world", "base_link", 0.2, 1.0)])
        ingest.static([sample("base", "marker", 0.3)])  # a dynamic edge of the graph
    assert ingest.counts == {"received": 7, "ingested": 3, "echoes": 0, "rejected": 4}
    refused = [r.getMessage() for r in caplog.records]
    assert len(refused) == 2, refused
    assert "TFBridge tf: cannot write the transform left_upper_shoulder -> left_lower_shoulder" in refused[0]
    assert "belongs to kinematic model baxter" in refused[0]
    assert "edge base->marker is a dynamic edge of the graph, not a static one" in refused[1]
    # The URDF edge stays the graph's own; only the new one counts as ingested.
    assert not ingest.ingested(("left_upper_shoulder", "left_lower_shoulder"))
    assert not ingest.ingested(("base", "marker")) and ingest.ingested(("world", "base_link"))
