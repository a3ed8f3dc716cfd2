"""An application file with two displays and two frame writers, run by the installed ``coco-launch``.

Needs the built workspace (``colcon build --packages-select coco_mr_display`` after changes: the
install is not a symlink install).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from pathlib import Path

import cv2
import pytest

ROOT = Path(__file__).resolve().parents[2]
APP = Path(__file__).resolve().parent / "data" / "display_app.xml"
LAUNCHER = ROOT / "install" / "coco_core" / "lib" / "coco_core" / "coco-launch"
ENTRY_POINTS = ROOT / "install" / "coco_mr_display" / "lib"


@pytest.fixture(scope="module")
def coco_launch() -> Path:
    if not LAUNCHER.exists() or not ENTRY_POINTS.exists():
        pytest.fail("build the workspace first: colcon build --packages-select coco_core coco_mr_display")
    return LAUNCHER


def launch(script: Path, out: Path, *options: str) -> subprocess.Popen[str]:
    """Start the installed launcher on the installed packages, as a user of the built workspace does
    (even when these tests run from the source tree with PYTHONPATH pointing there)."""
    installed = [str(path) for path in sorted(ROOT.glob("install/*/lib/python3*/site-packages"))]
    path = os.pathsep.join([*installed, os.environ.get("PYTHONPATH", "")])
    return subprocess.Popen([str(script), str(APP), f"out:={out}", *options], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "PYTHONPATH": path, "PYTHONUNBUFFERED": "1"})


def written(log: str, writer: str) -> int:
    match = re.search(rf"FrameWriter {writer}: (\d+) frames in ", log)
    assert match, f"FrameWriter {writer} reported nothing:\n{log}"
    return int(match.group(1))


def check_recordings(out: Path, log: str) -> None:
    """Every frame each writer received is on disk, and shows what the displays draw."""
    pngs = sorted((out / "png").glob("frame_*.png"))
    assert len(pngs) == written(log, "writer") >= 5
    last = cv2.imread(str(pngs[-1]))[..., ::-1]
    assert last.shape == (240, 320, 3)
    # The lit red box in the middle of the mono view, over the dark blue background (0.1 0.1 0.2).
    centre = last[100:140, 140:180].reshape(-1, 3).astype(int)
    assert (centre[:, 0] > 2 * centre[:, 1] + 20).all(), "the box is not in the middle of the mono frame"
    assert tuple(last[2, 2]) == (26, 26, 51)
    video = cv2.VideoCapture(str(out / "mp4" / "frame.mp4"))
    assert video.isOpened() and video.get(cv2.CAP_PROP_FRAME_COUNT) == written(log, "encoder") >= 5
    ok, stereo = video.read()
    assert ok and stereo.shape == (120, 320, 3)
    # The green box appears once in each half of the side-by-side frame.
    green = (stereo[..., 1].astype(int) > 100) & (stereo[..., 2] < 100)
    assert green[:, :160].sum() > 50 and green[:, 160:].sum() > 50
    for folder in ("png", "mp4"):
        sheet = cv2.imread(str(out / folder / "contact_sheet.png"))
        assert sheet is not None and sheet.shape[0] > 50


def test_two_displays_render_and_record_through_coco_launch(coco_launch: Path, tmp_path: Path) -> None:
    process = launch(coco_launch, tmp_path, "--duration", "3", "--profile", "10")
    log, _ = process.communicate(timeout=60)
    assert process.returncode == 0, log
    assert "application display_app stopped" in log and "(clean)" in log
    assert re.search(r"render_mono\s+periodic 40 ms", log) and re.search(r"render_stereo\s+periodic 50 ms", log)
    assert re.search(r"display\.color -> writer\.image\s+BUFFER/LOCKED\[64\]\s+(\d+)\s+\1\s+0\s+0", log), log
    check_recordings(tmp_path, log)


def test_ctrl_c_stops_quickly_and_flushes_the_recordings(coco_launch: Path, tmp_path: Path) -> None:
    process = launch(coco_launch, tmp_path, "--duration", "60")
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and len(list((tmp_path / "png").glob("frame_*.png"))) < 10:
            time.sleep(0.1)
        process.send_signal(signal.SIGINT)
        log, _ = process.communicate(timeout=15)
    finally:
        process.kill()
    assert process.returncode == 0, log
    stopped = re.search(r"application display_app stopped ([0-9.]+) s after the request \(clean\)", log)
    assert stopped and float(stopped.group(1)) < 1.0, log
    # The video was finalised (its index written at release) and every received frame is on disk.
    check_recordings(tmp_path, log)
