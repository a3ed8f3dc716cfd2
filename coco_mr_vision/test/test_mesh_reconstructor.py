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
from coco_mr_vision.mesh_kernel import depth_grid, fill_small_holes  # noqa: E402
from coco_mr_vision.mesh_reconstructor import MeshReconstructor  # noqa: E402
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
    holed[0:2, 0:4] = np.nan  # 4 wide: too large for 3
    filled, labels = np.empty_like(holed), np.empty(holed.shape, np.int32)
    assert depth_grid(holed, np.float32(1.0), np.float32(0.1), np.float32(10.0), filled, labels) == 9 + 8
    runs = np.empty((holed.size, 3), np.int32)
    assert fill_small_holes(filled, labels, 3, runs, np.empty(holed.size, np.int32)) == 9
    assert np.isnan(filled[0:2, 0:4]).all()
    filled[0:2, 0:4] = depth[0:2, 0:4]
    assert np.isfinite(filled).all() and np.abs(filled - depth).max() < 0.01


def _filled_by_opencv(depth: np.ndarray, hole_size: int) -> tuple[np.ndarray, int]:
    """The reference for the run-based hole filling: OpenCV's 8-connected components of the missing
    depth pick the regions whose bounding box fits, each of their pixels gets the mean of the known
    depth in its window (clipped at the border)."""
    missing = ~np.isfinite(depth)
    _, labels, stats, _ = cv2.connectedComponentsWithStats(missing.astype(np.uint8), connectivity=8)
    small = (stats[:, cv2.CC_STAT_WIDTH] <= hole_size) & (stats[:, cv2.CC_STAT_HEIGHT] <= hole_size)
    small[0] = False  # label 0: the known depth
    filled = depth.copy()
    chosen = np.nonzero(small[labels] & missing)
    for r, c in zip(*chosen):
        window = depth[max(r - hole_size, 0):r + hole_size + 1, max(c - hole_size, 0):c + hole_size + 1]
        known = window[np.isfinite(window)]
        filled[r, c] = known.mean() if known.size else np.nan
    return filled, len(chosen[0])


@pytest.mark.parametrize("seed", range(6))
def test_hole_filling_finds_the_regions_opencv_finds(seed):
    rng = np.random.default_rng(seed)
    rows, cols = rng.integers(8, 70, 2)
    depth = rng.uniform(1.0, 2.0, (rows, cols)).astype(np.float32)
    depth[rng.random((rows, cols)) < rng.uniform(0.05, 0.6)] = np.nan  # from specks to large regions
    hole_size = int(rng.integers(1, 6))
    filled, labels = np.empty_like(depth), np.empty(depth.shape, np.int32)
    depth_grid(depth, np.float32(1.0), np.float32(0.1), np.float32(10.0), filled, labels)
    runs = rows * ((cols + 1) // 2)
    count = fill_small_holes(filled, labels, hole_size, np.empty((runs, 3), np.int32), np.empty(runs, np.int32))
    expected, expected_count = _filled_by_opencv(depth, hole_size)
    assert count == expected_count
    np.testing.assert_allclose(filled, expected, rtol=1e-6, equal_nan=True)


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


def test_only_the_newest_waiting_frame_is_meshed_the_older_count_as_dropped():
    camera, reconstructor, viewer = rig()
    connection = camera.rgbd.connections[0]
    for depth in (1.0, 2.0, 3.0):
        camera.rgbd.write(frame_of(np.full((48, 64), depth)))
    reconstructor.on_update()
    status, slot = viewer.mesh.read()
    assert status is NEW_DATA and np.allclose(TriangleMesh.from_slot(slot).vertices[:, 2], 3.0)
    assert reconstructor.frames == 1
    assert connection.dropped == 2, "the two older frames show in the profile's dropped column"


def test_bands_on_helper_threads_give_the_same_mesh():
    """Rows meshed as bands on several threads: the same vertices, normals, colours and triangles, in
    the same order, as one thread (a steep slope with holes, so that triangles are cut and holes
    filled on both sides of the band boundaries)."""
    rows, cols = 240, 320
    depth = np.tile(np.linspace(0.8, 3.0, cols, dtype=np.float32), (rows, 1)) + np.linspace(0, 0.5, rows)[:, None]
    rng = np.random.default_rng(7)
    depth[rng.random((rows, cols)) < 0.08] = np.nan
    depth[100:160, 40:90] = np.nan
    depth[:, 200:] += 0.6  # a step: cells cut along it
    frame = frame_of(depth, CameraIntrinsics(cols, rows, 300.0, 300.0, 159.5, 119.5))
    meshes = {}
    for threads in (1, 2, 3):
        mesh, slot, reconstructor = mesh_of(frame, threads=threads)
        meshes[threads] = (mesh, slot)
        reconstructor.on_stop()
    one = meshes[1][0]
    assert len(one.triangles) > rows * cols  # the cut and the holes leave most cells
    for threads in (2, 3):
        mesh = meshes[threads][0]
        assert np.array_equal(mesh.vertices, one.vertices) and np.array_equal(mesh.normals, one.normals)
        assert np.array_equal(mesh.colors, one.colors) and np.array_equal(mesh.triangles, one.triangles)


def test_a_frame_without_intrinsics_is_refused_clearly():
    camera, reconstructor, _ = rig()
    frame = frame_of(np.ones((48, 64)))
    camera.rgbd.write(RGBDFrame(frame.color, Image(frame.depth.data, ImageFormat.DEPTH32F)))
    with pytest.raises(ValueError, match="no intrinsics"):
        reconstructor.on_update()


# --- the compiled passes against the whole-array numpy version they replaced --------------------

def _grid_differences(planes: tuple[np.ndarray, ...], known: np.ndarray, axis: int) -> list[np.ndarray]:
    """Differences of neighbouring grid points along ``axis`` for each coordinate plane: central where
    both neighbours are known, else forward, else backward (NaN when neither is)."""
    ahead = np.zeros_like(known)
    behind = np.zeros_like(known)
    inner = (slice(None), slice(1, -1)) if axis == 1 else (slice(1, -1), slice(None))
    after = (slice(None), slice(2, None)) if axis == 1 else (slice(2, None), slice(None))
    before = (slice(None), slice(None, -2)) if axis == 1 else (slice(None, -2), slice(None))
    head = (slice(None), slice(0, 1)) if axis == 1 else (slice(0, 1), slice(None))
    head_next = (slice(None), slice(1, 2)) if axis == 1 else (slice(1, 2), slice(None))
    tail = (slice(None), slice(-1, None)) if axis == 1 else (slice(-1, None), slice(None))
    tail_prev = (slice(None), slice(-2, -1)) if axis == 1 else (slice(-2, -1), slice(None))
    ahead[inner], ahead[head] = known[after], known[head_next]
    behind[inner], behind[tail] = known[before], known[tail_prev]
    both, only_ahead = ahead & behind, ahead & ~behind
    out = []
    for plane in planes:
        step = np.diff(plane, axis=axis)  # step[i] = p[i+1] - p[i]
        pad = np.zeros_like(np.take(plane, [0], axis=axis))
        forward = np.concatenate([step, pad], axis=axis)
        backward = np.concatenate([pad, step], axis=axis)
        out.append(np.where(both, 0.5 * (forward + backward), np.where(only_ahead, forward, backward)))
    return out



def _normals(x: np.ndarray, y: np.ndarray, z: np.ndarray, known: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit normal planes from grid differences (central where both neighbours exist, else
    one-sided), turned towards the camera; with no neighbour at all, the direction back to it.
    Works plane by plane in float32: a third of the memory traffic of Nx3 rows."""
    dx = _grid_differences((x, y, z), known, axis=1)
    dy = _grid_differences((x, y, z), known, axis=0)
    nx = dx[1] * dy[2] - dx[2] * dy[1]
    ny = dx[2] * dy[0] - dx[0] * dy[2]
    nz = dx[0] * dy[1] - dx[1] * dy[0]
    length = np.sqrt(nx * nx + ny * ny + nz * nz)
    with np.errstate(invalid="ignore", divide="ignore"):
        # Facing the camera: the normal and the point (the ray from the camera) point opposite ways.
        sign = np.where(nx * x + ny * y + nz * z > 0, -1.0, 1.0).astype(np.float32) / length
        bad = ~np.isfinite(sign)
        distance = np.sqrt(x * x + y * y + z * z)
        nx, ny, nz = nx * sign, ny * sign, nz * sign
        for normal, coordinate in ((nx, x), (ny, y), (nz, z)):
            normal[bad] = -coordinate[bad] / distance[bad]
    return nx, ny, nz

def _triangles(depth: np.ndarray, valid: np.ndarray, index: np.ndarray, limit: float) -> np.ndarray:
    a, b = index[:-1, :-1], index[:-1, 1:]
    c, d = index[1:, :-1], index[1:, 1:]
    za, zb, zc, zd = depth[:-1, :-1], depth[:-1, 1:], depth[1:, :-1], depth[1:, 1:]
    va, vb, vc, vd = valid[:-1, :-1], valid[:-1, 1:], valid[1:, :-1], valid[1:, 1:]
    with np.errstate(invalid="ignore"):
        near1 = np.fmin(np.fmin(za, zc), zb)
        far1 = np.fmax(np.fmax(za, zc), zb)
        near2 = np.fmin(np.fmin(zb, zc), zd)
        far2 = np.fmax(np.fmax(zb, zc), zd)
        keep1 = va & vb & vc & (far1 - near1 <= limit * near1)
        keep2 = vb & vc & vd & (far2 - near2 <= limit * near2)
    # Image rows grow downwards and the camera looks along +z: (a, c, b) is counter-clockwise as
    # the camera sees it, so the triangles face the camera.
    # Cell by cell, row-major, its first triangle before its second.
    cells = np.stack([np.stack([a, c, b], axis=-1), np.stack([b, c, d], axis=-1)], axis=2)
    return cells[np.stack([keep1, keep2], axis=-1)].astype(np.int32)


def numpy_mesh(depth: np.ndarray, ray_x: np.ndarray, ray_y: np.ndarray, rgb: np.ndarray, limit: float):
    """(vertices, normals, colours, triangles) as MeshReconstructor computed them with numpy."""
    x, y = ray_x * depth, ray_y * depth
    valid = np.isfinite(depth)
    index = np.cumsum(valid.ravel(), dtype=np.int32).reshape(depth.shape) - 1
    vertices = np.stack([x[valid], y[valid], depth[valid]], axis=-1)
    normals = np.stack([plane[valid] for plane in _normals(x, y, depth, valid)], axis=-1)
    return vertices, normals, rgb[valid], _triangles(depth, valid, index, limit)


@pytest.mark.parametrize("scene", ["step", "redwood"])
def test_compiled_passes_match_the_numpy_version(scene):
    if scene == "step":
        depth = np.full((48, 64), 1.0, np.float32)
        depth[:, 32:] = 1.5
        depth[10:13, 5:9] = np.nan  # a hole: one-sided differences around it
        depth[0, 0] = np.nan
        frame = frame_of(depth)
    else:
        if not REDWOOD.exists():
            pytest.skip(f"{REDWOOD} is absent")
        intrinsics = CameraIntrinsics.from_json(REDWOOD / "camera_primesense.json")
        frame = RGBDFrame.load(REDWOOD / "color" / "00000.jpg", REDWOOD / "depth" / "00000.png", intrinsics)
    mesh, _, reconstructor = mesh_of(frame, hole_size=0)
    depth = np.where(frame.depth_metres() >= 0.1, frame.depth_metres(), np.nan).astype(np.float32)
    ray_x, ray_y = reconstructor._ray_grid(frame, *depth.shape)
    vertices, normals, colors, triangles = numpy_mesh(depth, ray_x, ray_y, frame.color.to(ImageFormat.RGB8).data,
                                                      reconstructor.discontinuity)
    np.testing.assert_allclose(mesh.vertices, vertices, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(mesh.normals, normals, atol=2e-5)
    assert np.array_equal(mesh.colors, colors)
    assert np.array_equal(mesh.triangles, triangles)


def test_the_meshing_passes_are_compiled_when_the_component_is_configured():
    """Before the start gate opens, not at the first frame: a fresh process that only configures a
    MeshReconstructor holds the compiled passes (from numba's cache, or compiled then)."""
    import subprocess
    import sys

    probe = ("from coco_core import Application\n"
             "from coco_mr_vision.mesh_reconstructor import MeshReconstructor\n"
             "from coco_mr_vision.mesh_kernel import depth_grid, mesh_rows\n"
             "mesher = MeshReconstructor('mesher', stride=2)\n"
             "Application('probe').add(mesher)\n"
             "assert mesher.configure()\n"
             "print(len(depth_grid.signatures), len(mesh_rows.signatures))\n")
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    grids, rows = (int(word) for word in result.stdout.split())
    assert grids >= 2 and rows >= 1, "the depth grid for both depth encodings, the mesh rows"
