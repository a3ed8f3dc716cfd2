"""The god-object against analytic answers: force and proxy on spheres and planes, sweeps across
corners, thin walls and holes that must never pop through, friction, passivity."""

import math

import numpy as np
import pytest

from coco_mr_haptics.expression import parse_surface
from coco_mr_haptics.proxy import GodObject, Material
from coco_mr_haptics.scene import Scene

DT = 1e-3
CHORD_DEPTH = 0.9e-3
"""How deep the straight chord between two successive proxies may cut the solid: sliding over a
convex edge within one step cuts its corner, but a chord through a 2 mm wall reaches 1 mm deep."""
RNG = np.random.default_rng(3)


def proxy_on(text, **material):
    scene = Scene(parse_surface(text))
    return scene, GodObject(scene, Material(**{"damping": 0.0, "max_force": 1e9, **material}))


def press(god, start, direction, depths):
    """Approach from ``start`` along ``direction`` at 1 mm per step, then visit ``depths``."""
    start, direction = np.asarray(start, float), np.asarray(direction, float)
    for s in np.arange(0.0, 1.0, 1e-3):
        god.step(*(start + direction * s))
        if god.contact:
            break
    return start + direction * s


@pytest.mark.parametrize("trial", range(8))
def test_sphere_force_is_stiffness_times_penetration_along_the_normal(trial):
    radius, k = 0.05, 900.0
    scene, god = proxy_on(f"translate([0.01, -0.02, 0.03], sphere({radius}))", stiffness=k)
    centre = np.array([0.01, -0.02, 0.03])
    normal = RNG.normal(size=3)
    normal /= np.linalg.norm(normal)
    press(god, centre + 0.1 * normal, -normal, None)
    for depth in (0.001, 0.004, 0.011):
        device = centre + (radius - depth) * normal
        assert god.step(*device)
        proxy = np.array(god.proxy)
        assert abs(scene.evaluate(*proxy)[0]) < 1e-6
        assert np.linalg.norm(proxy - (centre + radius * normal)) < 1e-6
        force = np.array(god.force)
        assert np.linalg.norm(force) == pytest.approx(k * depth, rel=1e-5)
        assert np.allclose(force / np.linalg.norm(force), normal, atol=1e-5)


def test_plane_force_and_proxy_while_sliding():
    k = 500.0
    normal = np.array([0.0, 0.6, 0.8])
    scene, god = proxy_on("plane(normal=[0, 0.6, 0.8], offset=0.01)", stiffness=k)
    press(god, 0.01 * normal + 0.05 * normal, -normal, None)
    tangent = np.cross(normal, [1.0, 0.0, 0.0])
    for i in range(200):  # slide 0.5 m/s with a varying depth: frictionless, the proxy follows
        depth = 0.002 + 0.001 * math.sin(i / 20)
        device = (0.01 - depth) * normal + tangent * 5e-4 * i + np.array([1e-4 * i, 0, 0])
        assert god.step(*device)
        proxy = np.array(god.proxy)
        assert abs(scene.evaluate(*proxy)[0]) < 1e-6
        assert np.allclose(proxy, device + depth * normal, atol=1e-6)
        assert np.allclose(god.force, k * depth * normal, atol=k * 1e-6)


def sweep(scene, god, path, speed=1.0):
    """Move the device along the polyline ``path`` at ``speed`` m/s at 1 kHz; check after each step
    that the proxy is outside and that its move stayed outside; return devices and proxies."""
    devices, proxies = [], []
    previous = None
    for a, b in zip(path[:-1], path[1:]):
        a, b = np.asarray(a, float), np.asarray(b, float)
        steps = max(1, int(math.ceil(np.linalg.norm(b - a) / (speed * DT))))
        for s in np.linspace(0.0, 1.0, steps + 1)[1:]:
            device = a + (b - a) * s
            god.step(*device)
            proxy = np.array(god.proxy)
            assert scene.evaluate(*proxy)[0] > -1e-6, f"proxy inside the solid at device {device}"
            if previous is not None:
                along = previous + np.outer(np.linspace(0, 1, 21), proxy - previous)
                assert scene.distance(along).min() > -CHORD_DEPTH, f"proxy crossed the solid at device {device}"
            previous = proxy
            devices.append(device)
            proxies.append(proxy)
    return np.array(devices), np.array(proxies)


def test_thin_wall_is_never_crossed():
    scene, god = proxy_on("box(size=[0.2, 0.002, 0.2])", stiffness=1000)
    # Straight through at 1 m/s, then obliquely back and forth through it from the far side.
    path = [(0.01, -0.05, 0.02), (0.01, 0.05, 0.02), (0.05, 0.03, -0.03), (-0.04, 0.04, 0.0)]
    god.step(*path[0])
    devices, proxies = sweep(scene, god, path)
    beyond = devices[:, 1] > 0.001
    assert beyond.sum() > 100  # the device really was on the other side for a long time
    assert np.all(proxies[:, 1] <= -0.001 + 1e-6)
    assert np.all(proxies[beyond][:, 1] == pytest.approx(-0.001, abs=1e-6))


def test_box_corner_sweep_keeps_the_proxy_on_the_entry_faces():
    scene, god = proxy_on("box(size=[0.1, 0.1, 0.1])", stiffness=1000)
    # In over the top near the corner, diagonally across the corner deep into the box, out the far side.
    path = [(0.06, 0.06, 0.08), (0.045, 0.045, 0.04), (0.02, 0.07, 0.03), (-0.06, -0.01, 0.045),
            (0.07, 0.07, 0.07)]
    god.step(*path[0])
    devices, proxies = sweep(scene, god, path)
    inside = scene.distance(devices) < -0.005
    assert inside.sum() > 50
    force_direction = proxies[inside] - devices[inside]
    # The proxy never appears on the bottom or on a face the device did not come through.
    assert np.all(proxies[:, 2] > -0.05 + 1e-6)
    assert np.all(np.einsum("ij,ij->i", force_direction, proxies[inside] - 0.0) > 0)


def test_through_a_box_edge_and_out_of_the_opposite_one():
    scene, god = proxy_on("box(size=[0.1, 0.1, 0.1])", stiffness=1000)
    # In through the edge x = z = 0.05 at 1 m/s, through the centre, out at the edge x = z = -0.05.
    path = [(0.07, 0.01, 0.07), (-0.07, 0.01, -0.07)]
    god.step(*path[0])
    devices, proxies = sweep(scene, god, path)
    inside = scene.distance(devices) < 0.0
    assert inside.sum() > 120
    # Held on the entry faces (top z = 0.05 or side x = 0.05), even when the device is nearer the
    # opposite ones, until the device is out again.
    on_entry = (proxies[:, 2] > 0.05 - 1e-6) | (proxies[:, 0] > 0.05 - 1e-6)
    assert np.all(on_entry[inside])


def test_hole_walls_hold_the_proxy():
    scene, god = proxy_on("difference(box(size=[0.1, 0.1, 0.02]), cylinder(radius=0.01, height=0.05))",
                          stiffness=1000)
    # Pressed 2 mm into the top, across the hole and on into the material beyond its far rim.
    path = [(-0.04, 0.0, 0.03), (-0.04, 0.0, 0.008), (0.04, 0.0, 0.008), (0.04, 0.0, 0.03)]
    god.step(*path[0])
    devices, proxies = sweep(scene, god, path)
    over_hole = np.abs(devices[:, 0]) < 0.009
    assert np.all(np.linalg.norm(proxies[over_hole] - devices[over_hole], axis=1) < 1e-9)  # free in the hole
    past = (devices[:, 0] > 0.012) & (devices[:, 2] < 0.0099)
    assert past.sum() > 20
    # Past the far rim inside the material, the proxy is held in the hole on its wall.
    radial = np.hypot(proxies[past][:, 0], proxies[past][:, 1])
    assert np.allclose(radial, 0.01, atol=1e-6)
    assert np.all(proxies[past][:, 2] < 0.0099)


def test_friction_sticks_then_slides_with_the_dynamic_force():
    k, mu_s, mu_d, depth = 1000.0, 0.6, 0.4, 0.002
    scene, god = proxy_on("plane()", stiffness=k, static_friction=mu_s, dynamic_friction=mu_d)
    press(god, (0, 0, 0.01), (0, 0, -1), None)
    god.step(0, 0, -depth)
    anchor = np.array(god.proxy)
    normal_force = k * depth
    for x in np.arange(1e-4, 1.2e-3, 1e-4):  # inside the static cone: mu_s * depth = 1.2 mm
        god.step(x, 0, -depth)
        assert god.sticking
        assert np.allclose(god.proxy, anchor, atol=1e-9)
        assert god.force[0] == pytest.approx(-k * x, rel=1e-6)
        assert god.force[2] == pytest.approx(normal_force, rel=1e-6)
    god.step(1.3e-3, 0, -depth)  # out of the static cone: slides
    assert not god.sticking
    for x in np.arange(1.4e-3, 0.02, 5e-4):
        god.step(x, 0, -depth)
        assert not god.sticking
        assert god.force[0] == pytest.approx(-mu_d * normal_force, rel=1e-6)
        assert god.force[2] == pytest.approx(normal_force, rel=1e-6)
        assert abs(scene.evaluate(*god.proxy)[0]) < 1e-9
    # The hand stops: the proxy sticks where it trails, and a move back within the cone keeps it.
    held = np.array(god.proxy)
    god.step(x, 0, -depth)
    god.step(x - 5e-4, 0, -depth)
    assert god.sticking and np.allclose(god.proxy, held, atol=1e-9)
    # Forward again needs the static cone: 0.8 mm trailing + 0.3 mm < 1.2 mm, still stuck.
    god.step(x + 3e-4, 0, -depth)
    assert god.sticking


def work_on_device(god, positions):
    """Work the contact does on the device, with the force held over each step (zero-order hold)."""
    work = 0.0
    previous = positions[0]
    god.step(*previous)
    for position in positions[1:]:
        velocity = (position - previous) / DT
        force = np.array(god.force)
        work += float(force @ (position - previous))
        god.step(*position, *velocity)
        previous = position
    return work


def press_cycles(normal, centre_offset):
    t = np.arange(0.0, 2.0, DT)
    depth = 0.006 * np.sin(2 * math.pi * 2 * t) ** 2 - 0.001  # in and out 4 times, 6 mm deep
    return centre_offset - depth[:, None] * normal


@pytest.mark.parametrize("text,normal,surface_point", [
    ("plane()", np.array([0.0, 0.0, 1.0]), np.zeros(3)),
    ("sphere(0.05)", np.array([0.6, 0.0, 0.8]), 0.05 * np.array([0.6, 0.0, 0.8])),
])
def test_passivity_with_damping(text, normal, surface_point):
    k = 3000.0
    positions = press_cycles(normal, surface_point)
    # Damping above the zero-order hold's stiffness * T / 2: the contact only absorbs energy.
    scene, god = proxy_on(text, stiffness=k, damping=k * DT / 2 * 1.2)
    assert work_on_device(god, positions) < 0.0
    # Without damping the held spring returns more than it took: what the test must catch.
    scene, god = proxy_on(text, stiffness=k, damping=0.0)
    assert work_on_device(god, positions) > 0.0


def test_friction_only_dissipates():
    """Pressing in and out while stroking sideways, with friction: the friction force opposes the
    sliding, so the contact absorbs more energy than without friction and still returns none."""
    t = np.arange(0.0, 2.0, DT)
    depth = 0.004 * np.sin(2 * math.pi * t) ** 2 - 0.0005
    positions = np.stack([0.03 * np.sin(2 * math.pi * 1.5 * t), 0.0 * t, -depth], axis=1)
    k = 2000.0
    absorbed = {}
    for mu in (0.0, 0.5):
        scene, god = proxy_on("plane()", stiffness=k, damping=k * DT / 2 * 1.2, static_friction=mu,
                              dynamic_friction=0.8 * mu)
        absorbed[mu] = -work_on_device(god, positions)
    assert absorbed[0.0] > 0.0
    assert absorbed[0.5] > absorbed[0.0] * 1.5
