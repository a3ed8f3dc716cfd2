"""GLUrdf renders the real Baxter (example-robot-data) headless, posed from the transformation graph that a
TransformationInterface fills: its silhouette is the one of yourdfpy's model (an independent URDF loader),
before and after joints move; colour overrides, simplification, background loading, missing
frames and bad input."""

from __future__ import annotations

import logging
from typing import Callable

import cv2
import numpy as np
import pytest

from conftest import project
from coco_core import Application
from coco_core.component import UnknownNameError
from coco_core.transforms.interface import TransformationInterface
from coco_core.transforms.resources import ResourceNotFoundError, resolve
from coco_mr_display.urdf import GLUrdf
from test_mesh import camera_view, draw, drawn_mask

BAXTER = "package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"
SIZE = (320, 240)
MOVED = {"left_s0": 0.7, "left_s1": -0.9, "left_e1": 1.6, "left_w1": 1.0}
"""Left arm raised and bent (Baxter's left is +y: the right half of the image from the camera below).

The camera looks at the upper body from the front left, where the visuals' origins and scales show
(drawing every visual at its link origin leaves 10x more pixels wrong than the threshold allows)."""


@pytest.fixture(scope="module")
def baxter_path():
    pytest.importorskip("collada", reason="Baxter's meshes are DAE files, read through pycollada")
    pytest.importorskip("pinocchio", reason="the graph computes Baxter's kinematics with Pinocchio")
    try:
        return resolve(BAXTER)
    except ResourceNotFoundError as error:
        pytest.skip(f"example-robot-data is not installed: {error}")


@pytest.fixture(scope="module")
def reference(baxter_path):
    """yourdfpy's own model of Baxter with its meshes: the independent answer."""
    yourdfpy = pytest.importorskip("yourdfpy")
    return yourdfpy.URDF.load(str(baxter_path), filename_handler=lambda fname: str(resolve(fname, baxter_path.parent)))


@pytest.fixture
def robot(baxter_path, gl_context, framebuffer):
    """``robot(**attributes)``: a GLUrdf in an application whose TransformationInterface loaded Baxter;
    returns (the peer, the application, draw one frame)."""
    app = Application("urdf-test")
    app.add(TransformationInterface("tf", urdf=BAXTER))
    fbo = framebuffer(*SIZE)
    view = camera_view([1.6, 0.8, 1.0], [0.0, 0.0, 0.4], SIZE, up=(0, 0, 1), frame="base")
    made: list[GLUrdf] = []

    def make(**attributes) -> tuple[GLUrdf, Application, Callable[[], tuple[np.ndarray, np.ndarray]]]:
        """The peer, its application, and ``frame()``: draw one frame, return (RGB image, silhouette)."""
        peer = GLUrdf(f"baxter{len(made)}", **attributes)
        app.add(peer)
        assert peer.configure(), "GLUrdf failed to configure (see the log)"
        peer.gl_init(gl_context)
        made.append(peer)
        return peer, app, lambda: (draw(gl_context, fbo, view, peer), drawn_mask(fbo))

    make.view = view
    make.app = app
    yield make
    for peer in made:
        peer.on_stop()
        peer.gl_release()


def assert_silhouette(mask: np.ndarray, reference, view, configuration: dict[str, float]) -> None:
    """``mask`` is the union of yourdfpy's posed visual triangles, projected and filled by OpenCV: the
    two may differ on the outline (within a pixel), where rasterisation rules differ, and on a few
    sub-pixel slivers (panels seen edge-on, gaps between parts) that OpenCV fills and GL does not."""
    reference.update_cfg({name: configuration.get(name, 0.0) for name in reference.actuated_joint_names})
    mesh = reference.scene.to_geometry()
    pixels = project(view, mesh.vertices, SIZE[1])
    triangles = np.round((pixels[mesh.faces] - 0.5) * 16).astype(np.int32)  # 4 bits of sub-pixel precision
    expected = np.zeros(mask.shape, np.uint8)
    cv2.fillPoly(expected, list(triangles), 1, lineType=cv2.LINE_8, shift=4)
    kernel = np.ones((3, 3), np.uint8)
    outline = cv2.dilate(expected, kernel).astype(bool) & ~cv2.erode(expected, kernel).astype(bool)
    wrong = np.logical_xor(mask, expected.astype(bool)) & ~outline
    assert expected.sum() > 5000, "the test view should show the robot large"
    assert wrong.sum() < 0.002 * expected.sum(), f"{wrong.sum()} of {expected.sum()} pixels differ away from the " \
        f"outline, e.g. at {np.argwhere(wrong)[:5].tolist()}"


def test_baxter_silhouette_matches_yourdfpy_and_changes_when_a_joint_moves(robot, reference):
    peer, app, frame = robot()
    if not peer.loaded:
        assert not frame()[1].any(), "nothing is drawn (and nothing waits) before the meshes are read"
    peer.wait_loaded(timeout=120)
    rest = frame()[1]
    assert peer.triangles > 400_000, "every visual of Baxter is drawn"
    assert_silhouette(rest, reference, robot.view, {})
    app.transforms.set_joints(MOVED)
    moved = frame()[1]
    assert_silhouette(moved, reference, robot.view, MOVED)
    changed = np.logical_xor(rest, moved)
    assert changed.sum() > 1000, "the left arm moved"
    assert changed[:, SIZE[0] // 2:].sum() > 0.95 * changed.sum(), "only the left arm (image right) moved"
    app.transforms.set_joints({name: 0.0 for name in MOVED})
    assert (frame()[1] == rest).all(), "back at rest, the same pixels"


def test_link_colour_override_and_default_colour(robot):
    plain, _, frame = robot()
    plain.wait_loaded(timeout=120)
    image = frame()[0]
    green = (image[..., 1] > 100) & (image[..., 0] < 40) & (image[..., 2] < 40)
    assert green.sum() == 0
    coloured, _, frame = robot(colors="left_upper_shoulder=0 1 0, right_upper_shoulder=0 1 0 1",
                               ambient=1.0, diffuse=0.0, specular=0.0)
    coloured.wait_loaded(timeout=120)
    image = frame()[0]
    green = np.all(image == (0, 255, 0), axis=2)
    assert green.sum() > 200, "both upper shoulders are drawn in the override colour"
    assert green[:, :SIZE[0] // 2].sum() > 50 and green[:, SIZE[0] // 2:].sum() > 50


def test_simplified_baxter_keeps_its_silhouette(robot):
    full, _, frame_full = robot()
    light, _, frame_light = robot(simplify=0.25)
    full.wait_loaded(timeout=120)
    light.wait_loaded(timeout=120)
    a, b = frame_full()[1], frame_light()[1]
    assert light.triangles < 0.3 * full.triangles
    assert np.logical_xor(a, b).sum() < 0.08 * a.sum()


def test_frames_missing_from_the_graph_are_reported_once(robot, caplog):
    """A second Baxter, loaded with a frame prefix and joined to nothing, is named by the robot
    attribute: its links cannot be placed in the view's frame."""
    robot.app.add(TransformationInterface("tf2", urdf=BAXTER, prefix="other/"))
    peer, _, frame = robot(robot="other/baxter")
    peer.wait_loaded(timeout=120)
    with caplog.at_level(logging.WARNING, logger="coco.display"):
        assert not frame()[1].any()
        frame()
    warnings = [record for record in caplog.records if "not drawn until" in record.getMessage()]
    assert len(warnings) == 1, "reported once, not every frame"
    assert "other/left_upper_shoulder" in warnings[0].getMessage()
    assert peer.enabled


def test_bad_input_gives_clear_errors(baxter_path, tmp_path):
    app = Application("urdf-errors")
    with pytest.raises(UnknownNameError, match=r"has no URDF model 'baxter': load it with a TransformationInterface"):
        app.add(GLUrdf("alone", robot="baxter")).on_config()
    app.add(TransformationInterface("tf", urdf=BAXTER))
    app.add(TransformationInterface("tf2", urdf=BAXTER, prefix="other/"))
    with pytest.raises(UnknownNameError, match=r"has 2 URDF models: name one with the robot attribute; "
                                               r"valid: baxter, other/baxter"):
        app.add(GLUrdf("which")).on_config()
    with pytest.raises(UnknownNameError, match=r"no URDF model 'baxtr'.*did you mean 'baxter'\?"):
        app.add(GLUrdf("typo", robot="baxtr")).on_config()
    unknown = app.add(GLUrdf("unknown", robot="baxter", colors="left_upper_shouldr=1 0 0"))
    with pytest.raises(UnknownNameError, match=r"colors names link 'left_upper_shouldr', which robot baxter does "
                                               r"not have; did you mean 'left_upper_shoulder'\? valid: .*torso"):
        unknown.on_config()
    with pytest.raises(ValueError, match=r"must look like link=r g b \[a\]"):
        GLUrdf("syntax", colors="left_upper_shoulder=red")


def broken_robot(tmp_path, mesh: str) -> str:
    """A one-link URDF whose visual is ``meshes/<mesh>``, relative to the URDF."""
    path = tmp_path / "broken.urdf"
    path.write_text(f'<robot name="broken"><link name="a"><visual><geometry><mesh filename="meshes/{mesh}"/>'
                    "</geometry></visual></link></robot>")
    return str(path)


def test_a_missing_mesh_file_is_named_at_configuration(tmp_path):
    app = Application("urdf-missing-mesh")
    app.add(TransformationInterface("tf", urdf=broken_robot(tmp_path, "gone.stl")))
    with pytest.raises(ResourceNotFoundError, match=r"meshes/gone\.stl does not exist"):
        app.add(GLUrdf("broken")).on_config()


def test_preload_reads_the_meshes_while_the_application_is_built(robot):
    """With preload the meshes are read in init(): the first frame after configuration shows the robot."""
    peer, _, frame = robot(preload=True, simplify=0.25)
    assert peer.loaded, "preload must have read the meshes before the application starts"
    _, mask = frame()
    assert mask.sum() > 5000, "the first frame after a preload shows the robot"


def test_a_mesh_file_is_read_once_per_process_until_it_changes(tmp_path):
    """Two peers drawing the same robot share the parts read from its mesh files (read-only: neither can
    change what the other draws); a file changed since is read again."""
    import os
    import threading

    from coco_core.transforms.urdf import UrdfModel
    from coco_mr_display.urdf import load_links, mesh_paths

    (tmp_path / "meshes").mkdir()
    mesh = tmp_path / "meshes" / "part.stl"
    import trimesh
    trimesh.creation.box(extents=(1.0, 1.0, 1.0)).export(mesh)
    model = UrdfModel.load(broken_robot(tmp_path, "part.stl"))

    def load():
        return load_links(model.visuals, mesh_paths(model), (0.5, 0.5, 0.5, 1.0), 1.0, threading.Event())

    first, second = load(), load()
    assert [part for parts in first.values() for part in parts] == [part for parts in second.values() for part in parts]
    part = next(iter(first.values()))[0]
    assert len(part.indices) == 12 and not part.positions.flags.writeable
    trimesh.creation.icosphere(subdivisions=1).export(mesh)
    os.utime(mesh, ns=(mesh.stat().st_atime_ns, mesh.stat().st_mtime_ns + 1_000_000_000))
    assert len(next(iter(load().values()))[0].indices) == 80, "a changed file is read again"


def test_the_parts_kept_in_a_process_stay_within_their_bound():
    """A long run that loads many models (or one whose files change) let the parts kept in the
    process grow without end; the least recently used now go first beyond the bound."""
    from pathlib import Path

    from coco_mr_display.mesh import MeshPart
    from coco_mr_display.urdf import LoadedParts

    def parts(vertices: int) -> list[MeshPart]:
        return [MeshPart(np.zeros((vertices, 3), np.float32), np.zeros((0, 3), np.uint32))]

    def key(name: str):
        return (Path(name), 1, 1, b"", None, (1.0, 1.0, 1.0, 1.0), 1.0)

    kept = LoadedParts(limit=3 * 1200)  # three parts of 100 vertices (1,200 bytes each)
    for name in "abc":
        kept.put(key(name), parts(100))
    assert kept.get(key("a")) is not None  # used again: "b" is now the least recently used
    kept.put(key("d"), parts(100))
    assert kept.get(key("b")) is None and len(kept) == 3
    assert all(kept.get(key(name)) is not None for name in "acd")
    kept.put(key("e"), parts(1000))  # larger than the bound alone: kept, everything else let go
    assert len(kept) == 1 and kept.get(key("e")) is not None


def test_coco_mesh_cache_keeps_the_parts_for_the_next_process(tmp_path, monkeypatch):
    """With COCO_MESH_CACHE the parts a process made are written there, whole, and another process
    reads them instead of the file: here an entry replaced by one triangle is what it draws."""
    import subprocess
    import sys
    import threading

    import trimesh

    from coco_core.transforms.urdf import UrdfModel
    from coco_mr_display import mesh_cache
    from coco_mr_display.mesh import MeshPart
    from coco_mr_display.urdf import load_links, mesh_paths

    (tmp_path / "meshes").mkdir()
    trimesh.creation.box(extents=(1.0, 1.0, 1.0)).export(tmp_path / "meshes" / "part.stl")
    urdf = broken_robot(tmp_path, "part.stl")
    cache = tmp_path / "cache"
    monkeypatch.setenv(mesh_cache.ENVIRONMENT, str(cache))
    model = UrdfModel.load(urdf)
    made = next(iter(load_links(model.visuals, mesh_paths(model), (0.5, 0.5, 0.5, 1.0), 1.0,
                                threading.Event()).values()))[0]
    entries = list(cache.iterdir())
    assert len(entries) == 1 and entries[0].suffix == ".npz", entries  # no partial file left
    kept = mesh_cache.read(entries[0])
    assert kept is not None and len(kept) == 1
    assert all(np.array_equal(getattr(kept[0], name), getattr(made, name)) for name in ("positions", "indices", "colors"))
    triangle = MeshPart(made.positions[:3].copy(), np.array([[0, 1, 2]], dtype="u4"), made.colors[:3].copy())
    mesh_cache.write(entries[0], [triangle])
    other = subprocess.run(
        [sys.executable, "-c",
         "import sys, threading\n"
         "from coco_core.transforms.urdf import UrdfModel\n"
         "from coco_mr_display.urdf import load_links, mesh_paths\n"
         "model = UrdfModel.load(sys.argv[1])\n"
         "links = load_links(model.visuals, mesh_paths(model), (0.5, 0.5, 0.5, 1.0), 1.0, threading.Event())\n"
         "print(sum(len(part.indices) for parts in links.values() for part in parts))\n", urdf],
        capture_output=True, text=True, timeout=60)
    assert other.returncode == 0, other.stderr
    assert other.stdout.split() == ["1"], other.stdout
    monkeypatch.delenv(mesh_cache.ENVIRONMENT)
    assert mesh_cache.entry(("anything",)) is None


def test_preload_reports_a_bad_mesh_when_the_application_is_built(tmp_path):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "bad.stl").write_bytes(b"solid nothing but words")
    app = Application("urdf-preload")
    app.add(TransformationInterface("tf", urdf=broken_robot(tmp_path, "bad.stl")))
    with pytest.raises(Exception, match=r"bad\.stl"):
        app.add(GLUrdf("broken", preload=True))


def test_wait_for_joints_draws_nothing_before_the_first_joint_state(robot):
    """The graph holds Baxter at its all-zero pose until a joint state arrives: with wait_for_joints
    that pose is not drawn (every Baxter link is placed by the model), and the first joint state shows it."""
    peer, app, frame = robot(wait_for_joints=True, simplify=0.25)
    peer.wait_loaded(timeout=120)
    _, before = frame()
    app.transforms.set_joints(MOVED)
    _, after = frame()
    assert after.sum() > 5000, "after a joint state the robot is drawn"
    assert before.sum() == 0, "the all-zero pose loaded at start is not drawn"


def test_the_joint_state_a_frame_shows_first_is_its_input_origin(robot):
    """A joint state written with its stamp (as TransformationInterface does) reaches GLUrdf's ``shown``
    once: the frame that first draws it reports it, the next frame (nothing new) does not."""
    from coco_core.stamps import Stamp

    peer, app, frame = robot(simplify=0.25)
    peer.wait_loaded(timeout=120)
    frame()
    peer.shown.take()  # the all-zero pose the graph holds at start has no stamp anyway
    cause = Stamp.now(5, "/robot/joint_states")
    app.transforms.set_joints(MOVED, cause=cause)
    frame()
    assert peer.shown.take() is cause
    frame()
    assert peer.shown.take() is None
