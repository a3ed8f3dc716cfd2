"""FrameWriter: records the images it receives as a PNG sequence or an MP4, plus a contact sheet.

Put it in its own activity (triggered by its ``image`` port, or periodic) and connect it with a
buffered connection: encoding and disk writes then happen in that thread, and the renderer that
produces the frames never waits for the disk. Everything received is written, including what is still
queued when the application stops (``on_stop`` drains the port before closing the video), so Ctrl-C
loses no frame that reached the writer.
"""

from __future__ import annotations

import logging
from pathlib import Path

import cv2
import numpy as np

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import FileWriteError, ImageError
from coco_core.ports import InputPort
from coco_core.stamps import Stamped, unstamped
from coco_mr_vision.image import Image

from .contact_sheet import ContactSheet

log = logging.getLogger("coco.display")


class FrameWriter(Component):
    """Writes every received image to ``folder``; at stop, ``contact_sheet.png`` too."""

    folder = Attribute(Path, Path("frames"), "output folder (created if missing)")
    format = Attribute(str, "png", "png (one file per frame) or mp4 (one video, MPEG-4 part 2 'mp4v')",
                       choices=("png", "mp4"))
    prefix = Attribute(str, "frame", "file name start: frame_000000.png ..., frame.mp4")
    fps = Attribute(float, 30.0, "mp4: playback frame rate written in the video", min=0.1)
    png_compression = Attribute(int, 1, "png: zlib level 0-9 (1: fast, a little larger)", min=0, max=9)
    sheet_frames = Attribute(int, 16, "frames on the contact sheet (0: no sheet)", min=0)
    sheet_columns = Attribute(int, 4, "contact sheet columns", min=1)
    sheet_tile_width = Attribute(int, 240, "contact sheet thumbnail width in pixels", min=8)

    image = InputPort(Image | Stamped, event=True, doc="frames to record (any image format; depth is shown as grey), "
                      "optionally Stamped (a stamped GLManager's)")

    def init(self) -> None:
        self.written = 0
        self._first_stamp: float | None = None
        self._video: cv2.VideoWriter | None = None
        self._video_size: tuple[int, int] | None = None
        self._sheet: ContactSheet | None = None

    @property
    def video_path(self) -> Path:
        return self.folder / f"{self.prefix}.mp4"

    @property
    def sheet_path(self) -> Path:
        return self.folder / "contact_sheet.png"

    def frame_path(self, index: int) -> Path:
        return self.folder / f"{self.prefix}_{index:06d}.png"

    def on_config(self) -> None:
        self.folder.mkdir(parents=True, exist_ok=True)
        if self.sheet_frames:
            self._sheet = ContactSheet(self.sheet_frames, self.sheet_columns, self.sheet_tile_width)

    def on_update(self) -> None:
        for image in self.image.read_all():
            self.write(unstamped(image)[0])

    def write(self, image: Image) -> None:
        """Record one image (in the writer's own thread)."""
        rgb = image.to_rgb()
        bgr = rgb[..., ::-1]
        index = self.written
        if self.format == "png":
            if not cv2.imwrite(str(self.frame_path(index)), bgr, [cv2.IMWRITE_PNG_COMPRESSION, self.png_compression]):
                raise FileWriteError(f"FrameWriter {self.name}: could not write {self.frame_path(index)}")
        else:
            self._video_frame(np.ascontiguousarray(bgr))
        if image.stamp is not None and self._first_stamp is None:
            self._first_stamp = image.stamp
        if self._sheet is not None:
            seconds = image.stamp - self._first_stamp if image.stamp is not None and self._first_stamp is not None \
                else None
            self._sheet.add(index, seconds, rgb)
        self.written += 1

    def _video_frame(self, bgr: np.ndarray) -> None:
        size = (bgr.shape[1], bgr.shape[0])
        if self._video is None:
            self._video = cv2.VideoWriter(str(self.video_path), cv2.VideoWriter.fourcc(*"mp4v"), self.fps, size)
            if not self._video.isOpened():
                self._video = None
                raise FileWriteError(f"FrameWriter {self.name}: OpenCV cannot open {self.video_path} for 'mp4v' video")
            self._video_size = size
        elif size != self._video_size:
            width, height = self._video_size or (0, 0)
            raise ImageError(f"FrameWriter {self.name}: frame {self.written} is {size[0]}x{size[1]}, the video is "
                             f"{width}x{height}: a video keeps one size (use png)")
        self._video.write(bgr)

    def on_stop(self) -> None:
        try:
            self.on_update()  # what arrived since the last update is recorded too
        finally:
            if self._video is not None:
                self._video.release()
                self._video = None
            if self._sheet is not None and self._sheet.write(self.sheet_path):
                log.info("FrameWriter %s: %d frames in %s, contact sheet %s", self.name, self.written, self.folder,
                         self.sheet_path)
