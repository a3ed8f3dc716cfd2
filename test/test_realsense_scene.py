"""``scene:=realsense`` in config/palpation_replay.xml: the application's camera is the RealSense peer,
and with ``scene_path`` it plays a librealsense recording (written here by librealsense itself) as
the camera did, at the camera activity's period for a live source."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pyrealsense2", reason="pyrealsense2 is in requirements.txt")

from coco_core import registry  # noqa: E402
from coco_core.xml import load_application  # noqa: E402
from coco_mr_vision.realsense_recording import SyntheticScene, write_recording  # noqa: E402
from conftest import ROOT  # noqa: E402

SCENE = SyntheticScene()


def test_scene_realsense_plays_the_recording_as_the_camera(tmp_path: Path):
    recording = write_recording(tmp_path / "desk.db3", SCENE)
    spec = load_application(ROOT / "config" / "palpation_replay.xml", {
        "hand": "topic", "scene": "realsense", "scene_path": str(recording), "registration": "fixed",
        "display": "false"})
    camera = next(c for c in spec.components if c.name == "camera")
    [peer_spec] = camera.peers
    assert (peer_spec.task, {a.name: a.value for a in peer_spec.attributes}) == (
        "RealSenseRgbdPeer", {"path": str(recording)})
    activity = next(a for a in spec.activities if a.name == "camera")
    assert activity.schedule.period_ms == 10.0, "a live source is polled faster than its 30 fps"

    peer = registry.load(peer_spec.task, peer_spec.library)(peer_spec.name, path=str(recording), realtime=False)
    peer.on_config()
    try:
        frame = peer.grab()
    finally:
        peer.on_stop()
    assert frame is not None and frame.depth_scale == SCENE.depth_scale
    assert np.all(frame.depth.data[frame.depth.data > 0] == SCENE.plane_units)
