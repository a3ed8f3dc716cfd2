"""Implicit primitives and their combinations against their analytic signed distances."""

import math

import numpy as np
import pytest
from coco_core.errors import CocoError, HapticDeviceError, SurfaceExpressionError, WrongTypeError

from coco_mr_haptics.expression import parse_surface
from coco_mr_haptics.implicit import (Box, Capsule, Cylinder, Difference, Intersection, Placed, Plane, Sphere,
                                      Torus, Union, pose_from_xyz_rpy)
from coco_mr_haptics.scene import Scene

RNG = np.random.default_rng(7)


def analytic_box(p, h):
    q = np.abs(p) - h
    return np.linalg.norm(np.maximum(q, 0.0)) + min(q.max(), 0.0)


CASES = [
    (Sphere(0.05), lambda p: np.linalg.norm(p) - 0.05),
    (Plane((0.0, 1.0, 1.0), 0.02), lambda p: (p[1] + p[2]) / math.sqrt(2) - 0.02),
    (Box((0.1, 0.06, 0.04)), lambda p: analytic_box(p, np.array([0.05, 0.03, 0.02]))),
    (Cylinder(0.03, 0.08), lambda p: (np.linalg.norm(np.maximum([math.hypot(p[0], p[1]) - 0.03, abs(p[2]) - 0.04], 0))
                                      + min(max(math.hypot(p[0], p[1]) - 0.03, abs(p[2]) - 0.04), 0.0))),
    (Capsule(0.02, 0.1), lambda p: np.linalg.norm(p - [0, 0, np.clip(p[2], -0.05, 0.05)]) - 0.02),
    (Torus(0.05, 0.01), lambda p: math.hypot(math.hypot(p[0], p[1]) - 0.05, p[2]) - 0.01),
]


@pytest.mark.parametrize("surface,expected", CASES, ids=lambda c: repr(c) if not callable(c) else "")
def test_primitive_distance_and_gradient(surface, expected):
    scene = Scene(surface)
    points = RNG.uniform(-0.09, 0.09, size=(300, 3))
    h = 1e-7
    for p in points:
        f, gx, gy, gz = scene.evaluate(*p)
        assert f == pytest.approx(expected(p), abs=1e-12)
        gradient = np.array([gx, gy, gz])
        numeric = np.array([(expected(p + h * e) - expected(p - h * e)) / (2 * h) for e in np.eye(3)])
        if np.linalg.norm(numeric) > 0.999:  # away from the few points where f has a kink
            assert np.allclose(gradient, numeric, atol=1e-5)
        assert np.linalg.norm(gradient) == pytest.approx(1.0, abs=1e-9)


def test_placement_rotates_and_translates():
    pose = pose_from_xyz_rpy((0.1, -0.2, 0.3), (0.3, -0.5, 1.1))
    scene = Scene(Placed(Box((0.1, 0.06, 0.04)), pose))
    inverse = np.linalg.inv(np.array(pose))
    for p in RNG.uniform(-0.3, 0.4, size=(100, 3)):
        local = inverse[:3, :3] @ p + inverse[:3, 3]
        f, *g = scene.evaluate(*p)
        assert f == pytest.approx(analytic_box(local, np.array([0.05, 0.03, 0.02])), abs=1e-12)
        local_g = Scene(Box((0.1, 0.06, 0.04))).evaluate(*local)[1:]
        assert np.allclose(g, np.array(pose)[:3, :3] @ local_g, atol=1e-12)


def test_combinations_are_min_max_and_difference():
    a, b, c = Sphere(0.05), Placed(Sphere(0.04), pose_from_xyz_rpy((0.05, 0, 0))), Box((0.02, 0.02, 0.2))
    sa, sb, sc = Scene(a), Scene(b), Scene(c)
    union, inter, diff = Scene(Union([a, b, c])), Scene(Intersection([a, b])), Scene(Difference(a, [b, c]))
    for p in RNG.uniform(-0.1, 0.1, size=(300, 3)):
        fa, fb, fc = sa.evaluate(*p)[0], sb.evaluate(*p)[0], sc.evaluate(*p)[0]
        assert union.evaluate(*p)[0] == min(fa, fb, fc)
        assert inter.evaluate(*p)[0] == max(fa, fb)
        assert diff.evaluate(*p)[0] == max(fa, -fb, -fc)
    # The gradient is that of the active branch, negated for what a difference removes.
    # At x = 0.02 the removed sphere's surface (x = 0.01) is nearest; the solid lies at x < 0.01.
    f, *g = diff.evaluate(0.02, 0.0, 0.0)
    assert f == pytest.approx(0.01) and np.allclose(g, [1, 0, 0], atol=1e-12)


def test_combination_distance_is_a_lower_bound():
    scene = Scene(parse_surface("difference(box(size=[0.2,0.2,0.1]), translate([0,0,0.05], sphere(0.04)))"))
    surface = RNG.uniform(-0.1, 0.1, size=(20000, 3))
    surface = surface[np.abs(scene.distance(surface)) < 2e-4]  # points near the surface
    for p in RNG.uniform(-0.15, 0.15, size=(200, 3)):
        f = scene.evaluate(*p)[0]
        assert abs(f) <= np.min(np.linalg.norm(surface - p, axis=1)) + 2e-4


def test_frame_pose_moves_only_its_branch():
    scene = Scene(parse_surface("union(sphere(0.01), frame('tool', translate([0.1, 0, 0], sphere(0.02))))"))
    assert scene.evaluate(0.1, 0, 0)[0] == pytest.approx(-0.02)
    moved = np.eye(4)
    moved[2, 3] = 0.5
    scene.set_frame_pose("tool", moved)
    assert scene.evaluate(0.1, 0, 0.5)[0] == pytest.approx(-0.02)
    assert scene.evaluate(0, 0, 0)[0] == pytest.approx(-0.01)


def test_surfaces_that_cannot_be_built_raise_coco_errors_that_stay_value_errors() -> None:
    with pytest.raises(SurfaceExpressionError, match="plane normal") as caught:
        Plane((0.0, 0.0, 0.0))
    assert isinstance(caught.value, CocoError) and isinstance(caught.value, ValueError)
    with pytest.raises(SurfaceExpressionError, match="plane normal must not be zero"):
        parse_surface("plane([0, 0, 0])")
    with pytest.raises(WrongTypeError) as not_a_surface:
        Scene(object())  # type: ignore[arg-type]
    assert isinstance(not_a_surface.value, TypeError)


def test_a_hand_trajectory_too_short_is_a_haptic_device_error(tmp_path) -> None:
    from coco_mr_haptics.simulated_device import HandTrajectory

    path = tmp_path / "hand.csv"
    path.write_text("time,x,y,z\n0,0,0,0\n")
    with pytest.raises(HapticDeviceError, match="at least 2 rows") as caught:
        HandTrajectory(path)
    assert isinstance(caught.value, CocoError) and isinstance(caught.value, ValueError)
