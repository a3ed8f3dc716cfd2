"""Registration: SE(3) averaging with outlier rejection, and registering two disjoint frames of a graph
through temporary measurement paths (a marker held by a robot, seen by a camera)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coco_core.transforms import (
    Registration,
    RegistrationError,
    StaticEdge,
    TransformError,
    TransformGraph,
    average_quaternions,
    average_transforms,
    robust_average,
    transform_residuals,
)
from coco_core.transforms import se3

DEG = math.pi / 180.0


# --- helpers ----------------------------------------------------------------------------------------

def rotation_vector(vector: np.ndarray) -> np.ndarray:
    angle = float(np.linalg.norm(vector))
    return np.eye(3) if angle == 0.0 else se3.axis_angle(vector / angle, angle)


def noise(rng: np.random.Generator, sigma_translation: float, sigma_rotation: float) -> np.ndarray:
    """A small random transform: Gaussian translation and rotation vector, per-axis sigmas."""
    return se3.make(rotation_vector(rng.normal(0.0, sigma_rotation, 3)), rng.normal(0.0, sigma_translation, 3))


def far_off(rng: np.random.Generator) -> np.ndarray:
    """An outlier: 10-50 cm away or rotated by 15-90 degrees (a misdetection, a flipped marker)."""
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    if rng.random() < 0.5:
        return se3.make(None, direction * rng.uniform(0.10, 0.50))
    return se3.make(se3.axis_angle(direction, rng.uniform(15, 90) * DEG), rng.normal(0.0, 0.002, 3))


def errors(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    translation, rotation = transform_residuals(truth, [estimate])
    return float(translation[0]), float(rotation[0])


TRUTH = se3.make(se3.rpy_to_matrix(0.4, -0.7, 2.1), [1.2, -0.4, 0.8])


# --- averaging ----------------------------------------------------------------------------------------

def test_identical_samples_average_exactly_and_none_is_rejected() -> None:
    result = robust_average([TRUTH] * 10)
    assert np.allclose(result.transform, TRUTH, atol=1e-12)
    assert (result.used, result.rejected) == (10, 0)
    assert result.rms_translation < 1e-12 and result.rms_rotation < 1e-7
    assert np.allclose(average_transforms([TRUTH] * 3), TRUTH, atol=1e-12)


def test_weighted_mean_of_two_rotations_about_one_axis() -> None:
    a, b = se3.make(se3.axis_angle((0, 0, 1), 0.0)), se3.make(se3.axis_angle((0, 0, 1), 60 * DEG), [3.0, 0, 0])
    mean = average_transforms([a, b])
    assert np.allclose(mean, se3.make(se3.axis_angle((0, 0, 1), 30 * DEG), [1.5, 0, 0]), atol=1e-12)
    weighted = average_transforms([a, b], weights=[3.0, 1.0])
    assert np.allclose(weighted[:3, 3], [0.75, 0, 0])
    angle = math.atan2(weighted[1, 0], weighted[0, 0])
    assert 0.0 < angle < 30 * DEG  # pulled towards the heavier sample


def test_quaternion_sign_flips_do_not_change_the_mean() -> None:
    rng = np.random.default_rng(1)
    base = se3.matrix_to_quaternion(TRUTH[:3, :3])
    quaternions = np.array([se3.matrix_to_quaternion(se3.quaternion_to_matrix(base) @ noise(rng, 0, 2 * DEG)[:3, :3])
                            for _ in range(50)])
    signs = rng.choice([-1.0, 1.0], size=(50, 1))
    flipped = quaternions * signs
    assert np.allclose(average_quaternions(flipped), average_quaternions(quaternions), atol=1e-12)
    angle = 2 * math.acos(min(1.0, abs(float(average_quaternions(flipped) @ base))))
    assert angle < 1.5 * DEG
    naive = flipped.mean(axis=0)  # what a sign-blind mean would give: far from the truth
    naive_angle = 2 * math.acos(min(1.0, abs(float(naive / np.linalg.norm(naive) @ base))))
    assert naive_angle > 10 * DEG or np.linalg.norm(naive) < 0.8


def test_rotations_near_180_degrees_straddling_the_quaternion_sign() -> None:
    # matrix_to_quaternion keeps w >= 0, so rotations just below and above 180 degrees come out with
    # opposite vector parts: a component-wise mean would cancel them.
    rng = np.random.default_rng(2)
    truth = se3.make(se3.axis_angle((0.0, 0.6, 0.8), math.pi), [0.1, 0.2, 0.3])
    samples = [truth @ noise(rng, 0.001, 1.0 * DEG) for _ in range(100)]
    vector_signs = {np.sign(se3.matrix_to_quaternion(s[:3, :3])[2]) for s in samples}
    assert vector_signs == {-1.0, 1.0}
    translation, rotation = errors(robust_average(samples).transform, truth)
    assert rotation < 0.5 * DEG and translation < 0.001


def test_robust_average_recovers_a_known_transform_and_rejects_the_outliers() -> None:
    rng = np.random.default_rng(7)
    sigma_t, sigma_r, good, bad = 0.002, 0.5 * DEG, 500, 100
    samples = [TRUTH @ noise(rng, sigma_t, sigma_r) for _ in range(good)]
    # half the outliers at random, half clustered at one wrong pose (a consistently confused tracker)
    cluster = se3.make(se3.axis_angle((0.0, 0.6, 0.8), 30 * DEG), [0.2, 0.0, 0.1])
    samples += [TRUTH @ far_off(rng) for _ in range(bad // 2)]
    samples += [TRUTH @ cluster @ noise(rng, sigma_t, sigma_r) for _ in range(bad - bad // 2)]
    order = rng.permutation(len(samples))
    samples = [samples[i] for i in order]
    is_outlier = order >= good

    result = robust_average(samples)
    translation, rotation = errors(result.transform, TRUTH)
    # bound from the noise: 4.5 standard errors of the mean (per-axis sigma / sqrt(n)) in 3D
    assert translation < 4.5 * sigma_t / math.sqrt(good) < 0.001
    assert rotation < 4.5 * sigma_r / math.sqrt(good) and rotation < 0.1 * DEG
    assert np.all(~result.inliers[is_outlier]), "every outlier is rejected"
    assert np.count_nonzero(~result.inliers[~is_outlier]) <= good // 100, "almost no good sample is rejected"
    assert result.rejected >= bad
    # the reported residual matches the noise: RMS of a 3D Gaussian is sqrt(3) sigma
    assert result.rms_translation == pytest.approx(math.sqrt(3) * sigma_t, rel=0.1)
    assert result.rms_rotation == pytest.approx(math.sqrt(3) * sigma_r, rel=0.1)
    assert result.translation_uncertainty == pytest.approx(result.rms_translation / math.sqrt(result.used))

    naive_translation, naive_rotation = errors(average_transforms(samples), TRUTH)
    # without rejection, the mean is off by far more than the noise allows
    assert naive_translation > 10 * 4.5 * sigma_t / math.sqrt(good)
    assert naive_rotation > 10 * 4.5 * sigma_r / math.sqrt(good)


def test_a_large_cluster_of_outliers_does_not_capture_the_estimate() -> None:
    # 40 % of the samples at one wrong pose: a mean would start between the two groups and keep them
    # all; the robust start (median translation, medoid rotation) sits on the majority.
    rng = np.random.default_rng(9)
    wrong = TRUTH @ se3.make(se3.axis_angle((1.0, 0.0, 0.0), 20 * DEG), [0.0, 0.15, 0.0])
    samples = [TRUTH @ noise(rng, 0.002, 0.5 * DEG) for _ in range(60)]
    samples += [wrong @ noise(rng, 0.002, 0.5 * DEG) for _ in range(40)]
    result = robust_average(samples)
    assert result.rejected_indices == list(range(60, 100))
    translation, rotation = errors(result.transform, TRUTH)
    assert translation < 4.5 * 0.002 / math.sqrt(60) and rotation < 4.5 * 0.5 * DEG / math.sqrt(60)


def test_absolute_limits_reject_what_the_median_rule_would_keep() -> None:
    rng = np.random.default_rng(3)
    samples = [TRUTH @ noise(rng, 0.002, 0.5 * DEG) for _ in range(20)]
    samples.append(TRUTH @ se3.make(se3.axis_angle((1, 0, 0), 1.0 * DEG)))  # 2 sigma: kept by the median rule
    assert robust_average(samples).inliers[-1]
    assert not robust_average(samples, max_rotation=0.8 * DEG).inliers[-1]


def test_too_few_samples_say_how_many_are_needed() -> None:
    with pytest.raises(RegistrationError, match="at least 3 samples, got 2"):
        robust_average([TRUTH, TRUTH])
    with pytest.raises(RegistrationError, match="at least 5 samples, got 0"):
        robust_average([], min_samples=5)
    with pytest.raises(RegistrationError, match="only 3 of 5 samples agree.*at least 4 are needed"):
        robust_average([TRUTH] * 3 + [TRUTH @ se3.make(None, [0, 0, 0.1]), TRUTH @ se3.make(None, [0, 0.2, 0])],
                       min_samples=4)


def test_degenerate_and_invalid_samples_are_refused() -> None:
    half_turn = se3.make(se3.axis_angle((0, 0, 1), math.pi))
    with pytest.raises(RegistrationError, match="no unique mean"):
        average_transforms([np.eye(4), half_turn])
    skewed = np.eye(4)
    skewed[0, 1] = 0.3
    with pytest.raises(ValueError, match=r"sample\(s\) \[1\] are not rigid"):
        average_transforms([np.eye(4), skewed])
    with pytest.raises(ValueError, match="NaN"):
        robust_average([np.eye(4)] * 3 + [np.full((4, 4), np.nan)])
    with pytest.raises(ValueError, match="2 weights for 3 samples"):
        average_transforms([np.eye(4)] * 3, weights=[1, 1])


# --- registration on a graph: a camera sees a marker held by a robot ---------------------------------------

WORLD_CAMERA = se3.make(se3.rpy_to_matrix(-2.0, 0.1, 2.6), [1.1, 0.6, 1.0])
GRIPPER_MARKER = se3.make(se3.rpy_to_matrix(0.0, math.pi / 2, 0.3), [0.05, 0.0, 0.03])
POSES = [(0.0, 0.3, -0.6, 0.0), (0.4, 0.2, -0.4, 0.5), (-0.3, 0.5, -0.9, -0.4), (0.2, -0.1, -0.2, 1.0),
         (0.6, 0.4, -0.7, -0.8), (-0.5, 0.1, -0.5, 0.3), (0.1, 0.6, -1.1, -1.2), (0.3, 0.0, -0.3, 0.8)]


def robot_graph() -> TransformGraph:
    """world -> base (static) -> four revolute joints -> gripper -> marker (static, known)."""
    graph = TransformGraph()
    graph.add_static("world", "base", se3.make(se3.axis_angle((0, 0, 1), 30 * DEG), [0.2, 0.1, 0.0]))
    graph.add_axis("base", "link1", "j1", "revolute", se3.make(None, [0, 0, 0.3]), (0, 0, 1))
    graph.add_axis("link1", "link2", "j2", "revolute", se3.make(None, [0, 0, 0.1]), (0, 1, 0))
    graph.add_axis("link2", "link3", "j3", "revolute", se3.make(None, [0.4, 0, 0]), (0, 1, 0))
    graph.add_axis("link3", "gripper", "j4", "revolute", se3.make(None, [0.35, 0, 0]), (1, 0, 0))
    graph.add_static("gripper", "marker", GRIPPER_MARKER)
    return graph


def forward_kinematics(pose: tuple[float, float, float, float]) -> np.ndarray:
    """T_world_marker computed without the graph, to check it independently."""
    j1, j2, j3, j4 = pose
    return (se3.make(se3.axis_angle((0, 0, 1), 30 * DEG), [0.2, 0.1, 0.0])
            @ se3.make(se3.axis_angle((0, 0, 1), j1), [0, 0, 0.3])
            @ se3.make(se3.axis_angle((0, 1, 0), j2), [0, 0, 0.1])
            @ se3.make(se3.axis_angle((0, 1, 0), j3), [0.4, 0, 0])
            @ se3.make(se3.axis_angle((1, 0, 0), j4), [0.35, 0, 0]) @ GRIPPER_MARKER)


def set_pose(graph: TransformGraph, pose: tuple[float, float, float, float]) -> None:
    graph.set_joints(dict(zip(("j1", "j2", "j3", "j4"), pose)))


def tracker(rng: np.random.Generator, camera_marker: np.ndarray, outlier: bool) -> np.ndarray:
    """A marker tracker's T_camera_marker: noise about the marker's own centre (2 mm, 0.5 deg), or far off."""
    return camera_marker @ (far_off(rng) if outlier else noise(rng, 0.002, 0.5 * DEG))


def test_registration_of_a_camera_through_a_marker_held_by_the_robot() -> None:
    rng = np.random.default_rng(11)
    graph = robot_graph()
    assert "camera" not in graph.frames
    registration = Registration(graph, "world", "camera", via=("camera", "marker"))
    assert graph.edge("camera", "marker").kind.value == "dynamic"  # created, ready for the tracker
    assert registration.sample() == 0  # no measurement yet

    per_pose, stamp, outliers, distances = 40, 0.0, [], []
    for pose in POSES:
        set_pose(graph, pose)
        camera_marker = se3.inverse(WORLD_CAMERA) @ forward_kinematics(pose)
        distances.append(float(np.linalg.norm(camera_marker[:3, 3])))
        for _ in range(per_pose):
            outlier = rng.random() < 0.1
            outliers.append(outlier)
            stamp += 0.01
            graph.set_transform("camera", "marker", tracker(rng, camera_marker, outlier), stamp)
            assert registration.sample() == 1
        assert registration.sample() == 0  # nothing new: the same measurement is not counted twice

    result = registration.install()
    is_outlier = np.array(outliers)
    good = int(np.count_nonzero(~is_outlier))
    translation, rotation = errors(result.transform, WORLD_CAMERA)
    # Rotation noise about the marker's centre moves the camera's estimated position by up to
    # distance * angle: the per-axis sigma of a sample of T_world_camera's translation is at most
    # sqrt(2 mm^2 + (d * 0.5 deg)^2). Bound: 4.5 standard errors of the mean.
    sigma_t = math.hypot(0.002, max(distances) * 0.5 * DEG)
    assert translation < 4.5 * sigma_t / math.sqrt(good)
    assert rotation < 4.5 * 0.5 * DEG / math.sqrt(good)
    assert np.all(~result.inliers[is_outlier]), "every far-off measurement is rejected"
    assert np.count_nonzero(~result.inliers[~is_outlier]) <= 0.02 * good
    assert result.paths["camera->marker"].used == result.used == registration.sample_count - result.rejected

    # installed: a static edge world -> camera, the temporary edge gone, lookups consistent
    edge = graph.edge("world", "camera")
    assert isinstance(edge, StaticEdge) and (edge.parent, edge.child) == ("world", "camera")
    with pytest.raises(TransformError, match="no edge joins camera and marker"):
        graph.edge("camera", "marker")
    assert np.allclose(graph.lookup("world", "camera"), result.transform)
    assert graph.path("camera", "marker")[:2] == ["camera", "world"]
    set_pose(graph, POSES[2])
    looked_up = graph.lookup("camera", "marker")
    expected = se3.inverse(WORLD_CAMERA) @ forward_kinematics(POSES[2])
    assert errors(looked_up, expected)[0] < 0.002
    with pytest.raises(RegistrationError, match="already installed"):
        registration.sample()


def test_several_temporary_paths_open_at_once_are_sampled_separately_and_combined() -> None:
    rng = np.random.default_rng(5)
    graph = robot_graph()
    world_marker2 = se3.make(se3.rpy_to_matrix(0.2, 0.0, -0.4), [0.9, -0.3, 0.0])  # a marker fixed on the table
    graph.add_static("world", "marker2", world_marker2)
    registration = Registration(graph, "world", "camera")
    registration.add_path(("camera", "marker"))
    registration.add_path([("camera", "marker2")], name="table marker")
    expected: list[tuple[str, np.ndarray]] = []
    for index, pose in enumerate(POSES[:4]):
        set_pose(graph, pose)
        for _ in range(15):
            m1 = tracker(rng, se3.inverse(WORLD_CAMERA) @ forward_kinematics(pose), False)
            m2 = tracker(rng, se3.inverse(WORLD_CAMERA) @ world_marker2, False)
            graph.set_transform("camera", "marker", m1)
            graph.set_transform("camera", "marker2", m2)
            # both temporary edges close a loop camera-marker-...-world-marker2-camera: each path must be
            # evaluated on its own edge, not through the other marker's
            assert registration.sample() == 2
            expected += [("camera->marker", forward_kinematics(pose) @ se3.inverse(m1)),
                         ("table marker", world_marker2 @ se3.inverse(m2))]
    assert np.allclose(registration.samples, np.array([value for _, value in expected]), atol=1e-9)

    result = registration.solve()
    assert result.labels == tuple(label for label, _ in expected)
    assert set(result.paths) == {"camera->marker", "table marker"}
    assert all(stats.used + stats.rejected == 60 for stats in result.paths.values())
    translation, rotation = errors(result.transform, WORLD_CAMERA)
    assert translation < 0.004 and rotation < 0.3 * DEG
    registration.install(result)
    assert {(e.parent, e.child) for e in graph.edges} & {("camera", "marker"), ("camera", "marker2")} == set()
    assert graph.path("world", "camera") == ["world", "camera"]


def test_frames_already_joined_are_refused_naming_the_path() -> None:
    graph = robot_graph()
    with pytest.raises(RegistrationError, match="world -> base -> link1 -> link2 -> link3 -> gripper"):
        Registration(graph, "world", "gripper")
    with pytest.raises(TransformError):  # also a TransformError, as other graph errors
        Registration(graph, "base", "link1", replace=True)  # an axis edge cannot be re-registered
    with pytest.raises(RegistrationError, match="two different frames"):
        Registration(graph, "world", "world")


def test_a_path_that_does_not_join_the_frames_is_refused_and_leaves_no_edge() -> None:
    graph = robot_graph()
    with pytest.raises(RegistrationError, match="camera->nowhere does not join world and camera"):
        Registration(graph, "world", "camera", via=("camera", "nowhere"))
    assert "camera" not in {frame for e in graph.edges for frame in (e.parent, e.child)}


def test_too_few_samples_from_the_graph() -> None:
    graph = robot_graph()
    registration = Registration(graph, "world", "camera", via=("camera", "marker"), min_samples=5)
    graph.set_transform("camera", "marker", np.eye(4))
    registration.sample()
    with pytest.raises(RegistrationError, match=r"needs at least 5 samples, got 1 \(from camera->marker\)"):
        registration.install()
    assert graph.edge("camera", "marker")  # nothing changed


def test_cancel_on_exit_restores_the_graph_and_only_new_measurements_count() -> None:
    graph = robot_graph()
    with Registration(graph, "world", "camera", via=("camera", "marker")) as registration:
        graph.set_transform("camera", "marker", se3.make(None, [0, 0, 1.0]), stamp=1.0)
        assert registration.sample() == 1
        assert registration.sample() == 0
        assert registration.sample(only_new=False) == 1
        set_pose(graph, POSES[1])  # the robot moved but the tracker did not report: still nothing new
        assert registration.sample() == 0
    assert not any("camera" in (e.parent, e.child) for e in graph.edges)


def test_sampling_at_a_time_interpolates_the_measurement() -> None:
    graph = robot_graph()
    registration = Registration(graph, "world", "camera", via=("camera", "marker"))
    graph.set_transform("camera", "marker", se3.make(None, [0, 0, 1.0]), stamp=1.0)
    graph.set_transform("camera", "marker", se3.make(None, [0, 0, 2.0]), stamp=2.0)
    assert registration.sample(time=1.5) == 1
    assert registration.sample(time=5.0, only_new=False) == 0  # outside the history: skipped
    expected = graph.lookup("world", "marker") @ se3.make(None, [0, 0, -1.5])
    assert np.allclose(registration.samples[0], expected)


def test_re_registration_replaces_the_static_edge_or_restores_it_on_cancel() -> None:
    rng = np.random.default_rng(4)
    graph = TransformGraph()
    old = graph.add_static("camera", "world", se3.inverse(WORLD_CAMERA) @ se3.make(None, [0.05, 0, 0]))
    with pytest.raises(RegistrationError, match="replace=True"):
        Registration(graph, "world", "camera")

    registration = Registration(graph, "world", "camera", replace=True)
    with pytest.raises(TransformError):
        graph.path("world", "camera")  # the old calibration is out while measuring
    registration.cancel()
    assert graph.edge("world", "camera") is old and np.allclose(graph.lookup("camera", "world"), old.transform())
    with pytest.raises(RegistrationError, match="does not join"):
        Registration(graph, "world", "camera", via=("camera", "nowhere"), replace=True)
    assert graph.edge("world", "camera") is old  # put back when the constructor fails

    registration = Registration(graph, "world", "camera", replace=True)
    for _ in range(30):
        registration.add_sample(WORLD_CAMERA @ noise(rng, 0.001, 0.2 * DEG))
    version = old.version
    result = registration.install()
    assert graph.edge("world", "camera") is old and old.version > version  # same edge, declared camera -> world
    assert np.allclose(graph.lookup("world", "camera"), result.transform)
    assert errors(result.transform, WORLD_CAMERA)[0] < 0.001
