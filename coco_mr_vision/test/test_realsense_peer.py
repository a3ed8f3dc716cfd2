"""The RealSense peer's frame path run for real: a recording written by librealsense itself (a
software device streaming a plane at a known depth, recorded by librealsense's recorder) played
through the peer's pipeline, alignment and filters; and its errors for what is not there."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pyrealsense2", reason="pyrealsense2 is in requirements.txt")

from coco_core import Application, BufferPolicy, Component, ConnectionPolicy, InputPort  # noqa: E402
from coco_core.errors import CameraError  # noqa: E402
from coco_mr_vision.image import ImageFormat  # noqa: E402
from coco_mr_vision.realsense_peer import RealSenseRgbdPeer  # noqa: E402
from coco_mr_vision.realsense_recording import SyntheticScene, frames_of  # noqa: E402
from coco_mr_vision.rgbd_reader import RgbdCameraReader  # noqa: E402

SCENE = SyntheticScene()


class Sink(Component):
    rgbd = InputPort(object)


def test_every_recorded_frame_with_exact_depth_intrinsics_and_stamps(realsense_recording: Path):
    frames = frames_of(RealSenseRgbdPeer("rs", path=str(realsense_recording), realtime=False, align=False))
    assert len(frames) == SCENE.frames
    for index, frame in enumerate(frames):
        assert frame.depth.format is ImageFormat.DEPTH16 and frame.color.format is ImageFormat.RGB8
        assert np.array_equal(frame.depth.data, SCENE.depth()), f"frame {index}: the plane's depth"
        assert np.array_equal(frame.color.data, SCENE.color(index)), f"frame {index}: its colour pattern"
        assert frame.depth.stamp == pytest.approx(SCENE.stamp_ms(index) / 1000.0, abs=1e-6)
        assert frame.color.stamp == pytest.approx(SCENE.stamp_ms(index) / 1000.0, abs=1e-6)
    frame = frames[0]
    assert frame.depth_scale == SCENE.depth_scale == 2000.0, "the device's depth_units, 0.0005 m"
    assert float(np.nanmean(frame.depth_metres())) == pytest.approx(SCENE.plane_m)
    i = frame.intrinsics
    assert (i.width, i.height, i.fx, i.fy, i.cx, i.cy) == (SCENE.width, SCENE.height, SCENE.fx, SCENE.fy,
                                                           SCENE.ppx, SCENE.ppy)
    assert frame.frame_id == "camera"


def test_aligned_to_colour_and_filtered(realsense_recording: Path):
    frames = frames_of(RealSenseRgbdPeer("rs", path=str(realsense_recording), realtime=False,
                                    filters="decimation, hole_filling"))
    assert len(frames) == SCENE.frames
    depth = frames[-1].depth.data
    assert depth.shape == (SCENE.height, SCENE.width), "aligned to colour: the colour image's size"
    assert set(np.unique(depth)) <= {0, SCENE.plane_units}
    assert np.count_nonzero(depth) > depth.size * 0.8, "the plane, seen through the colour camera"


def test_reader_loops_the_recording_and_logs_its_length(realsense_recording: Path, caplog):
    caplog.set_level("INFO", logger="coco.vision")
    reader = RgbdCameraReader("camera", backend="realsense", path=str(realsense_recording), loop=True)
    app = Application("realsense")
    app.add(reader)
    sink = app.add(Sink("sink"))
    app.connect(reader.rgbd, sink.rgbd, ConnectionPolicy(BufferPolicy.BUFFER, size=200))
    reader.init()
    peer = reader.source
    assert isinstance(peer, RealSenseRgbdPeer)
    peer.realtime = False
    peer.on_config()
    reader.on_config()
    try:
        while reader.frames < SCENE.frames + 5:
            reader.on_update()
    finally:
        peer.on_stop()
    assert f"{SCENE.frames} frames of {SCENE.width}x{SCENE.height}" in caplog.text
    assert "camera.realsense: frames stamped by the hardware clock" in caplog.text
    got = sink.rgbd.read_all()
    blue = [int(v.value.color.data[0, 0, 0]) for v in got]  # BGR8 by default: blue first
    assert blue[:SCENE.frames] == list(range(SCENE.frames)) and blue[SCENE.frames:] == [0, 1, 2, 3, 4]


def test_real_time_playback_takes_the_recording_s_time(realsense_recording: Path):
    peer = RealSenseRgbdPeer("rs", path=str(realsense_recording))
    start = time.monotonic()
    frames = frames_of(peer)
    elapsed = time.monotonic() - start
    assert elapsed >= (SCENE.frames - 2) / SCENE.fps * 0.9, "played at the recorded pace"
    assert len(frames) >= SCENE.frames // 3, "frames the reader missed are dropped, as a live camera drops them"
    stamps = [f.stamp for f in frames]
    assert stamps == sorted(stamps)


def test_a_mode_the_recording_lacks_names_the_modes_it_has(realsense_recording: Path):
    peer = RealSenseRgbdPeer("rs", path=str(realsense_recording), width=640, height=480, fps=30)
    with pytest.raises(CameraError, match=r"cannot stream colour 640x480 at 30 fps.*offers "
                                          r"color 64x48 at 30 fps \(rgb8\); depth 64x48 at 30 fps \(z16\)"):
        peer.on_config()


def test_an_unknown_filter_and_a_missing_recording_are_named(tmp_path: Path):
    with pytest.raises(CameraError, match="no librealsense filter 'median'; filters: decimation, threshold"):
        RealSenseRgbdPeer("rs", filters="spatial,median").on_config()
    with pytest.raises(CameraError, match="no librealsense recording"):
        RealSenseRgbdPeer("rs", path=str(tmp_path / "none.db3")).on_config()


def test_a_serial_with_no_device_names_what_is_connected():
    with pytest.raises(CameraError, match="rs: no Intel RealSense device is connected"):
        RealSenseRgbdPeer("rs", serial="123").on_config()
