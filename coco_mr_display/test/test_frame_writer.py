"""FrameWriter records what reaches it (PNG exactly, MP4 decodable) in its own thread, then a contact sheet."""

from __future__ import annotations

import threading
from pathlib import Path

import cv2
import numpy as np
import pytest

from coco_core import Application, TriggeredActivity
from coco_core.component import Component
from coco_core.policy import BufferPolicy, ConnectionPolicy, SyncPolicy
from coco_core.ports import OutputPort
from coco_mr_display.contact_sheet import ContactSheet
from coco_mr_display.frame_writer import FrameWriter
from coco_mr_vision.image import Image, ImageFormat


class Source(Component):
    image = OutputPort(Image)


def frame(index: int, width: int = 64, height: int = 48) -> Image:
    """A frame that says which it is: a gradient, and its index in the top-left pixels' red."""
    data = np.empty((height, width, 3), np.uint8)
    data[...] = np.linspace(0, 255, width, dtype=np.uint8)[None, :, None]
    data[:, :, 2] = 255 - data[:, :, 0]
    data[:4, :4] = (index % 256, 40, 200)
    return Image(data, ImageFormat.RGB8, stamp=100.0 + index / 30.0)


def record(tmp_path: Path, count: int, **attributes: object) -> FrameWriter:
    """Write ``count`` frames through a real buffered connection into a writer on its own activity,
    then stop at once: the frames still queued must be written by on_stop."""
    app = Application("writer-test")
    source = app.add(Source("source"))
    writer = app.add(FrameWriter("writer", folder=tmp_path / "out", **attributes),
                     TriggeredActivity("writing"))
    app.connect("source.image", "writer.image", ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, count))
    app.start()
    for index in range(count):
        source.image.write(frame(index))
    assert app.stop()
    return writer


def test_png_sequence_is_exact_and_complete_and_the_sheet_is_evenly_spaced(tmp_path: Path) -> None:
    writer = record(tmp_path, 37, sheet_frames=4, sheet_columns=2, sheet_tile_width=64)
    assert writer.written == 37 and writer.stats.errors == 0
    files = sorted((tmp_path / "out").glob("frame_*.png"))
    assert [f.name for f in files] == [f"frame_{i:06d}.png" for i in range(37)]
    for index in (0, 17, 36):
        written = cv2.imread(str(files[index]))[..., ::-1]
        assert np.array_equal(written, frame(index).data)
    sheet = cv2.imread(str(tmp_path / "out" / "contact_sheet.png"))[..., ::-1]
    # 4 tiles of 64x48 in 2 columns with 4 px gaps: 2 x 2 grid.
    assert sheet.shape == (2 * 52 + 4, 2 * 68 + 4, 3)
    # Evenly spaced: frames 0, 12, 24, 36 here (the marker pixels carry the index).
    for slot, index in enumerate((0, 12, 24, 36)):
        y, x = 4 + (slot // 2) * 52, 4 + (slot % 2) * 68
        assert tuple(sheet[y + 1, x + 1]) == (index, 40, 200)


def test_mp4_video_decodes_with_every_frame(tmp_path: Path) -> None:
    writer = record(tmp_path, 30, format="mp4", fps=15.0, sheet_frames=0)
    video = cv2.VideoCapture(str(tmp_path / "out" / "frame.mp4"))
    assert video.isOpened()
    assert video.get(cv2.CAP_PROP_FRAME_COUNT) == 30 and video.get(cv2.CAP_PROP_FPS) == pytest.approx(15.0)
    decoded = []
    while True:
        ok, bgr = video.read()
        if not ok:
            break
        decoded.append(bgr[..., ::-1])
    assert len(decoded) == 30 and decoded[0].shape == (48, 64, 3)
    # Lossy, but the gradient survives: mean error of a few grey levels.
    assert np.abs(decoded[10].astype(int) - frame(10).data).mean() < 6
    assert not (tmp_path / "out" / "contact_sheet.png").exists() and writer.written == 30


def test_mp4_rejects_a_size_change_with_a_clear_error(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    writer = FrameWriter("writer", folder=tmp_path, format="mp4")
    Application("size-change").add(writer)
    assert writer.configure()
    writer.write(frame(0))
    with pytest.raises(ValueError, match="frame 1 is 32x48, the video is 64x48: a video keeps one size"):
        writer.write(frame(1, width=32))
    writer.stop()


def test_depth_images_are_recorded_as_grey(tmp_path: Path) -> None:
    depth = np.tile(np.linspace(0.5, 2.0, 40, dtype=np.float32), (30, 1))
    depth[0, 0] = np.nan
    writer = FrameWriter("writer", folder=tmp_path, sheet_frames=0)
    Application("depth").add(writer)
    assert writer.configure()
    writer.write(Image(depth, ImageFormat.DEPTH32F))
    writer.stop()
    grey = cv2.imread(str(tmp_path / "frame_000000.png"))
    assert grey[0, 0].tolist() == [0, 0, 0] and grey[5, -1].tolist() == [255, 255, 255]
    assert np.all(np.diff(grey[5, :, 0].astype(int)) >= 0)


def test_contact_sheet_memory_stays_bounded_and_spacing_even() -> None:
    sheet = ContactSheet(frames=8, columns=4, tile_width=16)
    for index in range(1001):
        sheet.add(index, index / 30.0, np.full((12, 16, 3), index % 256, np.uint8))
    assert len(sheet.kept) < 32 and sheet.stride == 64
    chosen = [kept.index for kept in sheet.chosen()]
    assert chosen[0] == 0 and chosen[-1] == 1000 and len(chosen) == 8
    ideal = np.linspace(0, 1000, 8)
    assert np.abs(np.array(chosen) - ideal).max() <= sheet.stride / 2
    rendered = sheet.render()
    assert rendered is not None and rendered.shape == (2 * (12 + 4) + 4, 4 * (16 + 4) + 4, 3)


def test_writing_happens_in_the_writer_thread(tmp_path: Path) -> None:
    """The producer only pushes references; encoding and disk writes run in the writer's activity."""
    threads: set[str] = set()

    class Spy(FrameWriter):
        def write(self, image: Image) -> None:
            threads.add(threading.current_thread().name)
            super().write(image)

    app = Application("writer-thread")
    source = app.add(Source("source"))
    writer = app.add(Spy("writer", folder=tmp_path, sheet_frames=4), TriggeredActivity("writing"))
    app.connect("source.image", "writer.image", ConnectionPolicy(BufferPolicy.BUFFER, SyncPolicy.LOCKED, 64))
    app.start()
    for index in range(20):
        source.image.write(frame(index, 640, 480))
    assert app.stop()
    assert writer.written == 20 and len(list(tmp_path.glob("frame_*.png"))) == 20
    assert threads == {"coco:writing"}
