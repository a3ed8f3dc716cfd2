"""URDF robots in the transformation graph: Pinocchio kinematics checked against Pinocchio itself and
yourdfpy (Baxter from example-robot-data), each joint kind checked analytically, JointState handling,
package:// resolution and errors."""

from __future__ import annotations

import ast
import importlib.metadata
import logging
import math
from pathlib import Path

import numpy as np
import pytest

pinocchio = pytest.importorskip("pinocchio")

from coco_core.transforms import EdgeKind, TransformError, TransformGraph, se3  # noqa: E402
from coco_core.transforms.resources import ResourceNotFoundError, package_share_directory, resolve  # noqa: E402
from coco_core.transforms.urdf import UrdfError, UrdfModel, load_urdf  # noqa: E402

TOLERANCE = 1e-9

HAND_CALIB = Path("/work/shared/data/baxter/hand_calib_pos.dat")
# A copy of the recorded Baxter joint_states message above, used when the shared data is not there.
HAND_CALIB_COPY = """\
name: ['head_nod', 'head_pan', 'left_e0', 'left_e1', 'left_s0', 'left_s1', 'left_w0', 'left_w1', 'left_w2', \
'right_e0', 'right_e1', 'right_s0', 'right_s1', 'right_w0', 'right_w1', 'right_w2', 'torso_t0']
position: [0.0, -0.04371845240478516, -0.31523305155029296, 1.349903091796875, -0.5269224000366212, \
0.014956312664794923, 1.2881603651550293, -1.0622816943969726, 0.08130098166503907, 1.2126118114379885, \
1.6451943931274415, -0.7179030079101563, 1.0599807232177736, -2.7534955111083987, -0.08321845764770508, \
-0.27151459914550785, -12.565987104803467]
"""


def parse_joint_state(text: str) -> dict[str, float]:
    """A joint_states message dumped as ``field: [python list]`` lines -> name -> position."""
    fields = {}
    for line in text.splitlines():
        key, colon, value = line.partition(":")
        if colon and value.strip():
            fields[key.strip()] = ast.literal_eval(value.strip())
    assert len(fields["name"]) == len(fields["position"])
    return dict(zip(fields["name"], map(float, fields["position"])))


def baxter_urdf() -> Path:
    """Baxter's URDF as installed by the example-robot-data wheel (found through its file list)."""
    try:
        files = importlib.metadata.files("example-robot-data") or []
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed")
    for file in files:
        if str(file).endswith("baxter_description/urdf/baxter.urdf"):
            return Path(str(file.locate()))
    pytest.skip("example-robot-data has no Baxter URDF")


@pytest.fixture(scope="module")
def baxter_path() -> Path:
    return baxter_urdf()


@pytest.fixture(scope="module")
def baxter(baxter_path):
    """(graph, model) shared by the read-only Baxter tests."""
    graph = TransformGraph()
    return graph, load_urdf(graph, baxter_path)


@pytest.fixture
def fresh_baxter(baxter_path):
    """(graph, model) for tests that care about first updates and logs."""
    graph = TransformGraph()
    return graph, load_urdf(graph, baxter_path.read_text())


@pytest.fixture(scope="module")
def references(baxter_path):
    """Pinocchio (model, data) built independently, and yourdfpy's model of the same file."""
    yourdfpy = pytest.importorskip("yourdfpy")
    model = pinocchio.buildModelFromUrdf(str(baxter_path))
    urdf = yourdfpy.URDF.load(str(baxter_path), load_meshes=False, build_scene_graph=True,
                              load_collision_meshes=False, build_collision_scene_graph=False)
    return model, model.createData(), urdf


def random_configuration(model: UrdfModel, rng: np.random.Generator) -> dict[str, float]:
    config = {}
    for name, (lower, upper) in model.limits.items():
        if not math.isfinite(lower):
            lower, upper = -math.pi, math.pi
        config[name] = float(rng.uniform(lower, upper))
    return config


def pinocchio_q(model, config: dict[str, float], mimics: dict[str, tuple[str, float, float]]) -> np.ndarray:
    """Pinocchio's q for a name -> value configuration, mimic joints computed from their leaders."""
    values = dict(config)
    for name, (leader, multiplier, offset) in mimics.items():
        values[name] = multiplier * config[leader] + offset
    q = pinocchio.neutral(model)
    for joint_id in range(1, model.njoints):
        joint = model.joints[joint_id]
        value = values[model.names[joint_id]]
        if joint.nq == 2:
            q[joint.idx_q:joint.idx_q + 2] = math.cos(value), math.sin(value)
        else:
            q[joint.idx_q] = value
    return q


# --- Baxter: correctness against Pinocchio and yourdfpy ---------------------------------------------
def test_baxter_structure(baxter):
    graph, model = baxter
    assert model.name == "baxter" and model.root_link == "base"
    assert len(model.link_names) == 57 and set(model.link_names) <= set(graph.frames)
    assert len(model.joint_names) == 17
    assert model.mimic_joints == {"l_gripper_r_finger_joint": ("l_gripper_l_finger_joint", -1.0, 0.0),
                                  "r_gripper_r_finger_joint": ("r_gripper_l_finger_joint", -1.0, 0.0)}
    left_s0 = graph.edge("left_arm_mount", "left_upper_shoulder")
    assert left_s0.kind is EdgeKind.AXIS and left_s0.joint == "left_s0"
    head_nod = graph.edge("head", "screen")
    assert head_nod.kind is EdgeKind.STATIC and head_nod.joint == "head_nod"
    assert graph.edge("left_gripper_base_link", "l_gripper_r_finger").kind is EdgeKind.AXIS
    assert sum(1 for edge in graph.edges if edge.kind is EdgeKind.AXIS) == 19
    assert len(graph.edges) == 56
    assert "head_nod" not in model.joint_names and "torso_t0" not in model.joint_names


def test_baxter_every_link_matches_pinocchio_and_yourdfpy(baxter, references):
    graph, model = baxter
    reference, data, urdf = references
    rng = np.random.default_rng(7)
    root = model.root_link
    for _ in range(20):
        config = random_configuration(model, rng)
        assert graph.set_joints(config) == []
        pinocchio.framesForwardKinematics(reference, data, pinocchio_q(reference, config, model.mimic_joints))
        urdf.update_cfg(config)
        for link in model.link_names:
            value = graph.lookup(root, link)
            expected = data.oMf[reference.getFrameId(link, pinocchio.BODY)].homogeneous
            np.testing.assert_allclose(value, expected, rtol=0, atol=TOLERANCE, err_msg=link)
            np.testing.assert_allclose(value, urdf.get_transform(link, root), rtol=0, atol=TOLERANCE, err_msg=link)
            assert not value.flags.writeable
        # the mimic fingers really moved opposite to their leaders
        assert graph.lookup("left_gripper_base_link", "l_gripper_r_finger")[1, 3] == pytest.approx(
            0.0015 - config["l_gripper_l_finger_joint"], abs=TOLERANCE)


def test_lookup_between_two_links(baxter, references):
    graph, model = baxter
    _, _, urdf = references
    rng = np.random.default_rng(11)
    for _ in range(5):
        config = random_configuration(model, rng)
        graph.set_joints(config)
        urdf.update_cfg(config)
        value = graph.lookup("right_gripper", "left_gripper")
        np.testing.assert_allclose(value, urdf.get_transform("left_gripper", "right_gripper"), atol=TOLERANCE)
        expected = se3.inverse(graph.lookup("base", "right_gripper")) @ graph.lookup("base", "left_gripper")
        np.testing.assert_allclose(value, expected, atol=TOLERANCE)
        np.testing.assert_allclose(graph.lookup("left_gripper", "right_gripper") @ value, np.eye(4), atol=TOLERANCE)
        np.testing.assert_array_equal(graph.lookup("left_wrist", "left_wrist"), np.eye(4))


def test_path_mixing_model_and_static_edges(fresh_baxter):
    graph, model = fresh_baxter
    world_base = se3.make(se3.rpy_to_matrix(0.0, 0.0, 0.7), [1.0, -2.0, 0.9])
    camera_on_hand = se3.make(se3.rpy_to_matrix(-math.pi / 2, 0.0, -math.pi / 2), [0.02, 0.0, 0.05])
    graph.add_static("world", "base", world_base)
    graph.add_static("left_hand_camera", "camera_optical", camera_on_hand)  # a frame outside the URDF
    graph.add_static("left_hand_camera_link", "left_hand_camera", np.eye(4))
    graph.set_joints({"left_s0": 0.4, "left_s1": -0.3, "left_e1": 1.2, "left_w1": 0.5, "right_s0": -0.2})
    base_hand = graph.lookup("base", "left_hand_camera_link")
    expected = world_base @ base_hand @ camera_on_hand
    np.testing.assert_allclose(graph.lookup("world", "camera_optical"), expected, atol=TOLERANCE)
    np.testing.assert_allclose(graph.lookup("camera_optical", "world"), se3.inverse(expected), atol=TOLERANCE)
    # the camera seen from the other gripper: static, model (both arms), static again
    expected = se3.inverse(graph.lookup("base", "right_gripper")) @ base_hand @ camera_on_hand
    np.testing.assert_allclose(graph.lookup("right_gripper", "camera_optical"), expected, atol=TOLERANCE)
    # a change of the model reaches the mixed path
    graph.set_joints({"left_w2": 1.0})
    moved = graph.lookup("world", "camera_optical")
    np.testing.assert_allclose(moved, world_base @ graph.lookup("base", "left_hand_camera_link") @ camera_on_hand,
                               atol=TOLERANCE)
    assert not np.allclose(moved, world_base @ base_hand @ camera_on_hand)


# --- JointState handling -----------------------------------------------------------------------------
def test_real_joint_state_unknown_and_never_set_joints(fresh_baxter, caplog):
    graph, model = fresh_baxter
    text = HAND_CALIB.read_text() if HAND_CALIB.exists() else HAND_CALIB_COPY
    state = parse_joint_state(text)
    assert parse_joint_state(HAND_CALIB_COPY) == state
    assert model.never_set == model.joint_names
    with caplog.at_level(logging.WARNING, logger="coco.transforms"):
        unknown = graph.set_joints(state)
        graph.set_joints(state)
        graph.set_joints({**state, "left_e0": 0.1})
    assert sorted(unknown) == ["head_nod", "torso_t0"]
    messages = [record.getMessage() for record in caplog.records]
    unknown_logs = [message for message in messages if "head_nod" in message]
    assert len(unknown_logs) == 1 and "torso_t0" in unknown_logs[0]
    assert model.never_set == ["l_gripper_l_finger_joint", "r_gripper_l_finger_joint"]
    never_logs = [message for message in messages if "l_gripper_l_finger_joint" in message]
    assert len(never_logs) == 1 and "r_gripper_l_finger_joint" in never_logs[0] and "keep 0" in never_logs[0]
    positions = model.positions
    for name, value in state.items():
        if name in model.joint_names and name != "left_e0":
            assert positions[name] == value
    assert positions["left_e0"] == 0.1 and positions["l_gripper_l_finger_joint"] == 0.0
    # the values really reached the kinematics
    reference = model.model
    data = reference.createData()
    pinocchio.framesForwardKinematics(reference, data, pinocchio_q(reference, positions, model.mimic_joints))
    np.testing.assert_allclose(graph.lookup("base", "left_gripper"),
                               data.oMf[reference.getFrameId("left_gripper", pinocchio.BODY)].homogeneous,
                               atol=TOLERANCE)
    graph.set_joints({"l_gripper_l_finger_joint": 0.01, "r_gripper_l_finger_joint": 0.01})
    assert model.never_set == []


def test_version_changes_only_with_values(fresh_baxter):
    graph, model = fresh_baxter
    graph.set_joints({"head_pan": 0.5})
    version = model.version
    first = graph.lookup("base", "head")
    graph.set_joints({"head_pan": 0.5})
    assert model.version == version
    assert graph.lookup("base", "head") is first  # cached, not recomputed
    graph.set_joints({"l_gripper_r_finger_joint": 0.01})  # a mimic joint: known, but follows its leader
    assert model.version == version
    graph.set_joints({"head_pan": -0.5})
    assert model.version == version + 1
    assert graph.lookup("base", "head") is not first


def test_value_that_is_not_a_number(fresh_baxter):
    graph, model = fresh_baxter
    graph.set_joints({"left_s0": 0.25})
    before = graph.lookup("base", "left_gripper")
    with pytest.raises(ValueError, match="left_s1.*'abc'"):
        graph.set_joints({"left_s0": 0.5, "left_s1": "abc"})
    assert model.positions["left_s0"] == 0.25
    np.testing.assert_array_equal(graph.lookup("base", "left_gripper"), before)


def test_query_callbacks_fire_after_set_joints(fresh_baxter):
    graph, model = fresh_baxter
    graph.add_static("world", "base", se3.make(None, [0.0, 0.0, 1.0]))
    received: list[np.ndarray] = []
    unsubscribe = graph.query("world", "left_gripper").on_change(received.append)
    graph.set_joints({"left_s0": 0.3, "head_nod": 0.2})
    assert len(received) == 1
    np.testing.assert_array_equal(received[0], graph.lookup("world", "left_gripper"))
    graph.set_joints({"not_a_joint": 1.0})
    assert len(received) == 1
    graph.set_joint("left_e1", 1.0)
    assert len(received) == 2
    np.testing.assert_allclose(received[1][:3, 3], graph.lookup("world", "left_gripper")[:3, 3])
    unsubscribe()
    graph.set_joints({"left_s0": -0.3})
    assert len(received) == 2


def test_set_joint_unknown_name_is_an_error(fresh_baxter):
    graph, _ = fresh_baxter
    with pytest.raises(TransformError, match="left_s9.*left_s0"):
        graph.set_joint("left_s9", 1.0)


# --- each joint kind, analytically -------------------------------------------------------------------
SMALL_URDF = """<?xml version="1.0"?>
<robot name="bench">
  <link name="base"/>
  <link name="slider"/>
  <link name="wheel"/>
  <link name="tool"/>
  <link name="arm"/>
  <link name="finger"/>
  <joint name="slide" type="prismatic">
    <parent link="base"/><child link="slider"/>
    <origin xyz="1 2 3" rpy="0 0 0.3"/>
    <axis xyz="0 0.6 0.8"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <joint name="spin" type="continuous">
    <parent link="slider"/><child link="wheel"/>
    <origin xyz="0 0 0.5" rpy="0.1 0.2 1.5707963267948966"/>
    <axis xyz="1 0 0"/>
  </joint>
  <joint name="mount" type="fixed">
    <parent link="wheel"/><child link="tool"/>
    <origin xyz="0.1 0 0" rpy="1.5707963267948966 0 0"/>
  </joint>
  <joint name="elbow" type="revolute">
    <parent link="slider"/><child link="arm"/>
    <origin xyz="0 0.2 0"/>
    <axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
    <mimic joint="spin" multiplier="0.5" offset="0.25"/>
  </joint>
  <joint name="grip" type="prismatic">
    <parent link="base"/><child link="finger"/>
    <axis xyz="1 0 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/>
    <mimic joint="slide" multiplier="-2" offset="0.1"/>
  </joint>
</robot>
"""


def origin(xyz, rpy=(0.0, 0.0, 0.0)) -> np.ndarray:
    return se3.make(se3.rpy_to_matrix(*rpy), xyz)


@pytest.fixture
def small_urdf(tmp_path) -> Path:
    path = tmp_path / "bench.urdf"
    path.write_text(SMALL_URDF)
    return path


def test_each_joint_kind_analytically(small_urdf):
    graph = TransformGraph()
    model = load_urdf(graph, small_urdf)
    assert model.joint_names == ["slide", "spin"]
    assert model.mimic_joints == {"elbow": ("spin", 0.5, 0.25), "grip": ("slide", -2.0, 0.1)}
    assert {edge.joint: edge.kind for edge in graph.edges} == {
        "slide": EdgeKind.AXIS, "spin": EdgeKind.AXIS, "mount": EdgeKind.STATIC, "elbow": EdgeKind.AXIS,
        "grip": EdgeKind.AXIS}
    assert model.limits == {"slide": (-1.0, 1.0), "spin": (-math.inf, math.inf)}
    half_pi = math.pi / 2
    for slide, spin in [(0.0, 0.0), (0.7, 4.0), (-0.4, -2.5), (1.0, 10.0)]:
        graph.set_joints({"slide": slide, "spin": spin, "elbow": 99.0, "grip": 99.0})  # mimic values ignored
        base_slider = origin([1, 2, 3], [0, 0, 0.3]) @ se3.make(None, [0.0, 0.6 * slide, 0.8 * slide])
        slider_wheel = origin([0, 0, 0.5], [0.1, 0.2, half_pi]) @ se3.make(se3.axis_angle((1, 0, 0), spin))
        wheel_tool = origin([0.1, 0, 0], [half_pi, 0, 0])
        slider_arm = origin([0, 0.2, 0]) @ se3.make(se3.axis_angle((0, 1, 0), 0.5 * spin + 0.25))
        base_finger = se3.make(None, [-2.0 * slide + 0.1, 0.0, 0.0])
        np.testing.assert_allclose(graph.lookup("base", "slider"), base_slider, atol=TOLERANCE)
        np.testing.assert_allclose(graph.lookup("slider", "wheel"), slider_wheel, atol=TOLERANCE)
        np.testing.assert_allclose(graph.lookup("wheel", "tool"), wheel_tool, atol=TOLERANCE)
        np.testing.assert_allclose(graph.lookup("base", "tool"), base_slider @ slider_wheel @ wheel_tool,
                                   atol=TOLERANCE)
        np.testing.assert_allclose(graph.lookup("slider", "arm"), slider_arm, atol=TOLERANCE)
        np.testing.assert_allclose(graph.lookup("base", "finger"), base_finger, atol=TOLERANCE)
        np.testing.assert_allclose(graph.lookup("finger", "arm"),
                                   se3.inverse(base_finger) @ base_slider @ slider_arm, atol=TOLERANCE)
        # each edge's own value agrees with its path
        np.testing.assert_allclose(graph.edge("slider", "wheel").transform(), slider_wheel, atol=TOLERANCE)
        np.testing.assert_allclose(graph.edge("slider", "wheel").inverse(), se3.inverse(slider_wheel),
                                   atol=TOLERANCE)
    positions = model.positions
    assert positions["elbow"] == pytest.approx(5.25) and positions["grip"] == pytest.approx(-1.9)


def test_urdf_text_and_prefixes_two_robots(small_urdf):
    graph = TransformGraph()
    left = load_urdf(graph, small_urdf, prefix="left/", joint_prefix="left_")
    right = load_urdf(graph, SMALL_URDF, prefix="right/", joint_prefix="right_")
    assert (left.name, right.name) == ("left/bench", "right/bench")
    assert left.source == small_urdf and right.source is None
    assert "left/tool" in graph.frames and "right/tool" in graph.frames and "tool" not in graph.frames
    assert left.frame_names == ["left/" + link for link in left.link_names]
    graph.add_static("world", "left/base", origin([0, 1, 0]))
    graph.add_static("world", "right/base", origin([0, -1, 0]))
    assert left.joint_names == ["left_slide", "left_spin"] and right.mimic_joints["right_grip"] == (
        "right_slide", -2.0, 0.1)
    assert graph.edge("right/slider", "right/wheel").joint == "right_spin"
    assert graph.set_joints({"left_slide": 0.5, "left_spin": 1.0, "right_slide": 0.5, "right_spin": 1.0,
                             "right_grip": 3.0}) == []
    assert right.positions == {"right_slide": 0.5, "right_spin": 1.0, "right_elbow": 0.75, "right_grip": -0.9}
    np.testing.assert_allclose(graph.lookup("right/tool", "left/tool"),
                               se3.inverse(graph.lookup("world", "right/tool")) @ graph.lookup("world", "left/tool"),
                               atol=TOLERANCE)
    # same joint values on both robots: the tools differ by the bases' offset only
    np.testing.assert_allclose(graph.lookup("right/tool", "left/tool")[:3, :3], np.eye(3), atol=TOLERANCE)
    np.testing.assert_allclose(graph.lookup("world", "left/tool")[:3, 3] - graph.lookup("world", "right/tool")[:3, 3],
                               [0, 2, 0], atol=TOLERANCE)
    np.testing.assert_allclose(left.placement("tool"), graph.lookup("left/base", "left/tool"), atol=TOLERANCE)
    with pytest.raises(TransformError, match="already has a model named 'left/bench'"):
        load_urdf(graph, small_urdf, prefix="left/")
    edges = len(graph.edges)
    with pytest.raises(TransformError, match="already joined"):
        load_urdf(graph, small_urdf, name="again", prefix="left/")
    assert len(graph.edges) == edges and "again" not in graph.models


def test_floating_joint_is_kept_fixed(caplog):
    text = SMALL_URDF.replace('<link name="finger"/>', '<link name="finger"/><link name="free"/>').replace(
        "</robot>", '<joint name="float" type="floating"><parent link="tool"/><child link="free"/>'
                    '<origin xyz="0 0 1"/></joint></robot>')
    graph = TransformGraph()
    with caplog.at_level(logging.WARNING, logger="coco.transforms"):
        model = load_urdf(graph, text)
    assert "float" in caplog.text and "kept fixed" in caplog.text
    assert graph.edge("tool", "free").kind is EdgeKind.STATIC and "float" not in model.joint_names
    np.testing.assert_allclose(graph.lookup("tool", "free"), origin([0, 0, 1]), atol=TOLERANCE)


# --- sources, package:// and errors ------------------------------------------------------------------
def make_package(prefix: Path, package: str, indexed: bool) -> Path:
    share = prefix / "share" / package
    (share / "urdf").mkdir(parents=True)
    (share / "urdf" / "bench.urdf").write_text(SMALL_URDF)
    if indexed:
        marker = prefix / "share" / "ament_index" / "resource_index" / "packages" / package
        marker.parent.mkdir(parents=True)
        marker.write_text("")
    return share / "urdf" / "bench.urdf"


@pytest.mark.parametrize("indexed", [True, False])
def test_package_url_through_ament_prefix_path(tmp_path, monkeypatch, indexed):
    path = make_package(tmp_path / "install", "my_robot_description", indexed)
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path / "install"))
    graph = TransformGraph()
    model = load_urdf(graph, "package://my_robot_description/urdf/bench.urdf")
    assert model.source == path and "tool" in graph.frames


def test_package_url_through_cmake_prefix_path(tmp_path, monkeypatch):
    path = make_package(tmp_path / "ws", "other_description", indexed=False)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    monkeypatch.setenv("CMAKE_PREFIX_PATH", str(tmp_path / "ws"))
    assert resolve("package://other_description/urdf/bench.urdf") == path


def test_package_url_of_pip_installed_data(monkeypatch, baxter_path):
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    monkeypatch.delenv("CMAKE_PREFIX_PATH", raising=False)
    url = "package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"
    assert resolve(url).samefile(baxter_path)
    # the meshes the URDF names resolve the same way
    assert resolve("package://example-robot-data/robots/baxter_description/meshes/torso/base_link.DAE").is_file()


def test_unknown_package_lists_the_places_tried(tmp_path, monkeypatch):
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path / "install"))
    with pytest.raises(ResourceNotFoundError) as caught:
        load_urdf(TransformGraph(), "package://no_such_package/urdf/robot.urdf")
    message = str(caught.value)
    assert "package://no_such_package/urdf/robot.urdf" in message
    assert str(tmp_path / "install" / "share" / "no_such_package") in message
    assert "ament index" in message and "cmeel.prefix" in message
    assert isinstance(caught.value, FileNotFoundError)
    with pytest.raises(ResourceNotFoundError, match="no_such_package"):
        package_share_directory("no_such_package")


def test_missing_file_in_a_package(tmp_path, monkeypatch):
    make_package(tmp_path / "install", "my_robot_description", indexed=True)
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path / "install"))
    with pytest.raises(ResourceNotFoundError, match=r"package://my_robot_description/urdf/nope.urdf.*"
                                                     r"does not exist"):
        load_urdf(TransformGraph(), "package://my_robot_description/urdf/nope.urdf")


def test_missing_file(tmp_path):
    missing = tmp_path / "robot.urdf"
    with pytest.raises(FileNotFoundError, match=str(missing)):
        load_urdf(TransformGraph(), missing)


def test_broken_urdf_names_the_file(tmp_path):
    broken = tmp_path / "broken.urdf"
    broken.write_text("<robot name='x'><link name='a'></robot>")
    with pytest.raises(UrdfError, match=f"{broken}.*not well-formed"):
        load_urdf(TransformGraph(), broken)
    # well-formed XML that Pinocchio (urdfdom) rejects: its explanation is part of the message
    bad_origin = tmp_path / "bad_origin.urdf"
    bad_origin.write_text(SMALL_URDF.replace('<origin xyz="1 2 3" rpy="0 0 0.3"/>', '<origin xyz="1 2"/>'))
    with pytest.raises(UrdfError) as caught:
        load_urdf(TransformGraph(), bad_origin)
    assert str(bad_origin) in str(caught.value) and "Pinocchio" in str(caught.value)
    assert "slide" in str(caught.value)  # urdfdom's "Malformed parent origin element for joint [slide]"


@pytest.mark.parametrize("change, message", [
    (("<mimic joint=\"spin\"", "<mimic joint=\"nope\""), "mimics 'nope', which is not a joint"),
    (("<mimic joint=\"spin\"", "<mimic joint=\"mount\""), "mimics 'mount', which is a fixed joint"),
    (('<parent link="base"/><child link="finger"/>', '<parent link="base"/><child link="hand"/>'),
     "child link 'hand', which is not declared"),
    (('<parent link="base"/><child link="finger"/>', '<parent link="base"/><child link="tool"/>'),
     "link tool is the child of two joints"),
    (('type="continuous"', 'type="spherical"'), "type 'spherical'"),
    (("<robot name=\"bench\">", "<robot name=\"bench\"><link name=\"stray\"/>"), "one root link"),
])
def test_wrong_structure_is_explained(change, message):
    with pytest.raises(UrdfError, match=message):
        UrdfModel.load(SMALL_URDF.replace(*change))


def test_resolve_plain_and_file_urls(small_urdf, tmp_path):
    assert resolve(str(small_urdf)) == small_urdf
    assert resolve(small_urdf.as_uri()) == small_urdf
    assert resolve("bench.urdf", relative_to=tmp_path) == small_urdf


def test_mimic_chains_and_cycles():
    chained = SMALL_URDF.replace('<mimic joint="spin" multiplier="0.5" offset="0.25"/>',
                                 '<mimic joint="grip" multiplier="0.5" offset="0.25"/>')
    graph = TransformGraph()
    model = load_urdf(graph, chained)
    graph.set_joints({"slide": 0.4})
    assert model.positions["elbow"] == pytest.approx(0.5 * (-2 * 0.4 + 0.1) + 0.25)
    np.testing.assert_allclose(graph.lookup("slider", "arm"),
                               origin([0, 0.2, 0]) @ se3.make(se3.axis_angle((0, 1, 0), -0.4 + 0.3)),
                               atol=TOLERANCE)
    cycle = SMALL_URDF.replace('<limit lower="-1" upper="1" effort="1" velocity="1"/>',
                               '<limit lower="-1" upper="1" effort="1" velocity="1"/><mimic joint="grip"/>')
    with pytest.raises(UrdfError, match="cycle: slide -> grip -> slide"):
        UrdfModel.load(cycle)


# --- visuals: read in the same parse as the kinematics ---------------------------------------------

def test_baxter_visuals_match_yourdfpy(baxter, references):
    """Every visual of the real Baxter, as yourdfpy (an independent loader) reads it: link, origin,
    geometry, mesh file and scale, and the material's colour (its own or the robot-level one it names)."""
    _, model = baxter
    robot = references[2].robot
    named = {material.name: material.color.rgba for material in robot.materials if material.color is not None}
    expected = []
    for link in robot.links:
        for visual in link.visuals:
            material = visual.material
            rgba = None if material is None else (material.color.rgba if material.color is not None
                                                  else named.get(material.name))
            geometry = visual.geometry
            mesh = geometry.mesh
            expected.append((link.name, np.eye(4) if visual.origin is None else visual.origin,
                             mesh.filename if mesh is not None else "",
                             None if mesh is None or mesh.scale is None else tuple(np.broadcast_to(mesh.scale, 3)),
                             None if rgba is None else tuple(rgba)))
    assert len(model.visuals) == len(expected) > 30
    for visual, (link, origin, filename, scale, color) in zip(model.visuals, expected):
        assert (visual.link, visual.filename, visual.scale, visual.color) == (link, filename, scale, color)
        np.testing.assert_allclose(visual.origin, origin, atol=TOLERANCE)


def test_visual_shapes_materials_and_errors():
    urdf = """<robot name="shapes">
      <material name="blue"><color rgba="0 0 1 1"/></material>
      <link name="a">
        <visual><origin xyz="1 2 3" rpy="0 0 1.5707963267948966"/><geometry><box size="1 2 3"/></geometry>
          <material name="blue"/></visual>
        <visual><geometry><sphere radius="0.5"/></geometry><material name="x"><color rgba="1 0 0 0.5"/></material>
        </visual>
        <visual><geometry><cylinder radius="0.1" length="2"/></geometry></visual>
        <visual><geometry><mesh filename="meshes/part.stl" scale="0.001"/></geometry></visual>
      </link>
    </robot>"""
    graph = TransformGraph()
    model = load_urdf(graph, urdf)
    box, sphere, cylinder, mesh = model.visuals
    assert (box.shape, box.size, box.color) == ("box", (1.0, 2.0, 3.0), (0.0, 0.0, 1.0, 1.0))
    np.testing.assert_allclose(box.origin, se3.make(se3.rpy_to_matrix(0, 0, math.pi / 2), [1, 2, 3]))
    assert (sphere.shape, sphere.size, sphere.color) == ("sphere", (0.5,), (1.0, 0.0, 0.0, 0.5))
    assert (cylinder.shape, cylinder.size, cylinder.color) == ("cylinder", (0.1, 2.0), None)
    assert (mesh.filename, mesh.scale) == ("meshes/part.stl", (0.001, 0.001, 0.001))
    assert graph.models == {"shapes": model}, "a robot of one link is a model of the graph too"
    for bad, message in [('<box size="1 2"/>', r"size='1 2' must be 3 number\(s\)"),
                         ('<mesh/>', "<mesh> has no filename"),
                         ('<cone/>', "has no <geometry> with one of mesh, box, sphere, cylinder"),
                         ('<cylinder radius="1"/>', "<cylinder> has no length")]:
        with pytest.raises(UrdfError, match=message):
            load_urdf(TransformGraph(), f'<robot name="r"><link name="a"><visual><geometry>{bad}</geometry>'
                                        "</visual></link></robot>")


def test_a_urdf_is_read_only_from_a_regular_file(tmp_path):
    """The one place a URDF is read (a display draws the model loaded here): a FIFO or a device is
    refused by name, not read until it blocks or fills the memory."""
    import os

    os.mkfifo(tmp_path / "robot.urdf")
    with pytest.raises(UrdfError, match="URDF .*robot.urdf is a FIFO, not a regular file"):
        UrdfModel.load(tmp_path / "robot.urdf")
    with pytest.raises(UrdfError, match="URDF /dev/zero is a character device, not a regular file"):
        UrdfModel.load(Path("/dev/zero"))
