"""MeshReconstructor: geometry of known surfaces (a plane, a step), hole filling, stride, normals,
the pooled output, PLY export read back by trimesh, and a real Redwood RGB-D frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

from coco_core import Application, Component, InputPort, NEW_DATA, OutputPort, Slot  # noqa: E402
from coco_mr_vision.image import CameraIntrinsics, Image, ImageFormat  # noqa: E402
from coco_mr_vision.mesh import TriangleMesh  # noqa: E402
from coco_mr_vision.mesh_reconstructor import MeshReconstructor, fill_small_holes  # noqa: E402
from coco_mr_vision.rgbd import RGBDFrame  # noqa: E402

REDWOOD = Path(__file__).resolve().parents[3] / "shared" / "data" / "rgbd" / "redwood"
K = CameraIntrinsics(64, 48, 60.0, 60.0, 31.5, 23.5)


class Camera(Component):
    rgbd = OutputPort(object)


class Viewer(Component):
    mesh = InputPort(Slot)


def rig(**attributes):
    app = Application("mesh")
    camera = app.add(Camera("camera"))
    reconstructor = app.add(MeshReconstructor("mesher", **attributes))
    viewer = app.add(Viewer("viewer"))
    app.connect(camera.rgbd, reconstructor.rgbd)
    app.connect(reconstructor.mesh, viewer.mesh)
    return camera, reconstructor, viewer


def frame_of(depth_m: np.ndarray, intrinsics: CameraIntrinsics = K) -> RGBDFrame:
    height, width = depth_m.shape
    color = np.zeros((height, width, 3), np.uint8)
    color[..., 2] = 200  # BGR: red
    color[:, : width // 2, 0] = 100
    return RGBDFrame(Image(color, ImageFormat.BGR8, 5.0, "cam"), Image(depth_m.astype(np.float32), ImageFormat.DEPTH32F,
                                                                      5.0, "cam"), intrinsics)


def mesh_of(frame: RGBDFrame, **attributes):
    camera, reconstructor, viewer = rig(**attributes)
    camera.rgbd.write(frame)
    reconstructor.on_update()
    status, slot = viewer.mesh.read()
    assert status is NEW_DATA
    return TriangleMesh.from_slot(slot), slot, reconstructor


def test_a_plane_gives_a_full_grid_on_the_plane_facing_the_camera():
    mesh, slot, _ = mesh_of(frame_of(np.full((48, 64), 2.0)))
    assert len(mesh.vertices) == 48 * 64 and len(mesh.triangles) == 2 * 47 * 63
    assert np.allclose(mesh.vertices[:, 2], 2.0)
    # Pixel (row 10, col 20) back-projects through the pinhole.
    assert np.allclose(mesh.vertices[10 * 64 + 20], [(20 - 31.5) / 60 * 2, (10 - 23.5) / 60 * 2, 2.0])
    assert np.allclose(mesh.normals, [0, 0, -1], atol=1e-5)
    a, b, c = (mesh.vertices[mesh.triangles[:, i]] for i in range(3))
    face_normals = np.cross(b - a, c - a)
    assert (face_normals[:, 2] < 0).all(), "counter-clockwise as the camera sees them: facing it"
    assert mesh.colors[0].tolist() == [200, 0, 100] and mesh.colors[-1].tolist() == [200, 0, 0]
    assert slot.stamp.image_stamp == 5.0 and slot.stamp.frame_id == "cam"


def test_a_depth_step_is_cut_not_bridged():
    depth = np.full((48, 64), 1.0)
    depth[:, 32:] = 3.0
    mesh, _, _ = mesh_of(frame_of(depth))
    assert len(mesh.vertices) == 48 * 64
    assert len(mesh.triangles) == 2 * 47 * 63 - 2 * 47, "the column of cells across the step is cut"
    z = mesh.vertices[mesh.triangles][..., 2]
    assert (z.max(axis=1) - z.min(axis=1)).max() == 0
    mesh, _, _ = mesh_of(frame_of(depth), discontinuity=5.0)
    assert len(mesh.triangles) == 2 * 47 * 63, "a loose threshold keeps the rubber sheet"


def test_small_holes_are_filled_large_ones_stay_open():
    depth = np.full((48, 64), 2.0)
    depth[10:13, 10:13] = np.nan   # 3x3: filled
    depth[20:40, 30:50] = 0.0      # 20x20: stays a hole (0 is unknown, like NaN)
    mesh, _, _ = mesh_of(frame_of(depth), hole_size=4)
    assert len(mesh.vertices) == 48 * 64 - 400
    assert np.allclose(mesh.vertices[:, 2], 2.0)
    mesh, _, _ = mesh_of(frame_of(depth), hole_size=0)
    assert len(mesh.vertices) == 48 * 64 - 409


def test_fill_small_holes_interpolates_a_slope():
    depth = np.tile(np.linspace(1.0, 2.0, 40, dtype=np.float32), (30, 1))
    holed = depth.copy()
    holed[14:17, 19:22] = np.nan
    filled = fill_small_holes(holed, 3)
    assert np.isfinite(filled).all() and np.abs(filled - depth).max() < 0.01


def test_stride_and_reuse_of_the_pool_buffers():
    camera, reconstructor, viewer = rig(stride=2)
    buffers = set()
    for _ in range(5):
        camera.rgbd.write(frame_of(np.full((48, 64), 1.5)))
        reconstructor.on_update()
        status, slot = viewer.mesh.read()
        mesh = TriangleMesh.from_slot(slot)
        assert len(mesh.vertices) == 24 * 32 and np.allclose(mesh.vertices[1, 0] - mesh.vertices[0, 0], 2 / 60 * 1.5)
        buffers.add(id(slot.array))
        slot.release()
    assert len(buffers) <= 3, "a steady stream reuses the pool's buffers"
    assert reconstructor.frames == 5


def test_real_redwood_frame_and_ply_export(tmp_path):
    if not REDWOOD.exists():
        pytest.skip(f"{REDWOOD} is absent")
    trimesh = pytest.importorskip("trimesh")
    intrinsics = CameraIntrinsics.from_json(REDWOOD / "camera_primesense.json")
    frame = RGBDFrame.load(REDWOOD / "color" / "00000.jpg", REDWOOD / "depth" / "00000.png", intrinsics)
    mesh, _, reconstructor = mesh_of(frame)
    valid = np.count_nonzero(frame.depth.data)
    assert len(mesh.vertices) >= valid * 0.95 and len(mesh.triangles) > len(mesh.vertices) * 1.5
    # Every vertex is where its pixel's depth says: project back to the image.
    u = mesh.vertices[:, 0] / mesh.vertices[:, 2] * 525 + 319.5
    assert u.min() > -0.5 and u.max() < 639.5
    assert np.allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-4)
    path = reconstructor.export_ply(str(tmp_path / "frame.ply"))
    loaded = trimesh.load(path, process=False)
    assert np.allclose(loaded.vertices, mesh.vertices, atol=1e-6)
    assert np.array_equal(loaded.faces, mesh.triangles)
    assert np.array_equal(loaded.visual.vertex_colors[:, :3], mesh.colors)


def test_a_frame_without_intrinsics_is_refused_clearly():
    camera, reconstructor, _ = rig()
    frame = frame_of(np.ones((48, 64)))
    camera.rgbd.write(RGBDFrame(frame.color, Image(frame.depth.data, ImageFormat.DEPTH32F)))
    with pytest.raises(ValueError, match="no intrinsics"):
        reconstructor.on_update()
