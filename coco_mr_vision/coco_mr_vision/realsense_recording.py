"""A RealSense recording of a known scene, written by librealsense itself, with no camera attached.

Why: the RealSense peer's frame path (pipeline, alignment, depth scale, intrinsics, stamps) and the
bag reader's SQLite storage must run against what librealsense really writes, on machines without a
camera. librealsense's ``software_device`` is a device whose frames the caller supplies; its
``recorder`` writes what such a device streams exactly as it records a D435 (librealsense 2.59: one
rosbag2 SQLite ``.db3`` file, colour as PNG ``CompressedImage``, depth as image_transport's
``compressedDepth`` PNG, ``CameraInfo`` per frame). The scene is a plane at a known depth seen by a
depth and a colour sensor with the same intrinsics, so every value read back can be checked exactly.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np


@dataclass(frozen=True)
class SyntheticScene:
    """What :func:`write_recording` records: each frame's pixels and stamps follow from these."""

    width: int = 64
    height: int = 48
    fps: int = 30
    frames: int = 60
    plane_m: float = 0.75
    """Depth of the plane every depth pixel sees, metres."""
    depth_units: float = 0.0005
    """Metres per depth unit (the device's ``depth_units`` option; a D435 says 0.001)."""
    fx: float = 50.0
    fy: float = 51.0
    first_ms: float = 1000.0
    """Hardware timestamp of the first frame, ms."""
    serial: str = "0123456789"

    @property
    def plane_units(self) -> int:
        """The plane's depth as the 16-bit value every depth pixel holds."""
        return round(self.plane_m / self.depth_units)

    @property
    def depth_scale(self) -> float:
        """Depth units per metre, as RGBDFrame counts them."""
        return 1.0 / self.depth_units

    @property
    def ppx(self) -> float:
        return (self.width - 1) / 2

    @property
    def ppy(self) -> float:
        return (self.height - 1) / 2

    def stamp_ms(self, index: int) -> float:
        """The hardware timestamp of frame ``index``, ms."""
        return self.first_ms + index * 1000.0 / self.fps

    def color(self, index: int) -> np.ndarray:
        """Frame ``index``'s RGB pixels: red along x, green along y, blue the frame's index."""
        x = (np.arange(self.width, dtype=np.uint16) * 255 // max(self.width - 1, 1)).astype(np.uint8)
        y = (np.arange(self.height, dtype=np.uint16) * 255 // max(self.height - 1, 1)).astype(np.uint8)
        pixels = np.empty((self.height, self.width, 3), np.uint8)
        pixels[..., 0] = x[None, :]
        pixels[..., 1] = y[:, None]
        pixels[..., 2] = index % 256
        return pixels

    def depth(self) -> np.ndarray:
        """Every frame's depth: the plane."""
        return np.full((self.height, self.width), self.plane_units, np.uint16)


def write_recording(path: str | Path, scene: SyntheticScene = SyntheticScene()) -> Path:
    """Record ``scene`` through librealsense's recorder into ``path`` (a ``.db3`` file) and return it.

    Frames are fed at the scene's rate (``frames / fps`` seconds of waiting, no CPU), because the
    recorder stamps each message with the time it arrived: a recording fed faster would replay in
    real time faster too.
    """
    import pyrealsense2 as rs

    path = Path(path)
    device = rs.software_device()
    device.register_info(rs.camera_info.name, "CoCo synthetic plane")
    device.register_info(rs.camera_info.serial_number, scene.serial)
    intrinsics = rs.intrinsics()
    intrinsics.width, intrinsics.height = scene.width, scene.height
    intrinsics.fx, intrinsics.fy, intrinsics.ppx, intrinsics.ppy = scene.fx, scene.fy, scene.ppx, scene.ppy
    intrinsics.model, intrinsics.coeffs = rs.distortion.brown_conrady, [0.0] * 5
    sensors, profiles = [], []
    for uid, (name, stream, fmt, bpp) in enumerate((("Depth", rs.stream.depth, rs.format.z16, 2),
                                                    ("Color", rs.stream.color, rs.format.rgb8, 3))):
        sensor = device.add_sensor(name)
        video = rs.video_stream()
        video.type, video.index, video.uid = stream, 0, uid
        video.width, video.height, video.fps, video.bpp, video.fmt = scene.width, scene.height, scene.fps, bpp, fmt
        video.intrinsics = intrinsics
        profiles.append(sensor.add_video_stream(video).as_video_stream_profile())
        sensors.append(sensor)
    sensors[0].add_read_only_option(rs.option.depth_units, scene.depth_units)
    profiles[0].register_extrinsics_to(profiles[1], _identity(rs))
    recorder = rs.recorder(str(path), device)
    queue = rs.frame_queue(4)
    for sensor, profile in zip(sensors, profiles):
        sensor.open(profile)
        sensor.start(queue)
    depth = scene.depth()
    start = time.monotonic()
    for index in range(scene.frames):
        delay = start + index / scene.fps - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        for sensor, profile, pixels, bpp in ((sensors[0], profiles[0], depth, 2),
                                             (sensors[1], profiles[1], scene.color(index), 3)):
            frame = rs.software_video_frame()
            frame.pixels, frame.bpp, frame.stride = pixels, bpp, scene.width * bpp
            frame.timestamp, frame.domain = scene.stamp_ms(index), rs.timestamp_domain.hardware_clock
            frame.frame_number, frame.profile = index, profile
            sensor.on_video_frame(frame)
        while queue.poll_for_frame():
            pass
    for sensor in sensors:
        sensor.stop()
        sensor.close()
    del recorder  # the recorder writes and closes its file when released
    return path


def _identity(rs: Any) -> Any:
    extrinsics = rs.extrinsics()
    extrinsics.rotation = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    extrinsics.translation = [0.0, 0.0, 0.0]
    return extrinsics


__all__ = ["SyntheticScene", "write_recording"]


def frames_of(peer: Any) -> list[Any]:
    """Every frame a recording's peer (an :class:`~coco_mr_vision.rgbd_peers.RgbdPeer`) gives from
    its configuration to its end: what a reader asking for frames at 200 Hz gets of a real-time one."""
    peer.on_config()
    frames = []
    try:
        while not peer.exhausted:
            frame = peer.grab()
            if frame is not None:
                frames.append(frame)
            elif getattr(peer, "realtime", False):
                time.sleep(0.005)
    finally:
        peer.on_stop()
    return frames
