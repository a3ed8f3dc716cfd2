"""RealSenseRgbdPeer: an Intel RealSense camera, or a librealsense recording of one, through pyrealsense2.

The paper's RgbdCameraReader embeds each vendor's API in a peer; this is librealsense's. What the
device says is used as it says it: the depth scale from the depth sensor's ``depth_units``, the
intrinsics of the stream the depth is registered to, the frames' own (hardware) timestamps as the
images' stamps. A recording (``path``: a ``.db3`` as librealsense 2.59 writes, or an older ``.bag``)
goes through the same pipeline as a live device, so it exercises the same code.

Pairing: librealsense's syncer hands out a frameset whenever either stream has a new frame, the
other one repeated; a frame is delivered only when both halves are new since the last one delivered,
so each recorded pair comes out once (and a live camera gives a pair per frame of its slower stream).
"""

from __future__ import annotations

import logging
import sqlite3
import time
from pathlib import Path
from typing import Any

import numpy as np

from coco_core.attributes import Attribute
from coco_core.errors import CameraError

from .image import CameraIntrinsics, Image, ImageFormat
from .rgbd import RGBDFrame
from .rgbd_peers import RgbdPeer

log = logging.getLogger("coco.vision")

FILTERS = ("decimation", "threshold", "spatial", "temporal", "hole_filling")
"""librealsense's depth post-processing blocks, by the names its documentation and viewer use."""

_COLOR_FORMATS = {"bgr8": ImageFormat.BGR8, "rgb8": ImageFormat.RGB8, "bgra8": ImageFormat.BGRA8,
                  "rgba8": ImageFormat.RGBA8, "y8": ImageFormat.GRAY8, "yuyv": ImageFormat.YUYV}
"""librealsense colour formats (``rs.format`` names) -> the image format they are delivered in."""
_SLICE_MS = 50
"""How long one wait for a recording's next frame lasts before its playback's status is looked at."""


class RealSenseRgbdPeer(RgbdPeer):
    """An Intel RealSense (D400 series and others librealsense drives), or a librealsense recording."""

    path = Attribute(str, "", "a librealsense recording (.db3 or .bag) played instead of a device (empty: a device)")
    serial = Attribute(str, "", "serial number of the device to open (empty: the only one connected; "
                       "not used with path)")
    width = Attribute(int, 0, "colour width (0: librealsense's default for the camera, or the recording's)", min=0)
    height = Attribute(int, 0, "colour height (0: as width)", min=0)
    fps = Attribute(int, 0, "colour frame rate (0: as width)", min=0)
    depth_width = Attribute(int, 0, "depth width (0: librealsense's default, or the recording's)", min=0)
    depth_height = Attribute(int, 0, "depth height (0: as depth_width)", min=0)
    depth_fps = Attribute(int, 0, "depth frame rate (0: as depth_width)", min=0)
    align = Attribute(bool, True, "depth aligned to colour (rs.align: registered pixel for pixel, the colour "
                      "camera's intrinsics); false: the depth camera's own image and intrinsics, colour and depth "
                      "must then be of the same size")
    filters = Attribute(str, "", "librealsense post-processing filters applied to depth, in this order, comma "
                        f"separated: {', '.join(FILTERS)} (with their librealsense defaults)")
    realtime = Attribute(bool, True, "a recording: played at its own pace, frames the reader could not take in time "
                         "skipped as a live camera drops them; false: every frame, as fast as the reader takes them")
    timeout = Attribute(float, 5.0, "seconds without a frame from a device after which it is reported unplugged "
                        "or stalled (an error, the application's on_error decides)", min=0.1)
    frame_id = Attribute(str, "camera", "frame of the camera")

    def on_config(self) -> None:
        try:
            import pyrealsense2 as rs
        except ImportError:
            raise CameraError(f"{self.name}: the RealSense peer needs pyrealsense2 (pip install pyrealsense2)") \
                from None
        self._rs = rs
        self._filters = [self._filter(name) for name in self.filters.replace(",", " ").split()]
        if not self.align and any(n == "decimation" for n in self.filters.replace(",", " ").split()):
            raise CameraError(f"{self.name}: the decimation filter shrinks depth below the colour image's size: "
                              "it needs align=true (depth registered to colour)")
        self._recording = Path(self.path) if self.path else None
        if self._recording is not None and not self._recording.is_file():
            raise CameraError(f"{self.name}: no librealsense recording {self.path!r} (expected a .db3 or .bag file)")
        self._device_serial = "" if self._recording is not None else self._choose_device()
        self._align = rs.align(rs.stream.color) if self.align else None
        self._pipeline: Any = None
        self._domain: str | None = None
        """The clock of the frames' timestamps (hardware_clock, global_time, system_time), logged once."""
        self._start()
        if self._recording is not None:
            playback = self._profile.get_device().as_playback()
            seconds = playback.get_duration().total_seconds()
            log.info("%s: %s: %s frames of %dx%d, %.3f s", self.name, self._recording,
                     self._frame_count(seconds), self._intrinsics.width, self._intrinsics.height, seconds)

    def _filter(self, name: str) -> Any:
        if name not in FILTERS:
            raise CameraError(f"{self.name}: no librealsense filter {name!r}; filters: {', '.join(FILTERS)}")
        return getattr(self._rs, f"{name}_filter")()

    # -- opening ---------------------------------------------------------------------------------

    def _choose_device(self) -> str:
        """The serial number of the device to open; a CameraError naming what is connected otherwise."""
        rs = self._rs
        found = {d.get_info(rs.camera_info.serial_number): d.get_info(rs.camera_info.name)
                 for d in rs.context().query_devices()}
        if not found:
            raise CameraError(f"{self.name}: no Intel RealSense device is connected (librealsense "
                              f"{rs.__version__} found none; name a recording in path to play one)")
        shown = ", ".join(f"{serial} ({name})" for serial, name in sorted(found.items()))
        if self.serial and self.serial not in found:
            raise CameraError(f"{self.name}: no RealSense with serial {self.serial}; connected: {shown}")
        if not self.serial and len(found) > 1:
            raise CameraError(f"{self.name}: {len(found)} RealSense devices are connected ({shown}): name one in "
                              "the serial attribute")
        return self.serial or next(iter(found))

    def _config(self) -> Any:
        rs = self._rs
        config = rs.config()
        if self._recording is not None:
            config.enable_device_from_file(str(self._recording), repeat_playback=False)
        else:
            config.enable_device(self._device_serial)
        color_format = rs.format.any if self._recording is not None else rs.format.bgr8
        config.enable_stream(rs.stream.color, self.width, self.height, color_format, self.fps)
        config.enable_stream(rs.stream.depth, self.depth_width, self.depth_height, rs.format.z16, self.depth_fps)
        return config

    def _start(self) -> None:
        rs = self._rs
        config = self._config()
        self._pipeline = rs.pipeline()
        try:
            # Why resolve first: a recording must be switched out of real time before it starts, or the
            # frames it plays before the switch are lost.
            resolved = config.resolve(rs.pipeline_wrapper(self._pipeline))
            if self._recording is not None:
                resolved.get_device().as_playback().set_real_time(self.realtime)
            self._profile = self._pipeline.start(config)
        except RuntimeError as error:
            raise CameraError(f"{self.name}: {self._source()} cannot stream {self._asked()} ({error}); it offers "
                              f"{self._modes()}") from None
        try:
            self._read_profile()
        except CameraError:
            self._pipeline.stop()  # a device left streaming would refuse the next opening
            self._pipeline = None
            raise
        self._last: tuple[int, int] | None = None
        self._waiting_since = time.monotonic()
        self._played = False
        """A recording's playback was seen playing, or gave a frame: only then is "stopped" its end
        (right after the start, on a loaded machine, it said stopped before it began)."""
        self.exhausted = False

    def _read_profile(self) -> None:
        """Depth scale, colour format and intrinsics of the started pipeline; a CameraError for what
        this peer cannot deliver."""
        rs = self._rs
        device = self._profile.get_device()
        units = device.first_depth_sensor().get_depth_scale()
        # The option is a float32: its 7 significant digits are the decimal the device means (0.001,
        # not 0.0010000000475), so a millimetre camera's scale is 1000 exactly.
        self._scale = 1.0 / float(f"{units:.7g}")
        streams = {s.stream_type(): s.as_video_stream_profile() for s in self._profile.get_streams()}
        color, depth = streams[rs.stream.color], streams[rs.stream.depth]
        self._color_format = _COLOR_FORMATS.get(color.format().name)
        if self._color_format is None:
            raise CameraError(f"{self.name}: {self._source()} streams colour as {color.format().name}; readable: "
                              f"{', '.join(_COLOR_FORMATS)}")
        if self._align is None and (color.width(), color.height()) != \
                (depth.width(), depth.height()):
            raise CameraError(f"{self.name}: colour is {color.width()}x{color.height()} and depth "
                              f"{depth.width()}x{depth.height()}: without align they must be of the same size")
        registered = color if self._align is not None else depth
        self._intrinsics = _intrinsics(registered.get_intrinsics(), self.frame_id)

    def _source(self) -> str:
        return f"recording {self._recording}" if self._recording is not None else f"RealSense {self._device_serial}"

    def _asked(self) -> str:
        def mode(width: int, height: int, fps: int) -> str:
            size = f"{width}x{height}" if width else "any size"
            return f"{size} at {fps} fps" if fps else f"{size} at any rate"
        return (f"colour {mode(self.width, self.height, self.fps)}, "
                f"depth {mode(self.depth_width, self.depth_height, self.depth_fps)}")

    def _modes(self) -> str:
        """The colour and depth modes the device or recording has, e.g. ``color 640x480 at 15/30 fps (bgr8, rgb8)``."""
        rs = self._rs
        try:
            device = (rs.context().load_device(str(self._recording)) if self._recording is not None else
                      next(d for d in rs.context().query_devices()
                           if d.get_info(rs.camera_info.serial_number) == self._device_serial))
        except (RuntimeError, StopIteration):
            return "nothing: it was not found again"
        modes: dict[tuple[str, int, int], tuple[set[int], set[str]]] = {}
        for sensor in device.query_sensors():
            for profile in sensor.get_stream_profiles():
                if profile.stream_type() not in (rs.stream.color, rs.stream.depth) or not profile.is_video_stream_profile():
                    continue
                video = profile.as_video_stream_profile()
                rates, formats = modes.setdefault((video.stream_type().name, video.width(), video.height()), (set(), set()))
                rates.add(video.fps())
                formats.add(video.format().name)
        return "; ".join(f"{stream} {w}x{h} at {'/'.join(map(str, sorted(rates)))} fps ({', '.join(sorted(formats))})"
                         for (stream, w, h), (rates, formats) in sorted(modes.items()))

    def _frame_count(self, seconds: float) -> str:
        """Depth frames in the recording: counted in a .db3's messages (read-only), else from its duration."""
        if self._recording is not None and self._recording.suffix == ".db3":
            try:
                with sqlite3.connect(f"{self._recording.resolve().as_uri()}?mode=ro", uri=True) as db:
                    row = db.execute("SELECT count(*) FROM messages JOIN topics ON topics.id = messages.topic_id "
                                     "WHERE topics.name LIKE '%/Depth_%/image/data%'").fetchone()
                return str(row[0])
            except sqlite3.Error:
                pass
        rate = self._profile.get_stream(self._rs.stream.depth).fps()
        return f"about {round(seconds * rate)}"

    # -- frames ----------------------------------------------------------------------------------

    def grab(self) -> RGBDFrame | None:
        while True:
            frames = self._next_frames()
            if frames is None:
                return None
            depth, color = frames.get_depth_frame(), frames.get_color_frame()
            if not depth or not color:
                continue
            numbers = (depth.get_frame_number(), color.get_frame_number())
            if self._last is not None and (numbers[0] == self._last[0] or numbers[1] == self._last[1]):
                continue  # one half repeated by the syncer: not a new pair
            self._last = numbers
            if self._domain is None:
                self._domain = depth.get_frame_timestamp_domain().name
                log.info("%s: frames stamped by the %s", self.name, self._domain.replace("_", " "))
            return self._frame(frames)

    def _next_frames(self) -> Any:
        """The next frameset, or None: none ready now (live, or a real-time recording between frames), or
        the recording is over (then ``exhausted``). A device silent for ``timeout`` is an error."""
        if self._recording is not None:
            return self._next_recorded()
        frames = self._pipeline.poll_for_frames()
        if frames:
            self._waiting_since = time.monotonic()
            return frames
        silent = time.monotonic() - self._waiting_since
        if silent >= self.timeout:
            self._waiting_since = time.monotonic()  # the next report after another timeout, not every grab
            raise CameraError(self._silence(silent))
        return None

    def _next_recorded(self) -> Any:
        """A recording's next frameset: at once in real time, else waited for (in slices, so that the
        end of the recording is seen when it comes rather than after ``timeout``)."""
        deadline = time.monotonic() + (0.0 if self.realtime else self.timeout)
        while True:
            ready, frames = self._pipeline.try_wait_for_frames(0 if self.realtime else _SLICE_MS)
            if ready:
                self._played = True
                return frames
            status = self._profile.get_device().as_playback().current_status()
            if status == self._rs.playback_status.playing:
                self._played = True
            elif not self._played and time.monotonic() - self._waiting_since >= self.timeout:
                raise CameraError(f"{self.name}: the recording {self._recording} did not start playing within "
                                  f"{self.timeout:g} s")
            elif status == self._rs.playback_status.stopped and self._played:
                frames = self._pipeline.poll_for_frames()  # what the pipeline still held when playback ended
                if frames:
                    return frames
                self.exhausted = True
                return None
            if time.monotonic() >= deadline:
                return None

    def _silence(self, seconds: float) -> str:
        rs = self._rs
        connected = [d.get_info(rs.camera_info.serial_number) for d in rs.context().query_devices()]
        if self._device_serial not in connected:
            return (f"{self.name}: RealSense {self._device_serial} was unplugged: no frame for {seconds:.1f} s and "
                    f"it is no longer connected (connected: {', '.join(connected) or 'none'})")
        return (f"{self.name}: RealSense {self._device_serial} sent no frame for {seconds:.1f} s although it is "
                "connected (a USB 2 port or a busy bus cannot carry the modes asked?)")

    def _frame(self, frames: Any) -> RGBDFrame:
        for block in self._filters:
            frames = block.process(frames).as_frameset()
        if self._align is not None:
            frames = self._align.process(frames)
        depth, color = frames.get_depth_frame(), frames.get_color_frame()
        color_format = self._color_format
        assert color_format is not None
        # Copies: librealsense recycles a frame's buffer once it is released.
        return RGBDFrame(
            Image(np.asanyarray(color.get_data()).copy(), color_format, color.get_timestamp() / 1000.0,
                  self.frame_id, self._intrinsics),
            Image(np.asanyarray(depth.get_data()).copy(), ImageFormat.DEPTH16, depth.get_timestamp() / 1000.0,
                  self.frame_id, self._intrinsics),
            self._intrinsics, self._scale)

    def rewind(self) -> bool:
        if self._recording is None:
            return False
        self._pipeline.stop()
        self._start()
        return True

    def on_stop(self) -> None:
        if self._pipeline is not None:
            self._pipeline.stop()
            self._pipeline = None


def _intrinsics(stream: Any, frame_id: str) -> CameraIntrinsics:
    return CameraIntrinsics(stream.width, stream.height, stream.fx, stream.fy, stream.ppx, stream.ppy,
                            distortion=tuple(stream.coeffs), frame_id=frame_id)


__all__ = ["FILTERS", "RealSenseRgbdPeer"]
