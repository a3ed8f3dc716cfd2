"""Shared inputs of the coco_mr_vision tests."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def realsense_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A librealsense recording of :class:`~coco_mr_vision.realsense_recording.SyntheticScene`, written
    by librealsense's own recorder once per test session (2 s of waiting: it is fed at 30 fps)."""
    pytest.importorskip("pyrealsense2", reason="pyrealsense2 is in requirements.txt")
    from coco_mr_vision.realsense_recording import write_recording

    return write_recording(tmp_path_factory.mktemp("realsense") / "plane.db3")
