"""The augmented teleoperation view of the Baxter replay app (config/baxter_teleop_replay.xml, the
paper's Fig. 5): rendered offscreen while a generated session replays, through the installed
coco-launch as a user runs it, and recorded as a video, PNGs and a contact sheet."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT, activity_cycles, run_launcher
from test_baxter_app import APP

cv2 = pytest.importorskip("cv2", reason="the recorded frames are decoded with OpenCV")

WIDTH, HEIGHT = 640, 480
PERIOD = 0.05
"""The display activity's period (s)."""
BOWL_CENTRE = (0.068, 0.0, -0.02, 1.0)
"""A point inside the bowl, in its grasp frame (config/meshes/bowl.obj: origin on the rim, centre at +x)."""
IMAGE_TOPIC = "/cameras/head_camera/image"


def read_video(path: Path) -> list[np.ndarray]:
    """Every frame of a video, RGB."""
    capture = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB))
    capture.release()
    return frames


def camera_pixel(point: np.ndarray) -> tuple[int, int]:
    """(row, column) where the app's camera (its GLCameraManager attributes) draws a base-frame point."""
    from coco_core.xml import load_application
    from coco_mr_display.projection import look_at, perspective

    display = next(c for c in load_application(ROOT / APP).components if c.name == "display")
    camera = next(p for p in display.peers if p.name == "camera")
    values = {a.name: [float(v) for v in a.value.split()] for a in camera.attributes}
    pose = look_at(values["position"], values["look_at"], values.get("up", [0.0, 0.0, 1.0]))
    clip = perspective(values["fov_y"][0], WIDTH / HEIGHT, 0.05, 100.0) @ np.linalg.inv(pose) @ point
    x, y = clip[:2] / clip[3]
    return round((1.0 - y) / 2.0 * HEIGHT), round((x + 1.0) / 2.0 * WIDTH)


def greenness(frame: np.ndarray, pixel: tuple[int, int]) -> float:
    """G / (R + G) of a 7x7 patch: about 0 for the red bowl, 0.5 yellow, 1 green (the table is ~0.43)."""
    row, column = pixel
    patch = frame[row - 3:row + 4, column - 3:column + 4].reshape(-1, 3).astype(float).mean(axis=0)
    return patch[1] / max(patch[0] + patch[1], 1.0)


def coloured_bowl(frame: np.ndarray, pixel: tuple[int, int]) -> bool:
    """Whether the patch shows the bowl in a colour of the red-yellow-green scale (no blue but the
    highlights), not the table (0.55 0.42 0.30) that is there until the first bowl pose arrives."""
    row, column = pixel
    patch = frame[row - 3:row + 4, column - 3:column + 4].reshape(-1, 3).astype(float).mean(axis=0)
    red, green, blue = patch
    return blue < 0.15 * (red + green + blue)


def test_view_renders_the_session(coco_launch: Path, session, tmp_path: Path) -> None:
    folder, info = session
    output = tmp_path / "teleop"
    result = run_launcher(coco_launch, APP, f"bag:={folder}", f"output:={output}", "--profile", "100",
                          "--duration", "60", timeout=120)
    assert result.returncode == 0, result.stderr
    assert "GLManager display: headless 640x480" in result.stderr, result.stderr
    for connection in ("distance.color -> bowl_color.color", "display.color -> writer.image"):
        assert connection in result.stdout, result.stdout

    frames = read_video(output / "frames.mp4")
    # One frame a cycle of the display (20 Hz at most; a loaded machine renders fewer, counted as
    # overruns), every one of them in the video.
    cycles = activity_cycles(result.stdout, "view", "display")
    assert len(frames) == cycles, (len(frames), result.stdout)
    assert 20 <= len(frames) <= info.duration / PERIOD + 40, len(frames)
    assert all(frame.shape == (HEIGHT, WIDTH, 3) for frame in frames)
    sheet = cv2.imread(str(output / "contact_sheet.png"))
    assert sheet is not None and sheet.shape[0] > 200 and sheet.shape[1] > 400, "no readable contact sheet"
    # The arm moves: frames a few seconds apart differ over many pixels.
    early, late = frames[len(frames) // 4], frames[3 * len(frames) // 4]
    assert (np.abs(early.astype(int) - late.astype(int)).max(axis=2) > 40).sum() > 2000

    # The bowl stands at its initial pose until the gripper has closed on it: there its colour goes
    # from red (the gripper at home, far) to green (within `near` = 2 cm, from grasp_time of the summary).
    summary = json.loads((output / "summary.json").read_text())
    # Sensor-to-display latency of the frames that showed a new joint state or colour, measured in the
    # view's own process and recorded by the summary in the launcher's (process level).
    shown = summary["display_latency_ms"]
    assert shown["frames"] > 0 and 0 < shown["median"] <= shown["max"], shown
    assert re.search(r"^view\s+display\s+display\s.*\s[0-9.]+ / [0-9.]+\s*$", result.stdout, re.M), result.stdout
    pixel = camera_pixel(info.bowl @ np.array(BOWL_CENTRE))
    assert 0 <= pixel[0] < HEIGHT and 0 <= pixel[1] < WIDTH, pixel

    # The frames carry no times (and a loaded machine skips some), so the order tells: at the bowl's
    # pixel, red at the start, through yellow to green, green while the gripper closes on it (from the
    # summary's grasp time, within 2 cm, until the session's grasp: then it is lifted), then gone.
    # The first frames may come before the first joint state and bowl pose (the robot is not drawn in
    # its all-zero pose, wait_for_joints, and the bowl is not in the graph yet): the table shows.
    first = next((i for i, frame in enumerate(frames) if coloured_bowl(frame, pixel)), len(frames))
    assert first < len(frames) // 4, f"the coloured bowl appears only at frame {first} of {len(frames)}"
    green = np.array([greenness(frame, pixel) for frame in frames[first:]])
    assert green[0] < 0.2, f"the bowl is not red at the start (G/(R+G) {green[0]:.2f})"
    assert (green > 0.9).any(), f"the bowl never turns green: {green.round(2)}"
    reached = int(np.argmax(green > 0.9))
    approach = green[:reached]
    assert all(b >= a - 0.05 for a, b in zip(approach, approach[1:])), f"not red to green: {approach.round(2)}"
    assert ((approach > 0.35) & (approach < 0.75)).any(), f"never yellow on the way: {approach.round(2)}"
    held = int(np.argmax(green[reached:] <= 0.9)) or len(green) - reached
    closing = info.grasp_time - summary["grasp_time"]
    assert closing > 0.6, (summary, info.grasp_time)
    interval = max(PERIOD, info.duration / len(frames))  # a loaded machine renders less often
    assert held * interval >= 0.5 * closing, f"green for {held} frames only, the grasp takes {closing:.2f} s"
    assert green[-1] < 0.6, f"the bowl did not leave its place: {green[-1]:.2f}"


def test_display_off_renders_nothing(coco_launch: Path, session, tmp_path: Path) -> None:
    folder, _ = session
    output = tmp_path / "teleop"
    result = run_launcher(coco_launch, APP, f"bag:={folder}", f"output:={output}", "display:=false",
                          "rate:=4", "--profile", "100", "--duration", "60", timeout=120)
    assert result.returncode == 0, result.stderr
    assert "GLManager" not in result.stderr and "FrameWriter" not in result.stderr, result.stderr
    assert "display" not in result.stdout and "writer" not in result.stdout, result.stdout
    assert sorted(p.name for p in output.iterdir()) == ["distance.csv", "summary.json"]


def write_bag_with_images(folder: Path, seconds: float = 3.0) -> np.ndarray:
    """A bag of the Baxter at home (joint states, 100 Hz) and camera images (10 Hz, 320x240 rgb8)
    whose quadrants are magenta, cyan, yellow and blue; returns the image (RGB)."""
    from sensor_msgs.msg import Image as ImageMessage

    from coco_ros.bag.writer import BagWriter
    from coco_ros.baxter.ik import NEUTRAL
    from coco_ros.baxter.importer import joint_state
    from coco_ros.baxter.joints import ARM_JOINTS, BAXTER_JOINT_NAMES

    home = {**dict(zip(ARM_JOINTS["left"], NEUTRAL["left"])), **dict(zip(ARM_JOINTS["right"], NEUTRAL["right"]))}
    positions = [home.get(name, 0.0) for name in BAXTER_JOINT_NAMES]
    image = np.zeros((240, 320, 3), np.uint8)
    image[:120, :160], image[:120, 160:] = (255, 0, 255), (0, 255, 255)
    image[120:, :160], image[120:, 160:] = (255, 255, 0), (0, 0, 255)
    start = 1_700_000_000 * 1_000_000_000
    with BagWriter(folder) as writer:
        for k in range(int(seconds * 100)):
            stamp = start + k * 10_000_000
            writer.write("/robot/joint_states", joint_state(stamp, BAXTER_JOINT_NAMES, positions), stamp)
            if k % 10 == 0:
                message = ImageMessage(height=240, width=320, encoding="rgb8", step=320 * 3, data=image.tobytes())
                message.header.stamp.sec, message.header.stamp.nanosec = divmod(stamp, 1_000_000_000)
                message.header.frame_id = "head_camera"
                writer.write(IMAGE_TOPIC, message, stamp)
    return image


def test_camera_images_are_the_background(coco_launch: Path, tmp_path: Path) -> None:
    bag = tmp_path / "with_images"
    write_bag_with_images(bag)
    output = tmp_path / "teleop"
    result = run_launcher(coco_launch, APP, f"bag:={bag}", f"output:={output}", "fixed_bowl:=true",
                          "images:=true", f"image_topic:={IMAGE_TOPIC}", "frames_format:=png",
                          "--duration", "60", timeout=120)
    assert result.returncode == 0, result.stderr
    files = sorted(output.glob("frames_*.png"))
    assert len(files) > 20, f"{len(files)} frames"
    frame = cv2.cvtColor(cv2.imread(str(files[-1])), cv2.COLOR_BGR2RGB)
    # fit=cover scales the 4:3 image to the 4:3 view: each corner shows its quadrant, upright.
    for (row, column), colour in (((5, 5), (255, 0, 255)), ((5, WIDTH - 6), (0, 255, 255)),
                                  ((HEIGHT - 6, 5), (255, 255, 0))):
        assert np.abs(frame[row, column].astype(int) - colour).max() <= 8, (row, column, frame[row, column])
    # The scene is drawn over it: the table (brown) and the bowl at bowl_xyz.
    table = (np.abs(frame.astype(int) - (140, 107, 76)).max(axis=2) < 50).sum()
    assert table > 2000, f"{table} table pixels"
