"""A generated, seeded remote palpation session (the CoCo paper's section 6.1) as a rosbag2 bag.

The remote scene: a mannequin-like body (a torso, slightly flattened, and a head) lying on a table,
with a fiducial marker stuck on the belly, seen by a fixed RGB-D camera above the table's side. The
scene is rendered once by the display module (GLManager offscreen, colour and depth), and each
30 Hz frame is made of that rendering the way a structured-light sensor delivers it:

- depth quantised in disparity steps that grow with the square of the distance (3.7 mm at 1 m, the
  PrimeSense step measured on the Redwood frames), with per-frame noise of a third of a step;
- no depth where the depth jumps (the edges of the body and the table: a projector's shadow and
  mixed pixels), nor on a few random pixels;
- colour with sensor noise.

The local side: a hand tracker (the paper's Leap Motion) reports the hand at 100 Hz in its own frame
``hand_tracker``, which the application does not know: it calibrates it by the touch on the marker.
The hand approaches, touches the marker's centre and holds still (the calibration touch), lifts,
presses the belly three times, strokes along it, and lifts off. The hand's pose is the point that
touches (the fingertip), palm down and aligned with the marker's axes, so that at the touch the
hand's pose is the marker's.

Topics (stamps = log times = ``start_stamp`` + session time):

================================ ========================== ======= =====================================
topic                            type                       rate    notes
================================ ========================== ======= =====================================
/camera/color/image_raw          sensor_msgs/Image          30 Hz   rgb8, 640x480, frame ``camera``
/camera/depth/image_raw          sensor_msgs/Image          30 Hz   16UC1 millimetres, registered to colour
/camera/color/camera_info        sensor_msgs/CameraInfo     30 Hz   the rendering's pinhole intrinsics
/hand/pose                       geometry_msgs/PoseStamped  100 Hz  frame ``hand_tracker``, seeded noise
================================ ========================== ======= =====================================

Deterministic: the same arguments give the same bytes (noise from ``numpy.random.default_rng``
seeded with ``seed``; the rendering is made once and is the same on every run of one renderer;
chunks are cut by size only, never by wall time).
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from coco_core.errors import CocoError, SessionError
from coco_core.transforms import se3

DEFAULT_START_NS = 1_700_000_000 * 1_000_000_000
"""Default stamp of session time 0: fixed, so runs are reproducible."""

WIDTH, HEIGHT, FOV_Y = 640, 480, 45.0
CAMERA_RATE, HAND_RATE = 30.0, 100.0
DEPTH_STEP = 3.7e-3
"""The sensor's depth step at 1 m (m); it grows with the square of the distance."""
DEPTH_NOISE = 0.3
"""Per-frame noise of the disparity, in steps."""
EDGE_JUMP = 0.02
"""m: a pixel whose depth differs from a neighbour's by more has no depth (an edge)."""
DROPOUT = 0.002
"""Fraction of pixels without depth at random."""
COLOR_NOISE = 1.5
"""Grey levels of colour noise (standard deviation)."""
HAND_NOISE = 3e-4
"""m: the hand tracker's position noise (standard deviation)."""

TABLE_TOP = 0.0
TORSO_RADIUS, TORSO_LENGTH, TORSO_FLATTEN = 0.15, 0.55, 0.8
"""The torso: a cylinder along x centred on the table's origin, flattened to ``TORSO_FLATTEN`` of its
radius in height, lying on the table."""
HEAD_RADIUS, HEAD_X = 0.1, 0.40
MARKER_DICTIONARY, MARKER_ID, MARKER_LENGTH, MARKER_X = "DICT_4X4_50", 7, 0.07, -0.05
"""The marker on the belly: its centre at ``MARKER_X`` along the torso, on top, face up."""
CAMERA_EYE, CAMERA_TARGET = (-0.05, -0.75, 0.85), (0.0, 0.0, 0.12)
"""The remote camera, in the table's frame ``table`` (z up)."""
TRACKER = ((0.05, 0.35, -0.30), (0.0, 0.0, 1.2))
"""Where the hand tracker's frame is in ``table``: xyz, rpy (unknown to the application)."""

# (name, nominal duration s)
PHASES = (
    ("approach", 1.5),
    ("calibration_touch", 1.0),
    ("lift", 0.5),
    ("press_1", 0.8),
    ("press_2", 0.8),
    ("press_3", 0.8),
    ("stroke", 2.0),
    ("lift_off", 0.8),
)
NOMINAL_DURATION = sum(p[1] for p in PHASES) + 0.3
PRESS_DEPTH = 0.008
"""m: how far under the body's surface a press takes the hand (the device stops on the surface)."""
STROKE_DEPTH = 0.004


@dataclass
class SessionInfo:
    """What :func:`generate_session` made: the scene's ground truth, phase times, message counts."""

    folder: Path
    seed: int
    duration: float
    start_ns: int
    camera: np.ndarray
    """Pose of the camera's optical frame (x right, y down, z forward) in ``table`` (4x4)."""
    marker: np.ndarray
    """Pose of the marker (OpenCV's marker frame: z out of its face) in ``table`` (4x4)."""
    tracker: np.ndarray
    """Pose of the hand tracker's frame in ``table`` (4x4)."""
    intrinsics: tuple[float, float, float, float]
    """fx fy cx cy of the images."""
    phases: list[tuple[str, float, float]] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)


def belly_height(x: float, y: float) -> float:
    """Height of the torso's top surface over the table at (x, y) (``table`` frame); -inf off it."""
    r, flatten = TORSO_RADIUS, TORSO_FLATTEN
    if abs(x) > TORSO_LENGTH / 2 or abs(y) >= r:
        return -math.inf
    return TABLE_TOP + flatten * r + flatten * math.sqrt(r * r - y * y)


def look_at(eye: Sequence[float], target: Sequence[float], up: Sequence[float] = (0.0, 0.0, 1.0)) -> np.ndarray:
    """The optical frame (x right, y down, z forward) at ``eye`` looking at ``target``."""
    eye_v, forward = np.asarray(eye, float), np.asarray(target, float) - np.asarray(eye, float)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(up, float))
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return se3.make(np.stack([right, down, forward], axis=1), eye_v)


def marker_pose() -> np.ndarray:
    x = MARKER_X
    return se3.make(np.eye(3), (x, 0.0, belly_height(x, 0.0) + 5e-4))


def min_jerk(tau: float) -> float:
    tau = min(max(tau, 0.0), 1.0)
    return tau**3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)


def _over(press: np.ndarray) -> np.ndarray:
    """Where a press comes down from and goes back to: 2 cm over the surface above its point."""
    return press + (0.0, 0.0, PRESS_DEPTH + 0.02)


def hand_plan(duration: float) -> list[tuple[str, float, float, np.ndarray, np.ndarray]]:
    """The hand's fingertip path in ``table``: (phase, start, end, from, to); strokes move along x."""
    if duration < 0.5 * NOMINAL_DURATION:
        raise SessionError(f"duration must be at least {0.5 * NOMINAL_DURATION:.1f} s, got {duration}")
    # The touch is held for its full second whatever the length (a calibration needs its rest); the
    # other phases share the rest of the session.
    held = dict(PHASES)["calibration_touch"] + 0.3
    scale = (duration - held) / (NOMINAL_DURATION - held)
    marker = marker_pose()[:3, 3]
    above = marker + (0.0, 0.0, 0.03)
    start = marker + (0.12, -0.10, 0.25)
    presses = [np.array((x, y, belly_height(x, y) - PRESS_DEPTH)) for x, y in ((0.08, 0.03), (0.14, -0.04), (0.02, 0.0))]
    stroke_from = np.array((-0.12, 0.02, belly_height(-0.12, 0.02) - STROKE_DEPTH))
    stroke_to = np.array((0.18, 0.02, belly_height(0.18, 0.02) - STROKE_DEPTH))
    # Each phase starts where the last one left the hand: a press ends back over its point.
    targets = {
        "approach": (start, marker), "calibration_touch": (marker, marker), "lift": (marker, above),
        "press_1": (above, presses[0]), "press_2": (_over(presses[0]), presses[1]),
        "press_3": (_over(presses[1]), presses[2]), "stroke": (_over(presses[2]), stroke_from),
        "lift_off": (stroke_to, stroke_to + (0.0, 0.0, 0.2)),
    }
    plan, t = [], 0.0
    for name, nominal in PHASES:
        length = nominal if name == "calibration_touch" else nominal * scale
        plan.append((name, t, t + length, *targets[name]))
        t += length
    return plan


def hand_at(plan: Sequence[tuple[str, float, float, np.ndarray, np.ndarray]], t: float) -> np.ndarray:
    """The fingertip at session time ``t``: presses go down and back up (a half-sine of depth over
    the straight move), the stroke goes to its start then along the belly at its depth."""
    for name, start, end, a, b in plan:
        if t < end:
            s = (t - start) / (end - start)
            if name.startswith("press"):
                # Over the first half move above the press point; then down to it and back up.
                over = _over(b)
                if s < 0.5:
                    return a + min_jerk(2 * s) * (over - a)
                return over + math.sin(math.pi * (s - 0.5) * 2) * (b - over) if s < 1.0 else over
            if name == "stroke":
                stroke_to = np.array((0.18, 0.02, 0.0))
                if s < 0.3:  # to the stroke's start
                    return a + min_jerk(s / 0.3) * (b - a)
                x = b[0] + min_jerk((s - 0.3) / 0.7) * (stroke_to[0] - b[0])
                return np.array((x, b[1], belly_height(x, b[1]) - STROKE_DEPTH))
            return a + min_jerk(s) * (b - a)
    last = plan[-1]
    return last[4]


def render_scene(folder: Path) -> tuple[np.ndarray, np.ndarray, tuple[float, float, float, float]]:
    """The scene drawn once by the display module: RGB (H x W x 3 uint8), depth (metres along the
    optical axis, NaN where nothing was drawn) and the intrinsics fx fy cx cy."""
    from coco_core.application import Application
    from coco_core.component import Component
    from coco_core.ports import InputPort
    from coco_mr_display.camera import GLCameraManager
    from coco_mr_display.entity import GLEntity
    from coco_mr_display.manager import GLManager
    from coco_mr_vision.marker_mesh import write_marker_mesh
    from coco_mr_vision.simulated_camera import render_intrinsics

    class Frames(Component):
        color = InputPort(object)
        depth = InputPort(object)

    marker_mesh = write_marker_mesh(folder / "marker.glb", MARKER_DICTIONARY, MARKER_ID, MARKER_LENGTH)
    app = Application("palpation_scene")
    manager = GLManager("scene", width=WIDTH, height=HEIGHT, depth_output=True, background=[0.35, 0.35, 0.4])
    manager.add_peer(GLCameraManager("camera", position=list(CAMERA_EYE), look_at=list(CAMERA_TARGET),
                                     fov_y=FOV_Y, near=0.1, far=6.0))
    r, flatten, length = TORSO_RADIUS, TORSO_FLATTEN, TORSO_LENGTH
    skin = [0.86, 0.72, 0.62]
    entities = [
        GLEntity("floor", mesh="box", size=[4.0, 4.0, 0.02], position=[0.0, 0.0, -0.76], color=[0.45, 0.42, 0.38]),
        GLEntity("table", mesh="box", size=[1.4, 0.8, 0.04], position=[0.0, 0.0, TABLE_TOP - 0.02],
                 color=[0.55, 0.62, 0.7]),
        GLEntity("torso", mesh="cylinder", size=[r, length], rpy=[0.0, math.pi / 2, 0.0],
                 position=[0.0, 0.0, TABLE_TOP + flatten * r], scale=[flatten, 1.0, 1.0],
                 color=skin),
        GLEntity("head", mesh="sphere", size=[HEAD_RADIUS], position=[HEAD_X, 0.0, TABLE_TOP + HEAD_RADIUS],
                 color=skin),
        GLEntity("marker", mesh=str(marker_mesh), position=[float(v) for v in marker_pose()[:3, 3]], specular=0.0),
    ]
    for entity in entities:
        manager.add_peer(entity)
    frames = Frames("frames")
    app.add(manager)
    app.add(frames)
    app.connect("scene.color", "frames.color")
    app.connect("scene.depth", "frames.depth")
    if not manager.configure():
        raise SessionError("the display module could not render the palpation scene (see the log: is "
                           "OpenGL 3.3 available, through EGL or llvmpipe?)")
    try:
        manager.step()
        color = np.array(frames.color.read()[1].data)
        depth = np.array(frames.depth.read()[1].data)
    finally:
        manager.stop()
    k = render_intrinsics(WIDTH, HEIGHT, FOV_Y)
    return color, depth, (k.fx, k.fy, k.cx, k.cy)


class StructuredLightSensor:
    """What a structured-light sensor makes of a static scene's true ``depth`` (metres), frame after
    frame: millimetres (uint16, 0: unknown), quantised in disparity with per-frame noise, no depth at
    jumps and a few random holes.

    What does not change from frame to frame (the disparity of the true depth, where it jumps) is
    computed once: it was two thirds of each frame's cost, and a session has hundreds of frames."""

    def __init__(self, depth: np.ndarray) -> None:
        valid = np.isfinite(depth) & (depth > 0)
        z = np.where(valid, depth, 1.0)
        self.disparity = 1.0 / z / DEPTH_STEP
        known = np.where(valid, depth, 0.0)
        padded = np.pad(known, 1, mode="edge")
        jump = np.zeros(z.shape, bool)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                neighbour = padded[1 + dy:1 + dy + z.shape[0], 1 + dx:1 + dx + z.shape[1]]
                jump |= np.abs(neighbour - known) > EDGE_JUMP
        self.seen = valid & ~jump
        """Where the sensor can give a depth at all (a frame's random holes aside)."""

    def frame(self, rng: np.random.Generator) -> np.ndarray:
        """One frame, its noise and holes drawn from ``rng``."""
        disparity = self.disparity + rng.normal(0.0, DEPTH_NOISE, self.disparity.shape)
        quantised = 1.0 / (np.round(disparity) * DEPTH_STEP)
        keep = self.seen & (rng.random(self.disparity.shape) >= DROPOUT)
        return np.where(keep, np.round(quantised * 1000.0), 0).astype(np.uint16)


def _stamp(message: Any, stamp_ns: int, frame_id: str) -> None:
    message.header.stamp.sec, message.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
    message.header.frame_id = frame_id


def _image(stamp_ns: int, data: np.ndarray, encoding: str) -> Any:
    from sensor_msgs.msg import Image as ImageMsg

    message = ImageMsg()
    _stamp(message, stamp_ns, "camera")
    message.height, message.width = data.shape[:2]
    message.encoding, message.is_bigendian = encoding, 0
    message.step = data.shape[1] * (3 if data.ndim == 3 else 1) * data.dtype.itemsize
    message.data = np.ascontiguousarray(data).tobytes()
    return message


def _camera_info(stamp_ns: int, intrinsics: tuple[float, float, float, float]) -> Any:
    from sensor_msgs.msg import CameraInfo

    fx, fy, cx, cy = intrinsics
    message = CameraInfo()
    _stamp(message, stamp_ns, "camera")
    message.width, message.height = WIDTH, HEIGHT
    message.distortion_model = "plumb_bob"
    message.d = [0.0] * 5
    message.k = [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]
    message.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    message.p = [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]
    return message


def _hand_pose(stamp_ns: int, position: np.ndarray, quaternion: np.ndarray) -> Any:
    from geometry_msgs.msg import PoseStamped

    message = PoseStamped()
    _stamp(message, stamp_ns, "hand_tracker")
    message.pose.position.x, message.pose.position.y, message.pose.position.z = (float(v) for v in position)
    o = message.pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in quaternion)
    return message


def _times(rate: float, duration: float) -> np.ndarray:
    return np.arange(int(math.floor(duration * rate + 1e-9)) + 1) / rate


def generate_session(folder: str | Path, seed: int = 0, duration: float = 8.5, *,
                     start_stamp: int = DEFAULT_START_NS,
                     progress: bool | Callable[[int], None] = False) -> SessionInfo:
    """Write the session as a new bag folder; returns its :class:`SessionInfo`.

    ``progress``: True for a tqdm bar, or a callable given the number of messages written since its
    last call."""
    from ..bag import BagWriter

    noise = np.random.default_rng([int(seed), 2])
    plan = hand_plan(duration)
    tracker = se3.make(se3.rpy_to_matrix(*TRACKER[1]), TRACKER[0])
    table_to_tracker = se3.inverse(tracker)
    # Palm down and aligned with the marker (the table's axes) all along: the calibration touch
    # associates the hand's pose with the marker's.
    palm = se3.matrix_to_quaternion(table_to_tracker[:3, :3] @ marker_pose()[:3, :3])
    with tempfile.TemporaryDirectory() as scratch:
        color, depth, intrinsics = render_scene(Path(scratch))
    camera_times, hand_times = _times(CAMERA_RATE, duration), _times(HAND_RATE, duration)
    total = 3 * len(camera_times) + len(hand_times)
    bar = None
    if progress is True:
        from tqdm import tqdm

        bar = tqdm(total=total, unit="msg", desc="palpation-session")
        step: Callable[[int], None] | None = bar.update
    else:
        step = progress or None

    def ns(t: float) -> int:
        return start_stamp + int(round(t * 1e9))

    sensor = StructuredLightSensor(depth)

    def color_image(stamp: int) -> Any:
        pixels = noise.normal(0.0, COLOR_NOISE, color.shape)
        pixels += color
        return _image(stamp, np.clip(pixels, 0, 255, out=pixels).astype(np.uint8), "rgb8")

    def depth_image(stamp: int) -> Any:
        return _image(stamp, sensor.frame(noise), "16UC1")

    def hand(stamp: int, t: float) -> Any:
        position = table_to_tracker[:3, :3] @ hand_at(plan, t) + table_to_tracker[:3, 3]
        return _hand_pose(stamp, position + noise.normal(0.0, HAND_NOISE, 3), palm)

    # Every message with its log time, in time order (ties: camera info, colour, depth, hand); made
    # when written, so that the noise is drawn in that order.
    events: list[tuple[int, int, str, Callable[[], Any]]] = []
    for t in camera_times:
        stamp = ns(float(t))
        events.append((stamp, 0, "/camera/color/camera_info", partial(_camera_info, stamp, intrinsics)))
        events.append((stamp, 1, "/camera/color/image_raw", partial(color_image, stamp)))
        events.append((stamp, 2, "/camera/depth/image_raw", partial(depth_image, stamp)))
    for t in hand_times:
        stamp = ns(float(t))
        events.append((stamp, 3, "/hand/pose", partial(hand, stamp, float(t))))
    events.sort(key=lambda e: e[:2])
    try:
        with BagWriter(folder, compression="zstd", chunk_size=4 << 20, flush_interval=None,
                       custom_data={"generator": "coco_ros.palpation.session", "seed": str(seed)}) as writer:
            for written, (stamp, _, topic, make) in enumerate(events, 1):
                writer.write(topic, make(), stamp)
                if step and written % 30 == 0:
                    step(30)
            counts = writer.topic_counts()
        if step:
            step(len(events) % 30)
    finally:
        if bar is not None:
            bar.close()
    return SessionInfo(Path(folder), int(seed), float(duration), start_stamp, look_at(CAMERA_EYE, CAMERA_TARGET),
                       marker_pose(), tracker, intrinsics,
                       [(name, start, end) for name, start, end, _, _ in plan], counts)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="palpation-session",
        description="Generate a seeded remote palpation session (RGB-D camera of a body with a marker, "
                    "a tracked hand) as a rosbag2 (MCAP) bag.")
    parser.add_argument("bag", help="the bag folder to create (must not exist or be empty)")
    parser.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    parser.add_argument("--duration", type=float, default=8.5,
                        help=f"session length in seconds (default 8.5, at least {0.5 * NOMINAL_DURATION:.1f})")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    try:
        info = generate_session(args.bag, args.seed, args.duration, progress=not args.quiet)
    except CocoError as error:
        print(f"palpation-session: {error}", file=sys.stderr)
        return 1
    if not args.quiet:
        counts = ", ".join(f"{topic} {count}" for topic, count in sorted(info.counts.items()))
        touch = next(p for p in info.phases if p[0] == "calibration_touch")
        print(f"wrote {args.bag}: {counts}; calibration touch {touch[1]:.2f}-{touch[2]:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
