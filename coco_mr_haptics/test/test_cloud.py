"""KDTreeBuilder and HapticCloud: structures and filters, agreement with HapticImplicitSurf on clouds
sampled from the same shapes, and strokes over real RGB-D frames through a structure swap."""

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial import cKDTree

from coco_core.application import Application
from coco_core.component import Component
from coco_core.errors import CocoError, StructureError
from coco_core.policy import BufferPolicy, ConnectionPolicy
from coco_core.ports import InputPort, OutputPort
from coco_mr_haptics.cloud import HapticCloud, KDTreeBuilder
from coco_mr_haptics.implicit_surf import HapticImplicitSurf
from coco_mr_vision.image import CameraIntrinsics
from coco_mr_vision.pointcloud import PointCloud

FX = FY = 525.0
CX, CY = 319.5, 239.5
RGBD = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "rgbd"


def rays(width=640, height=480):
    u, v = np.meshgrid(np.arange(width), np.arange(height))
    return np.stack([(u - CX) / FX, (v - CY) / FY, np.ones(u.shape)], axis=-1).reshape(-1, 3)


def plane_cloud(normal, point):
    """The organised cloud a pinhole camera at the origin sees of the plane through ``point``."""
    d = rays()
    t = (normal @ point) / (d @ normal)
    return PointCloud((d * t[:, None]).astype(np.float32), organized=(480, 640))


def sphere_cloud(centre, radius):
    d = rays()
    a = (d * d).sum(axis=1)
    b = -2 * d @ centre
    c = centre @ centre - radius * radius
    disc = b * b - 4 * a * c
    t = np.where(disc >= 0, (-b - np.sqrt(np.maximum(disc, 0))) / (2 * a), np.nan)
    return PointCloud((d * t[:, None]).astype(np.float32), organized=(480, 640))


def renderers(surface, cloud, kind, **material):
    app = Application("cloud_test")
    builder = KDTreeBuilder("builder", structure_kind=kind)
    cloud_renderer = HapticCloud("cloud", support=0.01, **material)
    implicit = HapticImplicitSurf("implicit", surface=surface, **material)
    for component in (builder, cloud_renderer, implicit):
        app.add(component)
    app.connect("builder.structure", "cloud.structure")
    for component in (builder, cloud_renderer, implicit):
        component.configure()
    builder.structure.write(builder.build(cloud))
    cloud_renderer.prepare()
    return builder, cloud_renderer, implicit


def stroke(start, inward, tangent, depth, length, steps_in=60, steps_along=300):
    """Approach along ``inward`` from ``start`` (on the free side), press ``depth`` past the surface
    point ``start + 0.02 inward``, then slide along ``tangent``."""
    surface_point = start + 0.02 * inward
    path = [start + (surface_point + depth * inward - start) * s for s in np.linspace(0, 1, steps_in)]
    pressed = path[-1]
    path += [pressed + tangent * length * s for s in np.linspace(0, 1, steps_along)]
    return np.array(path)


def compare(cloud_renderer, implicit, path):
    proxies, forces = [], []
    for p in path:
        a = cloud_renderer.render(*p, 0.0, 0.0, 0.0)
        b = implicit.render(*p, 0.0, 0.0, 0.0)
        proxies.append((cloud_renderer.proxy_object.proxy, implicit.proxy_object.proxy, a, b))
        forces.append((cloud_renderer.proxy_object.force, implicit.proxy_object.force))
    return proxies, np.array(forces)


@pytest.mark.parametrize("kind", ["projective", "grid", "kdtree"])
def test_cloud_of_a_plane_renders_like_the_plane(kind):
    normal = np.array([0.0, -0.3, -1.0])
    normal /= np.linalg.norm(normal)  # facing the camera
    point = np.array([0.0, 0.0, 1.0])
    builder, cloud_renderer, implicit = renderers(
        f"plane(normal=[{normal[0]}, {normal[1]}, {normal[2]}], offset={normal @ point})",
        plane_cloud(normal, point), kind, stiffness=800.0, damping=0.0)
    tangent = np.cross(normal, [1.0, 0.0, 0.0])
    path = stroke(point + 0.02 * normal + [0.01, 0.0, 0.0], -normal, tangent, 0.004, 0.03)
    proxies, forces = compare(cloud_renderer, implicit, path)
    contact = [i for i, (_, _, a, b) in enumerate(proxies) if b]
    assert len(contact) > 250 and all(proxies[i][2] for i in contact)
    # Tolerance: the float32 points of the cloud (1e-7 m at 1 m).
    for i in contact:
        assert np.allclose(proxies[i][0], proxies[i][1], atol=1e-5)
    assert np.abs(forces[contact, 0] - forces[contact, 1]).max() < 800.0 * 1e-5
    assert np.linalg.norm(forces[contact[-1], 1]) == pytest.approx(800.0 * 0.004, rel=1e-3)


@pytest.mark.parametrize("kind", ["projective", "grid", "kdtree"])
def test_cloud_of_a_sphere_renders_like_the_sphere(kind):
    centre, radius = np.array([0.02, -0.01, 0.8]), 0.1
    builder, cloud_renderer, implicit = renderers(
        f"translate([{centre[0]}, {centre[1]}, {centre[2]}], sphere({radius}))", sphere_cloud(centre, radius), kind,
        stiffness=800.0, damping=0.0)
    # Pressed at the point facing the camera, then stroked 3 cm across the sphere.
    out = np.array([0.3, 0.2, -1.0])
    out /= np.linalg.norm(out)
    top = centre + radius * out
    path = stroke(top + 0.02 * out, -out, np.cross(out, [0.0, 1.0, 0.0]), 0.003, 0.03)
    proxies, forces = compare(cloud_renderer, implicit, path)
    contact = [i for i, (_, _, a, b) in enumerate(proxies) if b and a]
    assert len(contact) > 250
    # Tolerance: the MLS plane through neighbours within 1 cm sits about r_s^2 / (2R) = 0.25 mm
    # inside a sphere of R = 0.1 m; we allow 0.4 mm on the proxy and 0.4 mm x k on the force.
    gaps = [np.linalg.norm(np.subtract(proxies[i][0], proxies[i][1])) for i in contact]
    assert max(gaps) < 4e-4
    assert np.abs(np.linalg.norm(forces[contact, 0], axis=1)
                  - np.linalg.norm(forces[contact, 1], axis=1)).max() < 800.0 * 4e-4


def test_builder_filters_and_structures():
    normal, point = np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, 1.0])
    cloud = plane_cloud(normal, point)
    builder = KDTreeBuilder("b", stride=2, max_distance=1.05)
    builder.configure()
    structure = builder.build(cloud)
    assert structure.kind == "projective" and structure.grid.shape == (240, 320, 3)
    fx, fy, cx, cy = structure.intrinsics
    assert fx == pytest.approx(FX / 2, rel=1e-6) and cx == pytest.approx(CX / 2, abs=1e-4)
    # Pixels whose depth is beyond 1.05 m are gone: the plane z = 1 is all nearer, all kept.
    assert structure.valid == 240 * 320
    far = KDTreeBuilder("far", max_distance=0.99)
    far.configure()
    assert far.build(cloud).valid == 0
    # An array (mesh vertices) gets a uniform grid; voxel decimation keeps one point per voxel.
    vertices = np.random.default_rng(1).uniform(0, 0.1, size=(20000, 3)).astype(np.float32) + [0, 0, 1]
    voxel = KDTreeBuilder("voxel", voxel=0.01)
    voxel.configure()
    decimated = voxel.build(vertices)
    assert decimated.kind == "grid" and decimated.valid == 1000
    # The grid holds every point once, sorted by cell, each cell's points inside it.
    cells = decimated.cells
    assert cells.ends[-1] == 1000 and np.all(np.diff(cells.keys) > 0)
    index = np.floor((decimated.points - cells.origin) / cells.cell).astype(np.int64)
    keys = index[:, 0] + cells.dims[0] * (index[:, 1] + cells.dims[1] * index[:, 2])
    assert np.array_equal(np.repeat(cells.keys, cells.ends - cells.starts), keys)
    projective = KDTreeBuilder("p", structure_kind="projective")
    projective.configure()
    with pytest.raises(StructureError, match="needs an organised cloud") as caught:
        projective.build(vertices)
    assert isinstance(caught.value, CocoError) and isinstance(caught.value, ValueError)


class Camera(Component):
    cloud = OutputPort(PointCloud)


def test_builder_offers_the_newest_structure():
    app = Application("builder")
    builder = KDTreeBuilder("builder")
    cloud_renderer = HapticCloud("cloud")
    app.add(builder)
    app.add(cloud_renderer)
    camera = Camera("camera")
    app.add(camera)
    app.connect("camera.cloud", "builder.cloud", ConnectionPolicy(BufferPolicy.BUFFER, size=4))
    app.connect("builder.structure", "cloud.structure")
    builder.configure()
    cloud_renderer.configure()
    clouds = [plane_cloud(np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, z])) for z in (1.0, 1.1, 1.2)]
    for cloud in clouds:
        camera.cloud.write(cloud)
    builder.step()  # three clouds waited: the newest is built, two are counted as dropped
    cloud_renderer.prepare()
    assert builder.built == 1 and camera.cloud.connections[0].dropped == 2, "the profile shows the skipped clouds"
    assert cloud_renderer.current.grid[240, 320, 2] == pytest.approx(1.2)


class RgbdSource(Component):
    rgbd = OutputPort(object)


class StructureSink(Component):
    structure = InputPort(object)


def mesh_to_cloud(name: str) -> tuple[RgbdSource, Any, KDTreeBuilder, StructureSink]:
    """RGB-D frames -> MeshReconstructor -> KDTreeBuilder -> a haptic side, wired in an application."""
    from coco_mr_vision.mesh_reconstructor import MeshReconstructor

    app = Application(name)
    sensor, mesher, builder = RgbdSource("sensor"), MeshReconstructor("mesher"), KDTreeBuilder("builder")
    haptics = StructureSink("haptics")
    for component in (sensor, mesher, builder, haptics):
        app.add(component)
    app.connect("sensor.rgbd", "mesher.rgbd")
    app.connect("mesher.mesh", "builder.cloud")
    app.connect("builder.structure", "haptics.structure")
    builder.configure()
    return sensor, mesher, builder, haptics


def test_the_structure_of_a_streamed_frame_carries_its_way_from_the_acquisition():
    """A stamped frame meshed and built: the structure's ``origin`` is the frame's acquisition stamp
    with its way so far and the steps ``meshed`` and ``built`` (the sensor-to-touchable latency)."""
    from coco_core.stamps import Stamp, Stamped
    from coco_mr_vision.image import Image, ImageFormat
    from coco_mr_vision.rgbd import RGBDFrame

    sensor, mesher, builder, haptics = mesh_to_cloud("stamped_mesh_to_cloud")
    intrinsics = CameraIntrinsics(64, 48, 60.0, 60.0, 31.5, 23.5)
    depth = np.full((48, 64), 1.0, np.float32)
    frame = RGBDFrame(Image(np.zeros((48, 64, 3), np.uint8), ImageFormat.RGB8, 10.0, "cam"),
                      Image(depth, ImageFormat.DEPTH32F, 10.0, "cam"), intrinsics)
    acquired = Stamp.now(5, "camera").step("received")
    sensor.rgbd.write(Stamped(frame, acquired))
    mesher.step()
    builder.step()
    origin = haptics.structure.read()[1].origin
    assert (origin.time, origin.seq, origin.source) == (acquired.time, 5, "camera")
    assert [name for name, _ in origin.steps] == ["received", "meshed", "built"]
    times = [origin.time, *(at for _, at in origin.steps)]
    assert times == sorted(times)
    assert [name for name, _ in origin.intervals()] == ["received", "meshed", "built"]
    assert all(seconds >= 0 for _, seconds in origin.intervals())


def test_a_mesh_reconstructor_feeds_the_builder_its_vertices():
    """RGB-D frames -> MeshReconstructor -> KDTreeBuilder, as wired in an application: the structure
    holds the mesh's vertices (in the camera's frame, with the image's stamp), and each mesh slot goes
    back to the reconstructor's pool (its three slots serve any number of frames)."""
    from coco_mr_vision.image import Image, ImageFormat
    from coco_mr_vision.rgbd import RGBDFrame

    sensor, mesher, builder, haptics = mesh_to_cloud("mesh_to_cloud")
    intrinsics = CameraIntrinsics(64, 48, 60.0, 60.0, 31.5, 23.5)
    for frame in range(8):
        depth = np.full((48, 64), 1.0 + 0.1 * frame, np.float32)
        depth[:5, :5] = np.nan  # a corner without depth: 25 vertices fewer
        sensor.rgbd.write(RGBDFrame(Image(np.zeros((48, 64, 3), np.uint8), ImageFormat.RGB8, 10.0 + frame, "cam"),
                                    Image(depth, ImageFormat.DEPTH32F, 10.0 + frame, "cam"), intrinsics))
        mesher.step()
        builder.step()
        assert mesher.stalls == 0, "every slot came back to the pool"
    structure = haptics.structure.read()[1]
    assert structure.kind == "grid" and structure.valid == 48 * 64 - 25
    assert structure.frame_id == "cam" and structure.stamp == pytest.approx(17.0)
    assert np.allclose(structure.points[:, 2], 1.7, atol=1e-6)
    assert builder.built == 8


def load_cloud(index):
    from coco_mr_vision.rgbd import RGBDFrame

    folder = RGBD / "redwood"
    if not folder.is_dir():
        pytest.skip(f"the RGB-D test data is not at {folder}")
    intrinsics = CameraIntrinsics(640, 480, FX, FY, CX, CY)
    frame = RGBDFrame.load(folder / "color" / f"{index:05d}.jpg", folder / "depth" / f"{index:05d}.png",
                           intrinsics)
    return PointCloud.from_depth(frame.depth, intrinsics, organized=True)


def floor_stroke(cloud, depth):
    """A stroke over the floor the Redwood camera sees at 1.1 m (lower image rows): approach along
    the floor's normal (fitted here with an SVD), press ``depth``, slide 4 cm sideways at 0.1 m/s."""
    grid = cloud.points.reshape(480, 640, 3)
    target = grid[420, 240].astype(float)
    normal = patch_plane(cloud, target)[0]
    along = np.array([1.0, 0.0, 0.0]) - normal[0] * normal
    return normal, stroke(target + 0.02 * normal, -normal, along / np.linalg.norm(along), depth, 0.04,
                          steps_in=60, steps_along=400)


def patch_plane(cloud, point, radius=0.03):
    """Normal (towards the camera) and centroid of the cloud's points within ``radius`` of ``point``."""
    points = cloud.points[np.isfinite(cloud.points).all(axis=1)].astype(float)
    patch = points[np.linalg.norm(points - point, axis=1) < radius]
    centroid = patch.mean(axis=0)
    normal = np.linalg.svd(patch - centroid)[2][2]
    return normal * -np.sign(normal @ centroid), centroid


def stroke_through_swap(first, second, depth, stride_after=1):
    app = Application("rgbd")
    builder = KDTreeBuilder("builder")
    renderer = HapticCloud("cloud", support=0.015, stiffness=500.0, damping=0.0)
    app.add(builder)
    app.add(renderer)
    app.connect("builder.structure", "cloud.structure")
    builder.configure()
    renderer.configure()
    builder.structure.write(builder.build(first))
    renderer.prepare()
    normal, path = floor_stroke(first, depth)
    trees = [cKDTree(c.points[np.isfinite(c.points).all(axis=1)]) for c in (first, second)]
    swap_at = 60 + 200
    forces, proxies, tree = [], [], trees[0]
    for i, p in enumerate(path):
        if i == swap_at:
            builder.stride = stride_after
            builder.structure.write(builder.build(second))
            renderer.step()
            tree = trees[1]
            assert renderer.swaps == 1
        in_contact = renderer.render(*p, 0.0, 0.0, 0.0)
        forces.append(renderer.proxy_object.force)
        proxies.append(renderer.proxy_object.proxy)
        if i >= 70:
            assert in_contact, f"lost contact at step {i}"
            if swap_at <= i < swap_at + renderer.blend:
                continue  # on the surface blended from the old fit to the new
            # On the surface: the proxy is within 1.5 pixel spacings of the cloud (2.1 mm per pixel
            # at 1.1 m, 4.2 mm after a stride of 2; the depth is quantised to millimetres).
            proxy = renderer.proxy_object.proxy
            assert tree.query(proxy)[0] < 1.5 * (stride_after if i >= swap_at else 1) * proxy[2] / FX
    return normal, path, np.array(forces), np.array(proxies), swap_at


def test_stroke_over_a_real_rgbd_frame_through_a_rebuilt_structure():
    frame = load_cloud(0)
    # The same frame rebuilt with a stride of 2 (a quarter of the points) replaces the structure.
    normal, path, forces, proxies, swap_at = stroke_through_swap(frame, frame, 0.004, stride_after=2)
    magnitude = np.linalg.norm(forces, axis=1)
    assert magnitude[70:].min() > 1.0  # pressed all along (4 mm x 500 N/m = 2 N)
    # Continuous: no step changes the force by more than 0.25 N (0.5 mm x k), the swap included.
    assert np.abs(np.diff(forces[70:], axis=0)).max() < 0.25
    assert np.linalg.norm(proxies[swap_at] - proxies[swap_at - 1]) < 5e-4


def test_stroke_over_real_rgbd_frames_follows_the_next_frame():
    first, second = load_cloud(0), load_cloud(1)
    # The camera moved between the two frames: the floor moved by a few millimetres along its normal
    # in the camera's frame. Pressed 15 mm, the proxy stays in contact and moves with the surface,
    # along the normal only: no tangential jump.
    normal, path, forces, proxies, swap_at = stroke_through_swap(first, second, 0.015)
    # No jump: the proxy moves less than 0.5 mm per cycle (the hand moves 0.1 mm per cycle).
    assert np.linalg.norm(np.diff(proxies[70:], axis=0), axis=1).max() < 5e-4
    # Over the blend (30 cycles), it moves with the surface along the normal.
    before, after = proxies[swap_at - 1], proxies[swap_at + 30]
    plane_before = patch_plane(first, before)
    shift = (patch_plane(second, before)[1] - plane_before[1]) @ plane_before[0]
    assert abs((after - before) @ normal - shift) < 1.5e-3
    # Continuous force: under 0.3 N per cycle (the shift x 500 N/m is spread over 30 cycles).
    assert np.abs(np.diff(forces[70:], axis=0)).max() < 0.3


def test_cloud_in_a_camera_frame_renders_in_the_world():
    """The cloud arrives in the camera's frame; the renderer works in the world, where the camera is
    placed by the transformation graph: the force is the one of the same plane written in the world."""
    from dataclasses import replace

    from coco_core.transforms import se3

    camera_pose = se3.make(se3.rpy_to_matrix(-np.pi / 2, 0.0, 0.3), (0.1, -0.8, 0.5))
    normal_c, point_c = np.array([0.0, -0.3, -1.0]) / np.linalg.norm([0.0, -0.3, -1.0]), np.array([0.0, 0.0, 1.0])
    normal_w = camera_pose[:3, :3] @ normal_c
    point_w = camera_pose[:3, :3] @ point_c + camera_pose[:3, 3]
    app = Application("frames")
    app.transforms.add_static("world", "camera", camera_pose)
    builder = KDTreeBuilder("builder")
    cloud_renderer = HapticCloud("cloud", frame="world", stiffness=800.0, damping=0.0)
    implicit = HapticImplicitSurf("implicit", stiffness=800.0, damping=0.0,
                                  surface=f"plane(normal=[{normal_w[0]}, {normal_w[1]}, {normal_w[2]}], "
                                          f"offset={normal_w @ point_w})")
    for component in (builder, cloud_renderer, implicit):
        app.add(component)
    app.connect("builder.structure", "cloud.structure")
    for component in (builder, cloud_renderer, implicit):
        component.configure()
    builder.structure.write(builder.build(replace(plane_cloud(normal_c, point_c), frame_id="camera")))
    cloud_renderer.prepare()
    tangent = np.cross(normal_w, [0.0, 0.0, 1.0])
    path = stroke(point_w + 0.02 * normal_w, -normal_w, tangent / np.linalg.norm(tangent), 0.003, 0.02)
    proxies, forces = compare(cloud_renderer, implicit, path)
    contact = [i for i, (_, _, a, b) in enumerate(proxies) if a and b]
    assert len(contact) > 250
    assert np.abs(forces[contact, 0] - forces[contact, 1]).max() < 800.0 * 1e-5
    assert np.linalg.norm(forces[contact[-1], 0]) == pytest.approx(800.0 * 0.003, rel=1e-3)


def real_points(index):
    """The valid points of a Redwood frame, unorganised (as a MeshReconstructor's vertices come)."""
    cloud = load_cloud(index)
    return cloud, cloud.points[np.isfinite(cloud.points).all(axis=1)]


def test_a_real_frame_gets_a_grid_with_the_default_cell():
    """A real PrimeSense frame (1-2.7 m deep, 2.4 m wide) needs 6.7e6 cells of 10 mm for 267k
    points: the builder takes the smallest larger cell that bounds the grid, and keeps every point."""
    _, points = real_points(0)
    builder = KDTreeBuilder("builder")
    builder.configure()
    structure = builder.build(points)
    cells = structure.cells
    assert structure.kind == "grid" and structure.valid == len(points)
    assert 0.01 < cells.cell < 0.02
    assert float(np.prod(cells.dims.astype(float))) <= 8 * len(points)
    assert np.all((structure.points >= cells.origin) & (structure.points < cells.origin + cells.dims * cells.cell))
    # An explicit cell that fits is kept as it is.
    coarse = KDTreeBuilder("coarse", cell=0.05)
    coarse.configure()
    assert coarse.build(points).cells.cell == 0.05


@pytest.mark.parametrize("kind", ["projective", "grid"])
@pytest.mark.parametrize("pixel", [(420, 240), (400, 320), (460, 80)])
def test_pushing_along_an_oblique_viewing_ray_into_a_real_floor(kind, pixel):
    """The Redwood floor seen at 60-75 degrees from its normal, with its depth in PrimeSense steps
    (5.5 mm at 1.2 m): the device pushed along the viewing ray 6 mm under the floor, then stroked.
    With the default support, the force stays within a few degrees of the floor's normal, contact is
    never released while the device is more than 2 mm under the floor, and the proxy stays on it."""
    cloud, points = real_points(0)
    builder = KDTreeBuilder("builder", structure_kind=kind)
    renderer = HapticCloud("cloud", stiffness=500.0, damping=0.0)
    app = Application("floor")
    app.add(builder)
    app.add(renderer)
    app.connect("builder.structure", "cloud.structure")
    builder.configure()
    renderer.configure()
    builder.structure.write(builder.build(cloud if kind == "projective" else points))
    renderer.prepare()
    target = cloud.points.reshape(480, 640, 3)[pixel].astype(float)
    normal, centre = patch_plane(cloud, target, radius=0.05)
    ray = centre / np.linalg.norm(centre)
    assert np.degrees(np.arccos(abs(ray @ normal))) > 55, "an oblique view of the floor"
    path = [centre - 0.03 * ray + s * ray for s in np.linspace(0.0, 0.03 + 0.006 / abs(ray @ normal), 600)]
    side = np.cross(normal, ray)
    path += [path[-1] + s * side / np.linalg.norm(side) for s in np.linspace(0.0, 0.04, 400)]
    released, angles, behind = 0, [], []
    for p in path:
        touching = renderer.render(*p, 0.0, 0.0, 0.0)
        under = normal @ (centre - p)
        if not touching:
            released += under > 0.002
            continue
        force = np.array(renderer.proxy_object.force)
        if np.linalg.norm(force) > 0.5:  # 1 mm deep
            angles.append(np.degrees(np.arccos(np.clip(force @ normal / np.linalg.norm(force), -1, 1))))
        behind.append(normal @ (centre - np.array(renderer.proxy_object.proxy)))
    assert released == 0
    assert len(angles) > 500 and max(angles) < 6.0
    assert max(behind) < 1.5e-3, "the proxy stays on the floor (within the depth step's noise)"


def test_a_haptic_loop_that_never_received_a_structure_is_not_a_perfect_run(tmp_path):
    """No cloud ever reached the HapticCloud (a builder that failed, a camera that never started):
    the recorder's summary says so and the application records it, so that the launcher exits 1."""
    from coco_core.launcher import stopped_by_a_failure
    from coco_mr_haptics.recorder import HapticRecorder
    from coco_mr_haptics.renderer import HapticRenderer
    from coco_mr_haptics.simulated_device import SimulatedDevice

    (tmp_path / "hand.csv").write_text("time,x,y,z\n0,0,0,0.05\n0.5,0,0,-0.05\n")
    app = Application("blind")
    device = SimulatedDevice("device", trajectory=str(tmp_path / "hand.csv"), time_step=1e-3)
    renderer = HapticRenderer("renderer")
    cloud_renderer = HapticCloud("cloud")
    renderer.add_peer(cloud_renderer)
    builder = KDTreeBuilder("builder")
    recorder = HapticRecorder("recorder", path=str(tmp_path / "h.csv"), summary=str(tmp_path / "s.json"))
    for component in (device, renderer, builder, recorder):
        app.add(component)
    app.connect("builder.structure", "cloud.structure")
    app.connect("device.state", "renderer.device")
    app.connect("renderer.force", "device.force")
    app.connect("renderer.sample", "recorder.samples", ConnectionPolicy(BufferPolicy.BUFFER, size=1000))
    for component in (device, renderer, builder, recorder):
        component.configure()
    for _ in range(500):
        device.step()
        renderer.step()
    recorder.step()
    recorder.stop()
    renderer.stop()
    summary = recorder.report()
    assert summary["samples_without_surface"] == {"cloud": 500} and summary["surfaces_ready"] is False
    assert cloud_renderer.blind_cycles == 500
    assert app.damage and "no cloud structure ever arrived on cloud.structure" in app.damage[0]
    assert stopped_by_a_failure(app)


def test_an_rgbd_frame_is_its_own_structure():
    """A stamped RGB-D frame straight from a stream (TUM's 16-bit depth, 5000 units a metre): its
    depth image is the structure, copied, with the frame's intrinsics (halved at stride 2) and its
    way from the acquisition plus ``built``; every pixel with depth is a point, the filters make the
    others unknown, and its fit is the projective fit of the same points as an organised cloud."""
    from coco_core.stamps import Stamp, Stamped, unstamped
    from coco_mr_vision.image import Image, ImageFormat
    from coco_mr_vision.rgbd import RGBDFrame

    app = Application("rgbd_structure")
    sensor, builder, haptics = RgbdSource("sensor"), KDTreeBuilder("builder"), StructureSink("haptics")
    for component in (sensor, builder, haptics):
        app.add(component)
    app.connect("sensor.rgbd", "builder.cloud")
    app.connect("builder.structure", "haptics.structure")
    builder.configure()
    intrinsics = CameraIntrinsics(64, 48, 60.0, 62.0, 31.5, 23.5)
    depth = np.full((48, 64), 5000, np.uint16)  # a wall 1 m away ...
    depth[:, 32:] = np.linspace(5000, 7000, 32).astype(np.uint16)  # ... turning away to 1.4 m
    depth[:5, :5] = 0  # a corner without depth
    frame = RGBDFrame(Image(np.zeros((48, 64, 3), np.uint8), ImageFormat.RGB8, 10.0, "cam"),
                      Image(depth, ImageFormat.DEPTH16, 10.0, "cam"), intrinsics, depth_scale=5000.0)
    acquired = Stamp.now(5, "camera").step("received")
    sensor.rgbd.write(Stamped(frame, acquired))
    builder.step()
    structure = haptics.structure.read()[1]
    assert structure.kind == "depth" and structure.valid == 48 * 64 - 25
    assert (structure.frame_id, structure.stamp) == ("cam", 10.0) and len(structure.points) == 0
    assert [name for name, _ in structure.origin.steps] == ["received", "built"]
    depth[10, 10] = 0  # the frame's array, not the structure's
    assert structure.depth[10, 10] == 5000 and structure.depth_scale == pytest.approx(1 / 5000)
    # The same points as an organised cloud, searched projectively: the same plane.
    z = depth.astype(np.float64) / 5000
    z[10, 10], z[:5, :5] = 1.0, np.nan
    v, u = np.mgrid[0:48, 0:64]
    grid = np.stack([(u - 31.5) / 60.0 * z, (v - 23.5) / 62.0 * z, z], axis=-1).astype(np.float32)
    organised = builder.build(PointCloud(grid.reshape(-1, 3), organized=(48, 64)))
    for q in ((0.01, 0.02, 0.99), (0.12, -0.05, 1.1), (-0.4, -0.3, 1.0)):  # the last one beside the hole
        fits = [np.zeros(7), np.zeros(7)]
        found = [s.fit(*q, 0.05, (0.0, 0.0, 0.0), fit, np.zeros(11)) for s, fit in zip((structure, organised), fits)]
        assert found[0] == found[1] >= 6 and np.allclose(fits[0], fits[1], atol=1e-6), (q, found, fits)
    # Every second pixel both ways; the pixels beyond 1.2 m unknown.
    halved = KDTreeBuilder("halved", stride=2, max_distance=1.2)
    halved.configure()
    half = halved.build(frame)
    assert half.depth.shape == (24, 32) and half.intrinsics == (30.0, 31.0, 15.75, 11.75)
    assert half.valid == int(np.count_nonzero((depth[::2, ::2] > 0) & (depth[::2, ::2] <= 6000)))
    voxel = KDTreeBuilder("voxel", structure_kind="projective", voxel=0.01)
    voxel.configure()
    with pytest.raises(StructureError, match="voxel decimation makes a cloud unorganised"):
        voxel.build(frame)
    with pytest.raises(StructureError, match="got Image"):
        builder.build(*unstamped(Stamped(frame.depth, acquired)))


def load_frame(name):
    """A real RGB-D frame of the shared data (PrimeSense intrinsics): Redwood's 0 and 1, TUM's."""
    from coco_mr_vision.rgbd import RGBDFrame

    intrinsics = CameraIntrinsics(640, 480, FX, FY, CX, CY)
    if name == "tum":
        folder = RGBD / "tum"
        paths, scale = (folder / "color.png", folder / "depth.png"), 5000.0
    else:
        folder = RGBD / "redwood"
        paths, scale = (folder / "color" / f"{name}.jpg", folder / "depth" / f"{name}.png"), 1000.0
    if not folder.is_dir():
        pytest.skip(f"the RGB-D test data is not at {folder}")
    return RGBDFrame.load(*paths, intrinsics, depth_scale=scale)


@pytest.mark.parametrize("name", ["00000", "00001", "tum"])
def test_the_depth_structure_touches_like_the_grid_on_real_frames(name):
    """Issue 34: the frame's depth image as the structure (what the palpation app now touches)
    against the uniform grid over the same valid points (what it touched before, over the mesh's
    vertices), through the same contact query (HapticCloud's): a hand that presses 5 mm into the
    surface at pixels spread over the image and slides 3 cm along it, and a drag across the whole
    image 3 mm under the surfaces the camera sees. The same contacts at every step, and the proxies
    within 0.5 mm of each other."""
    from coco_mr_haptics.cloud import frame_cloud

    frame = load_frame(name)
    points = frame_cloud(frame)
    assert len(points) > 0.6 * 640 * 480
    structures = []
    for kind in ("auto", "grid"):
        builder = KDTreeBuilder(f"builder_{kind}", structure_kind=kind)
        builder.configure()
        structures.append(builder.build(frame))
    assert [s.kind for s in structures] == ["depth", "grid"] and structures[0].valid == structures[1].valid
    z = frame.depth_metres()
    organised = PointCloud(np.stack([(np.arange(640) - CX)[None, :] / FX * z, (np.arange(480) - CY)[:, None] / FY * z,
                                     z], axis=-1).reshape(-1, 3).astype(np.float32), organized=(480, 640))
    contacts, gaps = [], []
    for row, col in ((120, 160), (120, 480), (240, 320), (360, 160), (360, 480), (420, 240)):
        target = organised.points.reshape(480, 640, 3)[row, col].astype(float)
        if not np.isfinite(target).all():
            continue
        normal = patch_plane(organised, target, radius=0.03)[0]
        along = np.cross(normal, [0.0, 1.0, 0.0])
        path = stroke(target + 0.02 * normal, -normal, along / np.linalg.norm(along), 0.005, 0.03,
                      steps_in=40, steps_along=200)
        renderers = []  # each press a new approach: a hand that came from the free side
        for structure in structures:
            renderer = Application(f"touch_{structure.kind}").add(HapticCloud("cloud", stiffness=500.0, damping=0.0))
            renderer.configure()
            renderer.use(structure)
            renderers.append(renderer)
        for p in path:
            touching = [renderer.render(*p, 0.0, 0.0, 0.0) for renderer in renderers]
            contacts.append(touching)
            if all(touching):
                gaps.append(np.linalg.norm(np.subtract(*(r.proxy_object.proxy for r in renderers))))
    contacts = np.array(contacts)
    assert len(contacts) >= 5 * 240 and contacts[:, 0].sum() > 0.6 * len(contacts), "the presses touch"
    assert np.array_equal(contacts[:, 0], contacts[:, 1]), np.nonzero(contacts[:, 0] != contacts[:, 1])
    assert max(gaps) < 5e-4, max(gaps)
