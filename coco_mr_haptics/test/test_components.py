"""HapticRenderer, HapticImplicitSurf, SimulatedDevice and HapticRecorder: the closed loop against
its analytic equilibrium, forces combined, frames, attributes at run time, the recorder's summary."""

import json
import math

import numpy as np
import pytest

from coco_core.application import Application
from coco_core.component import Component
from coco_core.policy import BufferPolicy, ConnectionPolicy
from coco_core.ports import InputPort, OutputPort
from coco_core.transforms import se3
from coco_core.transforms.samples import FramePose
from coco_mr_haptics.implicit_surf import HapticImplicitSurf
from coco_mr_haptics.recorder import HapticRecorder
from coco_mr_haptics.renderer import HapticRenderer
from coco_mr_haptics.simulated_device import SimulatedDevice
from coco_mr_haptics.types import HapticDeviceState, HapticForce


def hand_csv(tmp_path, rows):
    path = tmp_path / "hand.csv"
    path.write_text("time,x,y,z\n" + "".join(f"{t},{x},{y},{z}\n" for t, x, y, z in rows))
    return str(path)


def loop(tmp_path, hand_rows, peers, renderer_attributes=None, device_attributes=None, transforms=None):
    """Device and renderer wired in one application, stepped by hand at 1 kHz of simulated time."""
    app = Application("haptic_test")
    if transforms:
        transforms(app.transforms)
    device = SimulatedDevice("device", trajectory=hand_csv(tmp_path, hand_rows), time_step=1e-3,
                             **(device_attributes or {}))
    renderer = HapticRenderer("renderer", **(renderer_attributes or {}))
    for peer in peers:
        renderer.add_peer(peer)
    recorder = HapticRecorder("recorder", path=str(tmp_path / "h.csv"), summary=str(tmp_path / "s.json"))
    for component in (device, renderer, recorder):
        app.add(component)
    app.connect("device.state", "renderer.device")
    app.connect("renderer.force", "device.force")
    app.connect("renderer.sample", "recorder.samples", ConnectionPolicy(BufferPolicy.BUFFER, size=100000))
    for component in (device, renderer, recorder):
        component.configure()

    def run(seconds):
        for _ in range(int(round(seconds * 1000))):
            device.step()
            renderer.step()
        recorder.step()

    return device, renderer, recorder, run


def test_closed_loop_settles_at_the_coupling_equilibrium(tmp_path):
    k, kc, push = 800.0, 300.0, 0.02
    plane = HapticImplicitSurf("plane", surface="plane()", stiffness=k, damping=1.0)
    device, renderer, recorder, run = loop(tmp_path, [(0, 0, 0, 0.05), (0.3, 0, 0, -push), (5, 0, 0, -push)],
                                           [plane], device_attributes={"coupling_stiffness": kc})
    run(2.0)
    # The hand is 2 cm under the surface; the handle stops where the surface's spring balances the
    # stretched coupling: k d = kc (push - d).
    depth = kc * push / (k + kc)
    assert -device.z == pytest.approx(depth, abs=2e-5)
    summary = recorder.report()
    assert summary["samples"] == 2000
    assert summary["energy_in_j"] > 0 and summary["passive"], summary
    assert summary["max_penetration_m"] == pytest.approx(depth, rel=0.3)
    assert plane.proxy_object.force[2] == pytest.approx(k * depth, rel=2e-3)
    assert plane.proxy_object.proxy[2] == pytest.approx(0.0, abs=1e-9)
    # At run time, a stiffer surface: a new equilibrium.
    plane.set_attribute_now("stiffness", 2000.0)
    run(1.0)
    assert -device.z == pytest.approx(kc * push / (2000.0 + kc), abs=2e-5)


def test_device_limits_force_and_workspace(tmp_path):
    plane = HapticImplicitSurf("plane", surface="plane()", stiffness=3000.0, max_force=100.0)
    device, renderer, recorder, run = loop(
        tmp_path, [(0, 0, 0, 0.05), (0.3, 0.5, 0, -0.05), (5, 0.5, 0, -0.05)], [plane],
        renderer_attributes={"max_force": 2.0},
        device_attributes={"coupling_stiffness": 100.0, "workspace_max": [0.08, 0.1, 0.1]})
    run(2.0)
    assert device.x == pytest.approx(0.08)  # held at the workspace's edge
    # The renderer's clamp (2 N) balances the coupling: 100 N/m * (0.05 - d) = 2 N.
    assert -device.z == pytest.approx(0.05 - 2.0 / 100.0, abs=1e-4)
    assert max(float(row.split(",")[9]) for row in open(tmp_path / "h.csv").readlines()[1:]) <= 2.0 + 1e-9


@pytest.mark.parametrize("combine,expected", [("sum", 800.0 + 400.0), ("first", 800.0)])
def test_renderers_combine(tmp_path, combine, expected):
    a = HapticImplicitSurf("a", surface="plane()", stiffness=800.0)
    b = HapticImplicitSurf("b", surface="plane()", stiffness=400.0)
    device, renderer, recorder, run = loop(tmp_path, [(0, 0, 0, 0.05), (0.3, 0, 0, -0.02), (5, 0, 0, -0.02)],
                                           [a, b], renderer_attributes={"combine": combine})
    run(2.0)
    kc = device.coupling_stiffness
    assert -device.z == pytest.approx(kc * 0.02 / (expected + kc), abs=2e-5)
    rows = open(tmp_path / "h.csv").readlines()
    assert rows[-1].split(",")[11] == "a"


def test_workspace_is_a_frame_and_surfaces_follow_frames(tmp_path):
    # The device's workspace is turned 90 degrees about z and lifted 0.1 m; the sphere sits on frame
    # 'ball' at (0.2, 0, 0) in the world. The hand pushes along the workspace's -y, i.e. the world's +x.
    def frames(graph):
        graph.add_static("world", "ws", se3.make(se3.rpy_to_matrix(0.0, 0.0, math.pi / 2), (0.0, 0.0, 0.1)))
        graph.add_static("world", "ball", se3.make(None, (0.2, 0.0, 0.0)))

    ball = HapticImplicitSurf("ball", surface="frame('ball', sphere(0.05))", stiffness=500.0)
    device, renderer, recorder, run = loop(
        tmp_path, [(0, 0, 0, -0.1), (0.5, 0, -0.16, -0.1), (5, 0, -0.16, -0.1)], [ball],
        renderer_attributes={"device_frame": "ws"},
        device_attributes={"workspace_min": [-0.3, -0.3, -0.3], "workspace_max": [0.3, 0.3, 0.3]},
        transforms=frames)
    run(2.0)
    kc = device.coupling_stiffness
    depth = kc * (0.16 - 0.15) / (500.0 + kc)
    # Handle in the workspace: (0, -(0.15 + d), -0.1) -> world (0.15 + d, 0, 0): against the ball.
    assert device.y == pytest.approx(-(0.15 + depth), abs=2e-5)
    assert ball.proxy_object.proxy[0] == pytest.approx(0.15, abs=1e-9)
    # The force comes back in the workspace frame: along +y there.
    force = device._rendered
    assert force[1] == pytest.approx(500.0 * depth, rel=2e-3) and abs(force[0]) < 1e-9


class Handle(Component):
    """A device driver's ports, for a renderer scheduled alone."""

    state = OutputPort(HapticDeviceState)
    force = InputPort(HapticForce)


def test_implicit_surf_alone():
    app = Application("alone")
    surf = HapticImplicitSurf("surf", surface="sphere(0.1)", stiffness=1000.0, damping=0.0)
    handle = Handle("handle")
    app.add(surf)
    app.add(handle)
    app.connect("handle.state", "surf.device")
    app.connect("surf.force", "handle.force")
    surf.configure()
    for z in (0.2, 0.15, 0.11, 0.1, 0.097):
        handle.state.write(HapticDeviceState((0.0, 0.0, z)))
        surf.step()
    status, value = handle.force.read()
    assert value.force[2] == pytest.approx(1000.0 * 0.003, rel=1e-6)


def test_implicit_surf_alone_never_sends_a_non_finite_force():
    app = Application("alone_nan")
    # A finite but absurd stiffness and a deep contact overflow the force (an infinite one is refused).
    surf = HapticImplicitSurf("surf", surface="sphere(10)", stiffness=1e308)
    handle = Handle("handle")
    app.add(surf)
    app.add(handle)
    app.connect("handle.state", "surf.device")
    app.connect("surf.force", "handle.force")
    surf.configure()
    for z in (20.0, 15.0, 11.0, 10.0, 9.7, 8.0, math.nan):
        handle.state.write(HapticDeviceState((0.0, 0.0, z)))
        surf.step()
        assert handle.force.read()[1].force == (0.0, 0.0, 0.0)
    assert surf.force_faults >= 1 and surf.stats.refused == 1


def test_recorder_summary_file(tmp_path):
    plane = HapticImplicitSurf("plane", surface="plane()", stiffness=800.0)
    device, renderer, recorder, run = loop(tmp_path, [(0, 0, 0, 0.05), (0.3, 0, 0, -0.01), (0.6, 0, 0, 0.05)],
                                           [plane])
    run(1.0)
    recorder.stop()
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["samples"] == 1000
    assert summary["contact_samples"] > 50 and summary["contacts_by_renderer"] == {"plane": summary["contact_samples"]}
    assert summary["energy_out_j"] <= summary["energy_in_j"]
    header, *rows = (tmp_path / "h.csv").read_text().splitlines()
    assert header.startswith("time,device_x") and len(rows) == 1000


class Hand(Component):
    """What drives the hand port: here poses, as BagReplay makes them of a bag's PoseStamped."""

    pose = OutputPort(FramePose)


def hand_rig(name: str) -> tuple[SimulatedDevice, Hand]:
    """A simulated device whose hand port is driven by poses, configured."""
    app = Application(name)
    device = SimulatedDevice("device", time_step=1e-3, coupling_stiffness=300.0)
    hand = Hand("hand")
    app.add(device)
    app.add(hand)
    app.connect("hand.pose", "device.hand")
    device.configure()
    return device, hand


def test_hand_port_takes_poses():
    device, hand = hand_rig("hand")
    target = np.eye(4)
    target[:3, 3] = (0.02, -0.01, 0.03)
    for _ in range(3000):
        hand.pose.write(FramePose("haptic_workspace", "hand", target))
        device.step()
    # No force: the coupling pulls the handle onto the hand.
    assert (device.x, device.y, device.z) == pytest.approx((0.02, -0.01, 0.03), abs=1e-6)


def test_a_non_finite_hand_pose_is_refused_and_the_handle_stays_where_it_was():
    """A hand tracker that loses the hand may publish NaN (issue 20's bad input): counted as refused,
    the last finite target kept, the handle never NaN."""
    device, hand = hand_rig("hand_nan")
    target = np.eye(4)
    target[:3, 3] = (0.02, -0.01, 0.03)
    lost = target.copy()
    lost[:3, 3] = math.nan
    for cycle in range(3000):
        hand.pose.write(FramePose("haptic_workspace", "hand", lost if cycle % 100 == 50 else target))
        device.step()
        assert math.isfinite(device.x + device.y + device.z + device.vx), cycle
    assert device.stats.refused == 30
    assert (device.x, device.y, device.z) == pytest.approx((0.02, -0.01, 0.03), abs=1e-6)


def test_a_non_finite_force_is_never_sent_to_the_device(tmp_path):
    """An absurd stiffness and a deep contact overflow the proxy's force to NaN: the renderer sends
    zero instead, counts the fault (summary, sample) and restarts the proxy; the device never sees a NaN."""
    wild = HapticImplicitSurf("wild", surface="plane()", stiffness=1e308)
    device, renderer, recorder, run = loop(tmp_path, [(0, 0, 0, 0.05), (0.3, 0, 0, -5), (1, 0, 0, -5)], [wild],
                                           device_attributes={"workspace_min": [-10] * 3, "workspace_max": [10] * 3})
    forces = []
    for _ in range(1000):
        device.step()
        renderer.step()
        forces.append(device.force.read()[1].force)
    recorder.stop()
    assert all(math.isfinite(component) for force in forces for component in force)
    assert math.isfinite(device.x + device.y + device.z)
    summary = json.loads((tmp_path / "s.json").read_text())
    assert renderer.force_faults == wild.force_faults == summary["force_faults"] > 0
    assert math.isfinite(summary["energy_out_j"]) and math.isfinite(summary["max_force_n"])


def test_a_non_finite_device_state_is_refused_and_does_not_poison_the_proxy():
    app = Application("nan_device")
    renderer = HapticRenderer("renderer")
    plane = HapticImplicitSurf("plane", surface="plane()", stiffness=1000.0, damping=0.0)
    renderer.add_peer(plane)
    handle = Handle("handle")
    app.add(renderer)
    app.add(handle)
    app.connect("handle.state", "renderer.device")
    app.connect("renderer.force", "handle.force")
    renderer.configure()
    for position in ((0.0, 0.0, 0.05), (0.0, 0.0, -0.001), (math.nan, 0.0, -0.002), (0.0, math.inf, 0.0)):
        handle.state.write(HapticDeviceState(position))
        renderer.step()
        assert all(math.isfinite(v) for v in handle.force.read()[1].force)
    assert handle.force.read()[1].force == (0.0, 0.0, 0.0)
    assert renderer.stats.refused == 2
    handle.state.write(HapticDeviceState((0.0, 0.0, -0.003)))  # the proxy still holds the surface
    renderer.step()
    assert handle.force.read()[1].force[2] == pytest.approx(1000.0 * 0.003, rel=1e-6)
    assert plane.proxy_object.proxy[2] == pytest.approx(0.0, abs=1e-9)


class ForceSource(Component):
    """What a renderer looks like to a device: a force output."""

    force = OutputPort(HapticForce)


def test_the_simulated_device_refuses_a_non_finite_force():
    app = Application("device_nan")
    device = SimulatedDevice("device", time_step=1e-3)
    source = ForceSource("source")
    app.add(device)
    app.add(source)
    app.connect("source.force", "device.force")
    device.configure()
    source.force.write(HapticForce((math.nan, 0.0, 0.0)))
    device.step()
    assert device.stats.refused == 1
    assert math.isfinite(device.x + device.vx)


@pytest.mark.parametrize("special", ["/dev/zero", "fifo"])
def test_a_trajectory_that_is_no_regular_file_is_refused_naming_the_attribute(tmp_path, special):
    # /dev/zero grew the process to 2.4 GB in 4 s, a FIFO blocked on_config for ever.
    import os
    import signal

    from coco_core.errors import FileReadError

    # Setting the attribute refuses such a name (test_haptic_app); here the file is swapped after it.
    path = tmp_path / "hand.csv"
    path.write_text("time,x,y,z\n0,0,0,0\n1,0,0,0\n")
    device = SimulatedDevice("device", trajectory=str(path))
    path.unlink()
    if special == "fifo":
        os.mkfifo(path)
    else:
        path.symlink_to(special)
    kind = "a FIFO" if special == "fifo" else "a character device"
    signal.signal(signal.SIGALRM, lambda *_: pytest.fail("reading the trajectory did not end"))
    signal.setitimer(signal.ITIMER_REAL, 10)
    try:
        with pytest.raises(FileReadError) as raised:
            device.on_config()
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
    assert str(raised.value) == (f"attribute device.trajectory: hand trajectory {path} is {kind}, not a regular "
                                 "file; expected a CSV file time,x,y,z[,buttons]")


def test_a_trajectory_with_a_short_row_or_a_non_finite_number_is_an_error_at_its_line(tmp_path):
    from coco_core.errors import HapticDeviceError

    for row, problem in (("0.1,0,0", "expected numbers"), ("0.1,0,nan,0", "expected finite numbers")):
        path = tmp_path / "hand.csv"
        path.write_text(f"time,x,y,z\n0,0,0,0\n{row}\n")
        with pytest.raises(HapticDeviceError, match=rf"hand\.csv:3: {problem}"):
            SimulatedDevice("device", trajectory=str(path)).on_config()


def test_a_workspace_not_yet_joined_renders_zero_force_until_it_is(tmp_path):
    """The palpation application's device is registered to the scene only by the touch on the
    marker: until the graph joins the device's workspace to the render frame, the loop keeps its
    rate with zero force and no sample, then renders as soon as the edge is there. A workspace
    never joined is recorded as damage (the launcher exits 1)."""
    plane = HapticImplicitSurf("plane", surface="plane()", stiffness=800.0)
    device, renderer, recorder, run = loop(tmp_path, [(0, 0, 0, 0.05), (0.2, 0, 0, -0.01), (5, 0, 0, -0.01)],
                                           [plane], renderer_attributes={"device_frame": "workspace"})
    run(0.5)
    assert renderer.unjoined_cycles == 500 and device.force.read()[1].force == (0.0, 0.0, 0.0)
    assert recorder.report()["samples"] == 0 and device.z < -0.009, "the hand went through: nothing rendered"
    renderer.app.transforms.add_static("world", "workspace")
    run(0.5)
    assert renderer.unjoined_cycles == 500 and recorder.report()["samples"] == 500
    assert plane.proxy_object.contact and device.force.read()[1].force[2] > 1.0
    renderer.stop()
    assert not renderer.app.damage
    never = HapticRenderer("never", device_frame="elsewhere")
    never_app = Application("never")
    never_app.add(never)
    never.configure()
    never.step()
    never.stop()
    assert never.unjoined_cycles == 0, "no device state: nothing to render, nothing counted"
    (tmp_path / "blind").mkdir()
    blind_device, blind, _, blind_run = loop(tmp_path / "blind", [(0, 0, 0, 0.05), (1, 0, 0, 0.05)],
                                             [HapticImplicitSurf("p2", surface="plane()")],
                                             renderer_attributes={"device_frame": "elsewhere"})
    blind_run(0.1)
    blind.stop()
    assert any("was never joined to world" in damage for damage in blind.app.damage)


class DepthSink(Component):
    penetration = InputPort(float)
    samples = InputPort(object)


def test_the_penetration_port_carries_each_cycles_depth():
    """What a display colours a hand model by: the sample's depth, every cycle, 0 out of contact."""
    app = Application("penetration")
    renderer = HapticRenderer("renderer")
    renderer.add_peer(HapticImplicitSurf("plane", surface="plane()", stiffness=1000.0, damping=0.0))
    handle, sink = Handle("handle"), DepthSink("sink")
    for component in (renderer, handle, sink):
        app.add(component)
    app.connect("handle.state", "renderer.device")
    app.connect("renderer.penetration", "sink.penetration", ConnectionPolicy(BufferPolicy.BUFFER, size=100))
    app.connect("renderer.sample", "sink.samples", ConnectionPolicy(BufferPolicy.BUFFER, size=100))
    renderer.configure()
    for z in (0.01, 0.0, -0.002, -0.004, 0.01):
        handle.state.write(HapticDeviceState((0.0, 0.0, z)))
        renderer.step()
    depths, samples = sink.penetration.read_all(), sink.samples.read_all()
    assert depths == [sample.depth for sample in samples]
    assert depths[0] == 0.0 and depths[3] == pytest.approx(0.004, abs=1e-6) and depths[-1] == 0.0


class ProxySink(Component):
    proxy = InputPort(FramePose)
    force = InputPort(tuple)
    samples = InputPort(object)


def test_the_proxy_and_its_force_for_a_display():
    """What a display draws the contact by: the proxy's pose and the force at it, in the render frame,
    the sample's every cycle (the device where it is free; on the surface in contact)."""
    app = Application("proxy")
    renderer = HapticRenderer("renderer")
    renderer.add_peer(HapticImplicitSurf("plane", surface="plane()", stiffness=1000.0, damping=0.0))
    handle, sink = Handle("handle"), ProxySink("sink")
    for component in (renderer, handle, sink):
        app.add(component)
    app.connect("handle.state", "renderer.device")
    for port, to in (("proxy", "proxy"), ("proxy_force", "force"), ("sample", "samples")):
        app.connect(f"renderer.{port}", f"sink.{to}", ConnectionPolicy(BufferPolicy.BUFFER, size=100))
    renderer.configure()
    for z in (0.01, -0.004):
        handle.state.write(HapticDeviceState((0.02, 0.0, z)))
        renderer.step()
    poses, forces, samples = sink.proxy.read_all(), sink.force.read_all(), sink.samples.read_all()
    assert [(pose.target, pose.source) for pose in poses] == [("world", "proxy")] * 2
    assert [tuple(pose.transform[:3, 3]) for pose in poses] == [sample.proxy for sample in samples]
    assert forces == [sample.force for sample in samples]
    assert poses[0].transform[2, 3] == pytest.approx(0.01) and forces[0] == (0.0, 0.0, 0.0)
    assert poses[1].transform[2, 3] == pytest.approx(0.0, abs=1e-9), "held on the plane"
    assert forces[1] == pytest.approx((0.0, 0.0, 4.0), abs=1e-6), "1000 N/m x 4 mm, out of the plane"


def test_a_workspace_behind_an_edge_without_a_value_yet_gets_zero_force(tmp_path):
    """The device's workspace joined to the render frame through a dynamic edge that has had no value
    yet (a tracker declared in the file, silent so far): zero force and no sample, not an error; once
    the edge has a value, the loop renders."""
    _, renderer, recorder, run = loop(
        tmp_path, [(0, 0, 0, -0.01), (1, 0, 0, -0.01)],
        [HapticImplicitSurf("plane", surface="plane()", stiffness=800.0)],
        renderer_attributes={"device_frame": "tracker"},
        transforms=lambda graph: graph.add_dynamic("world", "tracker"))
    run(0.05)
    assert renderer.unjoined_cycles == 50 and renderer.stats.errors == 0 and recorder.rows == 0
    renderer.transform_graph.set_transform("world", "tracker", np.eye(4), stamp=1.0)
    run(0.05)
    assert recorder.rows > 0 and renderer.stats.errors == 0


def test_the_steady_haptic_cycle_leaves_nothing_for_the_garbage_collector(tmp_path):
    """A 1 kHz loop in contact (device, renderer, the recorder draining the samples) allocates only
    what reference counting frees: after 2,000 cycles no new container object is alive in the
    collector's young generation (nothing a collection would have to scan, in a gc="between_cycles"
    process or any other), and the memory in use stays flat."""
    import gc
    import tracemalloc

    _, _, _, run = loop(tmp_path, [(0, 0.0, 0.0, -0.01), (10, 0.05, 0.0, -0.01)],
                        [HapticImplicitSurf("plane", surface="plane()", stiffness=800.0),
                         HapticImplicitSurf("ball", surface="translate([0, 0.05, 0], sphere(0.02))", stiffness=800.0)])
    for _ in range(5):  # warm-up: contact made, every path taken once
        run(0.1)
    was = gc.isenabled()
    gc.disable()
    try:
        gc.collect()
        tracemalloc.start()
        before = tracemalloc.get_traced_memory()[0]
        for _ in range(20):  # the recorder drains every 100 ms, as its activity does
            run(0.1)
        young = gc.get_objects(generation=0)
        memory = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
        if was:
            gc.enable()
    assert len(young) < 50, f"{len(young)} container objects alive after 2,000 cycles, e.g. {young[:5]}"
    assert memory < 64 * 1024, f"{memory} bytes more in use after 2,000 cycles"
