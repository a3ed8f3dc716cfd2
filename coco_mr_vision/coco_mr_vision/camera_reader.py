"""CameraReader: a periodic source of images from anything OpenCV's ``VideoCapture`` opens.

``source`` says what to open, the way an OpenCV user writes it:

- ``"0"``, ``"2"``: a camera device index (V4L2 ``/dev/video<N>`` on Linux);
- a path with ``*``, ``?`` or ``[``: an image sequence, the files the glob matches in name order;
- a string with ``!``: a GStreamer pipeline ending in ``appsink`` (needs an OpenCV built with
  GStreamer: the pip wheels are not, and the error says so);
- anything else: a video file (or a URL OpenCV's FFmpeg back-end reads).

Each activation delivers at most one frame: at the activity's rate (``timing="rate"``), or when the
file's own clock says the next frame is due (``timing="file"``: the video's timestamps, or ``fps``
for an image sequence) so that a 25 Hz video plays at 25 Hz whatever the activity's period. Frames
come out in ``format``, converted once by OpenCV, stamped with acquisition time, sequence and
source, with the intrinsics of ``intrinsics`` (a JSON file) attached when given.
"""

from __future__ import annotations

import glob
import logging
import time
from pathlib import Path

import cv2
import numpy as np

from coco_core.attributes import Attribute, FileAttribute
from coco_core.component import Component
from coco_core.errors import CameraError, FileReadError
from coco_core.files import check_regular_file, read_regular_file
from coco_core.ports import OutputPort
from coco_core.stamps import Stamp, Stamped

from .image import CameraIntrinsics, Image, ImageFormat

log = logging.getLogger("coco.vision")

IMAGE_FILE_LIMIT = 256 * 2**20
"""Bytes one file of an image sequence may have (a 16k x 16k 8-bit PNG stays under it)."""
VIDEO_FILE_LIMIT = 64 * 2**30
"""Bytes a video file may have: only a bound against a device or /dev/zero named as a video."""


def has_gstreamer() -> bool:
    """Whether this OpenCV build has its GStreamer video back-end."""
    for line in cv2.getBuildInformation().splitlines():
        if line.strip().startswith("GStreamer:"):
            return line.split(":", 1)[1].strip().upper().startswith("YES")
    return False


class _Frames:
    """What a source delivers: BGR frames, each with its media time (seconds) or None."""

    unreadable: list[str]
    """Files passed over because they could not be read (an image sequence's)."""

    def read(self) -> tuple[np.ndarray | None, float | None]:
        raise NotImplementedError

    def rewind(self) -> bool:
        """Back to the first frame; False when the source cannot (a live camera)."""
        raise NotImplementedError

    def close(self) -> None:
        """Release the device or file."""


class _Capture(_Frames):
    def __init__(self, capture: cv2.VideoCapture, live: bool) -> None:
        self.capture, self.live = capture, live
        self.unreadable = []

    def read(self) -> tuple[np.ndarray | None, float | None]:
        ok, frame = self.capture.read()
        if not ok:
            return None, None
        return frame, None if self.live else self.capture.get(cv2.CAP_PROP_POS_MSEC) / 1000.0

    def rewind(self) -> bool:
        return not self.live and bool(self.capture.set(cv2.CAP_PROP_POS_FRAMES, 0))

    def close(self) -> None:
        self.capture.release()


class _Sequence(_Frames):
    """The files of a glob in order. A file that is not an image (truncated, a stray text file) is
    passed over and listed in :attr:`unreadable`: one bad file must not stop the files after it."""

    def __init__(self, files: list[str], fps: float) -> None:
        self.files, self.period, self.index = files, 1.0 / fps, 0
        self.unreadable: list[str] = []
        """Files passed over, in the order met (again on each loop)."""

    def read(self) -> tuple[np.ndarray | None, float | None]:
        while self.index < len(self.files):
            path = self.files[self.index]
            self.index += 1
            try:  # bounded, and never blocked by a FIFO that a glob matched
                data = read_regular_file(path, IMAGE_FILE_LIMIT, "image")
            except FileReadError:
                self.unreadable.append(path)
                continue
            frame = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
            if frame is not None:
                return frame, (self.index - 1) * self.period
            self.unreadable.append(path)
        return None, None

    def rewind(self) -> bool:
        self.index = 0
        return True


def open_source(source: str, fps: float = 30.0) -> tuple[_Frames, str]:
    """The frames of ``source`` and what kind of source it is (device, sequence, gstreamer, file)."""
    text = source.strip()
    if text.isdigit():
        capture = cv2.VideoCapture(int(text))
        if not capture.isOpened():
            raise CameraError(f"cannot open camera device {text} (is /dev/video{text} present and free?)")
        return _Capture(capture, live=True), "device"
    if "!" in text:
        if not has_gstreamer():
            raise CameraError(f"source {text!r} is a GStreamer pipeline, but this OpenCV "
                              f"({cv2.__version__}) was built without GStreamer; use a build with it, "
                              "or a device index, video file or image glob")
        capture = cv2.VideoCapture(text, cv2.CAP_GSTREAMER)
        if not capture.isOpened():
            raise CameraError(f"GStreamer could not start the pipeline {text!r} (it must end in appsink)")
        return _Capture(capture, live=True), "gstreamer"
    if any(c in text for c in "*?["):
        files = sorted(glob.glob(text))
        if not files:
            raise CameraError(f"image sequence {text!r} matches no file")
        return _Sequence(files, fps), "sequence"
    if not Path(text).exists() and "://" not in text:
        raise CameraError(f"video file {text!r} does not exist (a source is a device index, a video file, "
                          "an image glob or a GStreamer pipeline)")
    if "://" not in text:
        try:  # a FIFO or a device would block OpenCV's open, /dev/zero would never end
            check_regular_file(text, VIDEO_FILE_LIMIT, "video file")
        except FileReadError as error:
            raise CameraError(f"source: {error}") from None
    capture = cv2.VideoCapture(text)
    if not capture.isOpened():
        raise CameraError(f"OpenCV cannot open {text!r} as a video")
    return _Capture(capture, live=False), "file"


class CameraReader(Component):
    """Reads one frame per activation from a camera, a video, an image sequence or a GStreamer pipeline."""

    source = Attribute(str, "0", "device index, video file, image glob or GStreamer pipeline")
    format = Attribute(ImageFormat, ImageFormat.BGR8, "format of the output images")
    timing = Attribute(str, "rate", "rate: one frame per activation; file: at the recording's own timing",
                       choices=("rate", "file"))
    fps = Attribute(float, 30.0, "frame rate of an image sequence under timing=file", min=1e-3)
    loop = Attribute(bool, False, "start a video or image sequence again at its end")
    frame_id = Attribute(str, "camera", "frame of the camera in the transformation graph")
    intrinsics = FileAttribute("", "JSON file with the camera's intrinsics (empty: none attached)",
                               expected="a JSON file of camera intrinsics")

    image = OutputPort(Stamped, "Stamped(Image): each frame in `format`, stamped at acquisition")

    def init(self) -> None:
        self._camera: CameraIntrinsics | None = None
        if self.intrinsics:
            with self.reading_attribute_file("intrinsics"):
                self._camera = CameraIntrinsics.from_json(self.intrinsics, frame_id=self.frame_id)
        self.frames = 0
        """Frames delivered."""
        self.ended = False
        """True once a recording ran out (and ``loop`` is off)."""
        self.skipped = 0
        """Files of an image sequence that could not be read as images (passed over; each is also
        counted as a refused input in the profile)."""

    def on_config(self) -> None:
        self._frames, self.kind = open_source(self.source, self.fps)
        self._start: float | None = None
        self._pending: tuple[np.ndarray, float | None] | None = None
        self._seq = 0

    def on_update(self) -> None:
        if self.ended:
            return
        if self._pending is None:
            frame, media_time = self._frames.read()
            if frame is None and self.loop and self._frames.rewind():
                self._start = None
                frame, media_time = self._frames.read()
            self._count_unreadable()
            if frame is None:
                self.ended = True
                log.info("%s: %s %r ended after %d frames", self.name, self.kind, self.source, self.frames)
                return
            self._pending = (frame, media_time)
        frame, media_time = self._pending
        now = time.perf_counter()
        if self.timing == "file" and media_time is not None:
            if self._start is None:
                self._start = now - media_time
            elif now < self._start + media_time:
                return  # not due yet: the frame waits for its time
        self._pending = None
        self._seq += 1
        self.frames += 1
        image = Image(frame, ImageFormat.BGR8, time.time(), self.frame_id, self._camera).to(self.format)
        self.image.write(Stamped(image, Stamp(now, self._seq, self.name)))

    def _count_unreadable(self) -> None:
        unreadable = self._frames.unreadable
        while self.skipped < len(unreadable):
            path = unreadable[self.skipped]
            self.skipped += 1
            self.record_refusal(f"image {path}", CameraError(f"image sequence: cannot read {path} as an image; "
                                                             "passed over"))

    def on_stop(self) -> None:
        if self.skipped:
            log.warning("%s: %d files of %r could not be read and were passed over", self.name, self.skipped,
                        self.source)
        self._frames.close()
