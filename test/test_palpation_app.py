"""The remote palpation app (config/palpation_replay.xml) on a generated session, run through the
installed coco-launch as a user does: the calibration touch registers the hand tracker to the remote
camera, the device then touches the body where the hand presses and strokes it, and never goes
through it; the same file without its processes touches the same places."""

from __future__ import annotations

import csv
import json
import os
import re
import signal
import socket
import subprocess
import threading
from pathlib import Path

import numpy as np
import pytest

from conftest import PALPATION_SECONDS, ROOT, activity_cycles, run_launcher

APP = ROOT / "config" / "palpation_replay.xml"
DURATION = PALPATION_SECONDS
"""The session's length (conftest's ``palpation_session``, shared by the run): the shortest
palpation-session makes, every phase in a short test."""

BEHIND_BOUND = 5e-3
"""m: how far the proxy may be behind the true surface of the body. The proxy lies on the surface
reconstructed from the sensor's depth, whose steps are ~3 mm at the body's 0.9 m, with a third of a
step of noise: measured under 1.5 mm in most runs, 3.5 mm in one sample of one run (the device
free, above the reconstructed surface where it lies lowest). A device through the body would be
as deep as the hand: 8 mm in the presses."""

RESIDUAL_BOUND = 3e-3
"""m: the calibration touch's RMS residual (the marker's detections against the touch mapped by the
registration: the detections' noise; measured ~1 mm)."""

PLACES = ("press_1", "press_2", "press_3", "stroke")
"""Where the hand goes into the body after the calibration touch."""

JOIN_DELAY = 0.3
"""s from the detection that completes the registration (its stamp, the recording's time) to the
haptic loop rendering with it: the detection's way through the tracker, the registration's edge to
the haptic process, and the hand's replay and the camera's each paced by a clock of its own (with
the hand at half speed, the hand reaches a stamp well after the camera)."""


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


HAND_RATE = 0.5
"""The hand replayed at half speed (the camera keeps its own: the body does not move). These tests
check where the device touches the body, not how a loaded 2-core machine keeps up with five
processes: there, at full speed, the hand's replay (which decompresses every camera chunk of the
bag to find the hand's poses) stalled for over a second at times and a press went by untouched."""


RUN_APP = ROOT / "scripts" / "run_app.sh"


def run_app(command: tuple[Path, str], bag: Path, output: Path, *args: str):
    """Run ``command`` (a launcher and the application file, or ``run_app.sh palpation``) on ``bag``."""
    result = run_launcher(command[0], command[1], f"bag:={bag}", f"output:={output}", f"rate:={HAND_RATE}",
                          f"stream:=tcp://127.0.0.1:{free_port()}", *args, "--profile", "100", "--duration", "60",
                          timeout=240)
    assert result.returncode == 0, result.stderr[-6000:]
    return result


def haptic_rows(output: Path) -> dict[str, np.ndarray]:
    with (output / "haptic.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert rows, "no haptic sample: the renderer never had the device's workspace joined to the camera"
    return {"time": np.array([float(r["time"]) for r in rows]),
            "proxy": np.array([[float(r[f"proxy_{a}"]) for a in "xyz"] for r in rows]),
            "contact": np.array([r["contact"] == "1" for r in rows])}


def in_table(points_in_camera: np.ndarray) -> np.ndarray:
    """Points of the camera's frame (the render frame) in the session's table frame (its ground truth)."""
    from coco_ros.palpation.session import CAMERA_EYE, CAMERA_TARGET, look_at

    camera = look_at(CAMERA_EYE, CAMERA_TARGET)
    return points_in_camera @ camera[:3, :3].T + camera[:3, 3]


def places_touched(rows: dict[str, np.ndarray]) -> set[str]:
    """The places of PLACES the proxy touched. A contact episode (contact samples less than 50 ms
    apart) is the stroke when it slides over 15 cm along the body; otherwise it touched each press
    point it came within 2 cm of (they are at least 6.7 cm apart; the registration's error is about
    1 cm). The device may also meet the body on its way to a press, where a loaded machine's slow
    haptic loop integrates the handle with long steps: such an episode slides on to the press."""
    from coco_ros.palpation.session import hand_plan, marker_pose

    points = {name: end[:2] for name, _, _, _, end in hand_plan(DURATION) if name.startswith("press")}
    points["calibration_touch"] = marker_pose()[:2, 3]
    names, centres = list(points), np.array(list(points.values()))
    contact = np.flatnonzero(rows["contact"])
    proxy, times = in_table(rows["proxy"]), rows["time"]
    episodes = np.split(contact, np.flatnonzero(np.diff(times[contact]) > 0.05) + 1) if len(contact) else []
    touched = set()
    for episode in episodes:
        path = proxy[episode]
        if np.ptp(path[:, 0]) > 0.15:
            touched.add("stroke")
            continue
        near = np.linalg.norm(path[:, None, :2] - centres[None], axis=2).min(axis=0) < 0.02
        touched.update(name for name, close in zip(names, near) if close)
    return touched & set(PLACES)


def places_after_the_registration(output: Path) -> set[str]:
    """The places of PLACES the hand reaches after the registration was complete (before it, the
    renderer rightly sends zero force: the hand is not joined to the remote scene yet). On a quiet
    machine the touch completes it a second before the first press."""
    from coco_ros.palpation.session import DEFAULT_START_NS, hand_plan

    registered = json.loads((output / "registration.json").read_text())["stamp"] - DEFAULT_START_NS * 1e-9
    return {name for name, start, _, _, _ in hand_plan(DURATION)
            if name in PLACES and start >= registered + JOIN_DELAY}


def behind_the_body(rows: dict[str, np.ndarray]) -> float:
    """The deepest the proxy went under the true top of the torso (m), from its first contact on
    (before it, the device may be anywhere: the surface joins the haptic loop with the registration)."""
    from coco_ros.palpation.session import TORSO_LENGTH, TORSO_RADIUS, belly_height

    first = int(np.argmax(rows["contact"]))
    proxy = in_table(rows["proxy"][first:])
    over = (np.abs(proxy[:, 0]) < TORSO_LENGTH / 2 - 0.01) & (np.abs(proxy[:, 1]) < TORSO_RADIUS - 0.03)
    return max(0.0, max(belly_height(x, y) - z for x, y, z in proxy[over]))


@pytest.fixture(scope="module")
def documented_run(palpation_session: Path, tmp_path_factory: pytest.TempPathFactory):
    """``./scripts/run_app.sh palpation`` (on the test's session), run once: (its output folder, the
    completed run). The end-to-end test checks everything it prints and writes; the one-process
    comparison takes it as its run with processes (the display it adds only watches)."""
    output = tmp_path_factory.mktemp("documented") / "palpation"
    return output, run_app((RUN_APP, "palpation"), palpation_session, output)


def test_palpation_app_end_to_end(documented_run) -> None:
    """As the docs show it, ``./scripts/run_app.sh palpation`` (on the test's session)."""
    output, result = documented_run
    report = result.stdout
    assert f"Palpation summary ({output}/summary.json" in report and "registration: residual" in report, report
    assert f"Contact sheet:  {output}/contact_sheet.png" in report, report
    assert "registered from" in result.stderr, result.stderr[-4000:]
    for process in ("hand", "remote", "haptics", "stream", "local", "view"):
        assert re.search(rf"^{process}\s+\d+\s", report, re.M), f"process {process} missing:\n{report}"
    rows = haptic_rows(output)
    expected = places_after_the_registration(output)
    assert {"press_3", "stroke"} <= expected, f"the registration came late: only {expected} after it"
    touched = places_touched(rows)
    assert expected <= touched, (expected, touched)
    behind = behind_the_body(rows)
    assert behind <= BEHIND_BOUND, f"the proxy went {behind * 1e3:.1f} mm behind the body's surface"

    summary = json.loads((output / "summary.json").read_text())
    assert summary["registration_residual_mm"] is not None and summary["registration_residual_mm"] < RESIDUAL_BOUND * 1e3
    registration = json.loads((output / "registration.json").read_text())
    assert registration["residual_m"] == pytest.approx(summary["registration_residual_mm"] / 1e3)
    haptics = summary["haptics"]
    assert haptics["samples"] == len(rows["contact"])
    assert haptics["contact_time_s"] > 0.5 and 0 < haptics["max_penetration_mm"] < 30, haptics
    assert summary["kdtree"]["updates"] >= 2 and summary["kdtree"]["build_ms"]["median"] > 0, summary
    assert summary["stream"]["frames"] >= 10, summary
    # Sensor-to-display: the remote camera's frames, from their acquisition (the remote process)
    # through the stream to the view process's pixels.
    shown = summary["display_latency_ms"]["camera"]
    assert shown["frames"] > 0 and 0 < shown["median"] <= shown["max"], summary["display_latency_ms"]
    # Split by the steps the frames' stamps passed on their way to the pixels and to the haptic loop.
    assert list(summary["display_steps_ms"]["camera"]) == ["sent", "received", "frame_start", "drawn", "read_back"]
    assert list(summary["kdtree"]["steps_ms"]) == ["sent", "received", "built"], summary["kdtree"]
    assert summary["input_damage"] == []

    # The view: one video frame per display cycle, and a contact sheet; the hand (the only saturated
    # colour in the scene but the force arrow's blue) green out of contact, redder in it (OpenCV hues:
    # green 60, yellow 30, red 0); the force arrow (hue ~107) only in contact, so never in the
    # first frame (nothing streamed, nothing registered yet).
    cv2 = pytest.importorskip("cv2", reason="the recorded frames are decoded with OpenCV")
    capture = cv2.VideoCapture(str(output / "frames.mp4"))
    frames, hues, arrows = 0, [], []
    while (frame := capture.read())[0]:
        frames += 1
        hsv = cv2.cvtColor(frame[1], cv2.COLOR_BGR2HSV)
        saturated = (hsv[:, :, 1] > 150) & (hsv[:, :, 2] > 120)
        hand = saturated & (hsv[:, :, 0] < 90)
        arrows.append(int((saturated & (hsv[:, :, 0] >= 95) & (hsv[:, :, 0] <= 120)).sum()))
        if hand.sum() > 500:
            hues.append(float(np.median(hsv[:, :, 0][hand])))
    assert frames == activity_cycles(report, "view", "display") >= 3, frames
    assert hues and max(hues) >= 55 and min(hues) <= 48, hues
    assert arrows[0] == 0 and max(arrows) >= 15, arrows
    assert (output / "contact_sheet.png").stat().st_size > 0


def test_palpation_app_without_processes_touches_the_same_places(coco_launch: Path, palpation_session: Path,
                                                                documented_run, tmp_path: Path) -> None:
    """The file with its <process> elements removed (every activity in the launcher's process):
    the same places touched as the documented run with its processes, the proxy never through the
    body; this one without the display, which only watches (one process draws what it computes)."""
    text = APP.read_text()
    flat = re.sub(r"\s*</?process\b[^>]*>", "", text)
    assert "<process" not in flat and flat.count("<activity ") == text.count("<activity ")
    flat_app = tmp_path / "palpation_one_process.xml"
    flat_app.write_text(flat)
    runs, expected = {}, set(PLACES)
    for name in ("processes", "one process"):
        if name == "processes":
            output, result = documented_run
        else:
            output = tmp_path / "one_process"
            result = run_app((coco_launch, str(flat_app)), palpation_session, output, "display:=false")
        runs[name] = haptic_rows(output)
        expected &= places_after_the_registration(output)
        # The process table's row of the haptic process (name, pid): only with the process level.
        assert bool(re.search(r"^haptics\s+\d+\s", result.stdout, re.M)) == (name == "processes"), result.stdout
        assert behind_the_body(runs[name]) <= BEHIND_BOUND, name
    assert {"press_3", "stroke"} <= expected, f"a registration came late: only {expected} after both"
    assert places_touched(runs["processes"]) & expected == places_touched(runs["one process"]) & expected == expected


HAND_DOMAIN, CAMERA_DOMAIN = "151", "159"


def fed_by_replay(session: Path, output: Path, domain: str, app_args: tuple[str, ...],
                  topics: tuple[str, ...]) -> str:
    """Run the application with the ROS launcher (``app_args`` choose its sources) and, once it runs,
    ``coco-replay`` of the session's ``topics`` at the hand's pace, as live sources publish them;
    Ctrl-C once they have been played (a topic has no end). The launcher's output; its exit status
    must be 0."""
    installed = ROOT / "install" / "coco_ros" / "lib" / "coco_ros"
    env = {**os.environ, "ROS_DOMAIN_ID": domain, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "PYTHONUNBUFFERED": "1"}
    launcher = subprocess.Popen(
        [str(installed / "launcher"), str(APP), *app_args, f"bag:={session}", f"output:={output}",
         f"stream:=tcp://127.0.0.1:{free_port()}", "display:=false", "--profile", "100", "--duration", "120"],
        cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    running = threading.Event()

    def read() -> None:
        assert launcher.stdout is not None
        for line in launcher.stdout:
            lines.append(line)
            if "is not joined to camera yet" in line:  # the haptic loop's first cycle: every process runs
                running.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert running.wait(120), "".join(lines)[-6000:]
        replay = subprocess.run([str(installed / "coco-replay"), str(session), "--topics", *topics,
                                 "--rate", str(HAND_RATE), "--wait-subscribers", str(len(topics)), "--no-progress"],
                                cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
        assert replay.returncode == 0 and "subscriptions after" not in replay.stdout + replay.stderr, replay.stdout + replay.stderr
    finally:
        launcher.send_signal(signal.SIGINT)
        code = launcher.wait(30)
        reader.join(5)
    log = "".join(lines)
    assert code == 0, log[-6000:]
    return log


def test_ros_launcher_takes_the_hand_from_a_topic(palpation_session: Path, tmp_path: Path) -> None:
    """``ros2 run coco_ros launcher config/palpation_replay.xml hand:=topic``: the hand's poses come
    from DDS, here the session's ``/hand/pose`` played by ``coco-replay`` (as a live tracker or a
    played recording publishes them) once the application runs; the touch registers the tracker
    and the places the hand reaches after it are touched, as with the bag's hand."""
    output = tmp_path / "topic"
    log = fed_by_replay(palpation_session, output, HAND_DOMAIN, ("hand:=topic",), ("/hand/pose",))
    assert "registered from" in log, log[-6000:]
    rows = haptic_rows(output)
    expected = places_after_the_registration(output)
    assert {"press_3", "stroke"} <= expected, f"the registration came late: only {expected} after it"
    assert expected <= places_touched(rows)
    assert behind_the_body(rows) <= BEHIND_BOUND


def test_ros_launcher_takes_the_camera_from_a_drivers_topics(palpation_session: Path, tmp_path: Path) -> None:
    """``scene:=topic hand:=topic``: the remote camera is a ROS 2 driver's colour, depth and
    camera_info topics (the bag's topic names given as the camera_*_topic args), paired by stamp by
    the TopicRgbdPeer, and the hand a tracker's topic: the session's, played by one ``coco-replay``
    as the live camera and tracker publish them together (reliable: a lost fragment of a frame is
    sent again, where a busy machine loses most frames of a best-effort subscription). The touch registers the tracker, and the
    places the hand reaches after it are touched, as with the bag's camera."""
    output = tmp_path / "camera_topics"
    camera = ("/camera/color/image_raw", "/camera/depth/image_raw", "/camera/color/camera_info")
    log = fed_by_replay(palpation_session, output, CAMERA_DOMAIN,
                        ("scene:=topic", "hand:=topic", "camera_reliability:=reliable",
                         *(f"camera_{kind}_topic:={topic}"
                                                          for kind, topic in zip(("color", "depth", "info"), camera))),
                        (*camera, "/hand/pose"))
    assert "registered from" in log, log[-6000:]
    paired = re.search(r"camera_topics: (\d+) colour, (\d+) depth, (\d+) camera_info messages; (\d+) frames paired", log)
    assert paired and int(paired.group(4)) >= 30, log[-3000:]
    rows = haptic_rows(output)
    expected = places_after_the_registration(output)
    assert {"press_3", "stroke"} <= expected, f"the registration came late: only {expected} after it"
    assert expected <= places_touched(rows)
    assert behind_the_body(rows) <= BEHIND_BOUND


REDWOOD = ROOT.parent / "shared" / "data" / "rgbd" / "redwood"
REDWOOD_TRACKER = ("0.047 0.943 1.5696", "1.6413 -1.1994 -0.058")
"""The hand tracker's pose in the Redwood camera's frame (xyz, rpy) that puts the session's body
where the floor is: the floor fitted to the depth's bottom rows (1.8 mm RMS), its normal as the
table's z, its point under pixel (320, 420) lowered by the belly's height as the table's origin,
composed with the session's table -> tracker (``session.TRACKER``). The presses then take the
hand 5.6 to 8 mm into the floor, the stroke 2 to 4 mm."""


@pytest.mark.skipif(not REDWOOD.is_dir(), reason="the shared Redwood frames are not beside the workspace")
def test_a_real_rgbd_scene_with_a_fixed_registration(coco_launch: Path, palpation_session: Path,
                                                     tmp_path: Path) -> None:
    """``scene:=redwood`` (a real PrimeSense room, no marker in it) with ``registration:=fixed``: the
    remote camera plays the folder's frames, the hand tracker is joined to it from the start by
    the given pose, the hand's presses meet the floor and are rendered as force, bounded by the
    device's limit; no touch, so no residual, and nothing reported as damaged."""
    output = tmp_path / "redwood"
    run_app((coco_launch, str(APP)), palpation_session, output, "scene:=redwood", f"scene_path:={REDWOOD}",
            "registration:=fixed", f"tracker_xyz:={REDWOOD_TRACKER[0]}", f"tracker_rpy:={REDWOOD_TRACKER[1]}",
            "display:=false")
    summary = json.loads((output / "summary.json").read_text())
    assert summary["registration"] == "fixed" and summary["registration_residual_mm"] is None, summary
    assert summary["input_damage"] == [], summary
    haptics = summary["haptics"]
    assert haptics["contact_time_s"] > 0.2 and 0 < haptics["max_force_n"] <= 8.0 + 1e-9, haptics
    assert summary["kdtree"]["updates"] >= 2 and summary["stream"]["frames"] >= 10, summary
    rows = haptic_rows(output)
    assert rows["contact"].any()


def test_the_camera_from_a_librealsense_recording(coco_launch: Path, palpation_session: Path,
                                                  tmp_path: Path) -> None:
    """``scene:=realsense scene_path:=RECORDING``: a recording that librealsense's own software
    device and recorder wrote (60 frames of a plane 0.75 m away, a colour pattern, intrinsics set)
    is the remote camera, through the RealSense peer, played at its rate and again at its end; with
    the tracker joined by a fixed pose, every frame is streamed and made touchable, and the structures hold
    the plane's points. Nothing is reported as damaged."""
    pytest.importorskip("pyrealsense2", reason="pyrealsense2 is in requirements.txt")
    from coco_mr_vision.realsense_recording import SyntheticScene, write_recording

    scene = SyntheticScene()
    recording = write_recording(tmp_path / "desk.db3", scene)
    output = tmp_path / "realsense"
    run_app((coco_launch, str(APP)), palpation_session, output, "scene:=realsense", f"scene_path:={recording}",
            "registration:=fixed", "display:=false")
    summary = json.loads((output / "summary.json").read_text())
    assert summary["input_damage"] == [] and summary["input_refused"] == {}, summary
    assert summary["stream"]["frames"] >= scene.frames and summary["kdtree"]["updates"] >= 10, summary
    # Every pixel with depth is a point of the structure (the plane fills the image).
    assert summary["kdtree"]["points_median"] >= 0.75 * scene.width * scene.height, summary


def two_host_palpation() -> Path:
    """config/palpation_replay.xml over two hosts, nothing else changed: the remote process (the
    camera and its stream server) on host ``remote``, the first (its clock is the application's, so
    the camera's stamps are), everything else on host ``local``."""
    text = APP.read_text()
    opened = text.index("    <activities>\n") + len("    <activities>\n")
    closed = text.index("    </activities>")
    remote = text.index('        <process name="remote">')
    end = text.index("        </process>\n", remote) + len("        </process>\n")
    placed = (text[:opened] + '        <host name="remote">\n' + text[remote:end] + "        </host>\n"
              + '        <host name="local">\n' + text[opened:remote] + text[end:closed] + "        </host>\n"
              + text[closed:])
    path = ROOT / "config" / f".test_palpation_two_hosts_{os.getpid()}.xml"  # beside the original: paths resolve alike
    path.write_text(placed)
    return path


def test_remote_palpation_over_two_hosts_on_a_delaying_lossy_link(palpation_session: Path, tmp_path: Path) -> None:
    """The paper's two sites as two hosts: the camera and its stream on ``remote``, the hand, the
    haptic loop, the touchable structure and the view on ``local``, each a network namespace, joined by a link
    that delays every packet by 5 ms and loses 1 % of them. The stream crosses the link; the touch
    registers the tracker, the places the hand reaches after it are touched, and the summary gives
    the sensor-to-pixel latency on the first host's clock with the local host's measured offset."""
    from netns import Impairment, Network, unavailable
    from test_hosts_netns import start

    if unavailable() is not None:
        pytest.skip(f"no simulated network here: {unavailable()}")
    app = two_host_palpation()
    output = tmp_path / "two_hosts"
    try:
        args = (str(app), f"bag:={palpation_session}", f"output:={output}", f"rate:={HAND_RATE}",
                "stream:=tcp://10.77.0.1:5611", "--profile", "100", "--duration", "90")
        with Network(["remote", "local"], domain=188, impairment=Impairment(delay_s=0.005, loss=0.01, seed=5)) as net:
            remote = start(net, "remote", tmp_path / "remote.log", *args)
            local = start(net, "local", tmp_path / "local.log", *args)
            assert local.wait(200) == 0, (tmp_path / "local.log").read_text()[-6000:]
            assert remote.wait(30) == 0, (tmp_path / "remote.log").read_text()[-6000:]
            dropped_on_link = sum(counts["dropped"] for counts in net.counters().values())
    finally:
        app.unlink()
    local_log = (tmp_path / "local.log").read_text()
    assert dropped_on_link > 0 and "registered from" in local_log, local_log[-6000:]
    rows = haptic_rows(output)
    expected = places_after_the_registration(output)
    assert {"press_3", "stroke"} <= expected, f"the registration came late: only {expected} after it"
    assert expected <= places_touched(rows)
    assert behind_the_body(rows) <= BEHIND_BOUND
    summary = json.loads((output / "summary.json").read_text())
    clock = summary["clock"]
    assert clock["exchanges"] > 0 and abs(clock["offset_ms"]) <= clock["uncertainty_ms"] + 0.05  # one machine
    camera = summary["display_latency_ms"]["camera"]
    assert camera["frames"] > 30 and 5.0 < camera["median"] < 2000.0  # the link's 5 ms are in it
