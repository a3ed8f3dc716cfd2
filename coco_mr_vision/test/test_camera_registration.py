"""Camera-to-robot registration end to end (the paper's Fig. 2), in one process: the display module
renders the real Baxter with a textured ArUco marker on its left gripper, from a camera at a
ground-truth pose the registration never sees, with image noise; MarkerTracker measures camera ->
marker, the kinematic chain gives base -> gripper -> marker, and the transformation graph's
registration averages the temporary path over several arm poses and installs camera -> base.
Goal: within 5 mm and 0.5 degrees of the truth. The camera looks at the gripper from 0.6 m, on the
line to Baxter's head (at the head itself the marker is ~50 px wide and the error 14 mm). The
first noisy view is saved as ``view.png`` in the test's tmp folder. The application file,
config/camera_registration.xml, runs the same chain with its components (test/test_camera_registration_app.py)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")
trimesh = pytest.importorskip("trimesh")
pytest.importorskip("collada", reason="Baxter's meshes are DAE files, read through pycollada")
pytest.importorskip("pinocchio")

from coco_core import Application, BufferPolicy, Component, ConnectionPolicy, InputPort, OutputPort  # noqa: E402
from coco_core.transforms.interface import TransformationInterface  # noqa: E402
from coco_core.transforms.averaging import transform_residuals  # noqa: E402
from coco_core.transforms.registration import Registration  # noqa: E402
from coco_mr_vision.image import CameraIntrinsics, Image  # noqa: E402
from coco_mr_vision.marker_mesh import write_marker_mesh  # noqa: E402
from coco_mr_vision.marker_tracker import MarkerTracker  # noqa: E402

BAXTER = "package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"
W, H, FOV = 640, 480, 50.0
LENGTH, ID = 0.10, 3
POSES = [{"left_s0": s0, "left_s1": s1, "left_e1": e1, "left_w1": w1, "left_w2": w2}
         for s0, s1, e1, w1, w2 in [(0.3, -0.3, 1.5, 0.8, 0.0), (0.15, -0.2, 1.4, 0.9, 0.3),
                                    (0.45, -0.35, 1.6, 0.7, -0.3), (0.3, -0.1, 1.3, 1.0, 0.5),
                                    (0.2, -0.4, 1.7, 0.6, -0.5), (0.4, -0.25, 1.45, 0.85, 0.2),
                                    (0.3, -0.3, 1.5, 0.8, 0.5), (0.25, -0.25, 1.5, 0.9, -0.4),
                                    (0.35, -0.3, 1.45, 0.75, 0.8), (0.2, -0.2, 1.5, 0.8, 0.0)]]


def marker_mesh(path: Path) -> Path:
    """A textured square: ArUco DICT_4X4_50 id 3 of side LENGTH with a white border, in the xy plane."""
    return write_marker_mesh(path, "DICT_4X4_50", ID, LENGTH)


class Frames(Component):
    image = InputPort(object)


class Camera(Component):
    """Hands the noisy rendered images, with the camera's intrinsics, to the tracker."""

    image = OutputPort(object)


def look_at(eye, target) -> np.ndarray:
    z = np.asarray(target, float) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    pose = np.eye(4)
    pose[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    pose[:3, 3] = eye
    return pose


def test_rendered_marker_registers_the_head_camera(tmp_path):
    from coco_mr_display.camera import GLCameraManager
    from coco_mr_display.entity import GLEntity
    from coco_mr_display.manager import GLManager
    from coco_mr_display.urdf import GLUrdf

    app = Application("registration")
    app.add(TransformationInterface("tf", urdf=BAXTER))
    display = GLManager("display", width=W, height=H, world="base", background=[0.5, 0.5, 0.5, 1.0])
    display.add_peer(GLCameraManager("camera", follow_frame="truth_camera", fov_y=FOV, near=0.05, far=10.0))
    display.add_peer(GLUrdf("baxter", preload=True))
    display.add_peer(GLEntity("marker", mesh=str(marker_mesh(tmp_path / "marker.glb")), frame=f"marker_{ID}"))
    app.add(display)
    frames = app.add(Frames("frames"))
    tracker = app.add(MarkerTracker("tracker", dictionary="DICT_4X4_50", marker_length=LENGTH,
                                    camera_frame="head_camera"))
    camera = app.add(Camera("head_camera_driver"))
    app.connect(display.color, frames.image, ConnectionPolicy(BufferPolicy.BUFFER, size=4))
    app.connect(camera.image, tracker.image)
    graph = app.transforms
    graph.set_joints(POSES[0])
    gripper = graph.lookup("base", "left_gripper")[:3, 3]
    head = np.array([0.25, 0.0, 0.75])  # towards the head, 0.6 m from the gripper (a 640x480 camera sees
    eye = gripper + 0.6 * (head - gripper) / np.linalg.norm(head - gripper)  # the marker ~100 px wide)
    truth = look_at(eye, gripper)
    graph.add_static("base", "truth_camera", truth)  # drawn from here; the registration never reads it
    mount = np.diag([1.0, -1.0, -1.0, 1.0])  # beyond the fingertips, its face turned back to the wrist
    mount[:3, 3] = [0.0, 0.0, 0.08]
    graph.add_static("left_gripper", f"marker_{ID}", mount)  # where the marker is fixed on the gripper
    fy = (H / 2) / math.tan(math.radians(FOV) / 2)
    intrinsics = CameraIntrinsics(W, H, fy, fy, W / 2 - 0.5, H / 2 - 0.5, frame_id="head_camera")
    tracker.on_config()
    noise = np.random.default_rng(7)
    registration = Registration(graph, "base", "head_camera", via=("head_camera", f"marker_{ID}"))
    assert display.configure()
    try:
        for index, pose in enumerate(POSES):
            graph.set_joints(pose)
            display.step()
            rendered = frames.image.read_all()[-1]
            noisy = np.clip(rendered.data + noise.normal(0, 3.0, rendered.data.shape), 0, 255).astype(np.uint8)
            if index == 0:
                cv2.imwrite(str(tmp_path / "view.png"), cv2.cvtColor(noisy, cv2.COLOR_RGB2BGR))
            detected = tracker.detected
            camera.image.write(Image(noisy, "RGB8", float(index), "head_camera", intrinsics))
            tracker.on_update()  # publishes head_camera -> marker_3 into the graph when it sees the marker
            if tracker.detected == detected:
                continue  # turned away or hidden by the fingers in this pose: no sample, as with a real camera
            assert registration.sample() == 1
    finally:
        display.stop()
    assert registration.sample_count >= 4, f"the marker was seen in {registration.sample_count} poses of {len(POSES)}"
    result = registration.install()
    found = graph.lookup("base", "head_camera")
    translation, rotation = transform_residuals(truth, found[None])
    print(f"\ntruth base->camera:\n{np.round(truth, 4)}\nregistered:\n{np.round(found, 4)}\n{result.summary()}\n"
          f"error: {translation[0] * 1000:.2f} mm, {math.degrees(rotation[0]):.3f} deg")
    assert translation[0] < 0.005 and math.degrees(rotation[0]) < 0.5
