"""Back-ends of the RgbdCameraReader, as peers (the paper's pattern: one reader, one peer per device).

The peer interface, for whoever adds an OpenNI, Kinect or ZED peer:

- subclass :class:`RgbdPeer` (a Component, so it has attributes an XML file can set, and is
  registered under ``coco.components`` like any other);
- open the device or recording in ``on_config`` and raise :class:`~coco_core.errors.CameraError`
  with what is missing when it cannot (no device, no SDK, no file);
- implement ``grab()``: the next :class:`RGBDFrame` (colour and depth registered to each other, same
  size, with the depth camera's intrinsics and the depth scale of its 16-bit depth), or ``None``
  when no new frame is ready now (a live device between frames) or the recording is over
  (then set ``exhausted``);
- implement ``rewind()`` for recordings (``loop``), return False for live devices;
- release the device in ``on_stop``.

The reader, not the peer, stamps frames, converts formats and writes the port: a peer only delivers.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import CameraError
from coco_core.files import DATA_FILE_LIMIT, read_regular_file

from .image import CameraIntrinsics, Image, ImageFormat
from .rgbd import RGBDFrame

PRIMESENSE = CameraIntrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)
"""The default intrinsics of the PrimeSense / Kinect v1 sensors that TUM and Redwood recorded with."""


class RgbdPeer(Component):
    """Base of RGB-D back-ends: see the module docstring for the contract."""

    exhausted = False
    """Set by a recording peer once its last frame was delivered."""

    def grab(self) -> RGBDFrame | None:
        raise NotImplementedError(f"{type(self).__name__} must implement grab()")

    def rewind(self) -> bool:
        """Back to the first frame; False for a live device."""
        return False


def _folder(path: str, what: str) -> Path:
    folder = Path(path)
    if not folder.is_dir():
        raise CameraError(f"{what}: {path!r} is not a folder")
    return folder


def _intrinsics_file(path: str, default: CameraIntrinsics | None, frame_id: str) -> CameraIntrinsics:
    if path:
        return CameraIntrinsics.from_json(path, frame_id=frame_id)
    assert default is not None
    return CameraIntrinsics.from_matrix(default.K, default.width, default.height, frame_id=frame_id)


class _FilePairs(RgbdPeer):
    """A list of (colour file, depth file, time) read in order with OpenCV."""

    path: Attribute[str]  # each dataset peer declares it, with its own description

    def _open(self) -> tuple[list[tuple[Path, Path, float | None]], CameraIntrinsics, float]:
        raise NotImplementedError

    def on_config(self) -> None:
        self._pairs, self._intrinsics, self._scale = self._open()
        if not self._pairs:
            raise CameraError(f"{self.name}: no colour/depth pairs in {self.path!r}")
        self._index = 0
        self.exhausted = False

    def grab(self) -> RGBDFrame | None:
        if self._index >= len(self._pairs):
            self.exhausted = True
            return None
        color, depth, stamp = self._pairs[self._index]
        self._index += 1
        try:
            frame = RGBDFrame.load(color, depth, self._intrinsics, self._scale, stamp, self._intrinsics.frame_id)
        except (FileNotFoundError, ValueError) as error:
            raise CameraError(f"{self.name}: {error}") from None
        return frame

    def rewind(self) -> bool:
        self._index, self.exhausted = 0, False
        return True


class TumRgbdPeer(_FilePairs):
    """A TUM RGB-D sequence folder: ``rgb.txt`` and ``depth.txt`` (``time file`` per line), paired by
    nearest time as TUM's ``associate.py`` does, or the association file that script wrote."""

    path = Attribute(str, "", "the sequence folder (holding rgb.txt, depth.txt, rgb/, depth/)")
    association = Attribute(str, "", "association file (time rgb time depth per line), relative to path; "
                            "empty: associations.txt if present, else pair rgb.txt and depth.txt")
    max_difference = Attribute(float, 0.02, "largest colour/depth time difference paired, s", min=0.0)
    intrinsics = Attribute(str, "", "JSON intrinsics (empty: PrimeSense defaults, as Open3D uses for TUM)")
    depth_scale = Attribute(float, 5000.0, "depth units per metre (TUM: 5000)", min=1e-9)
    frame_id = Attribute(str, "camera", "frame of the camera")

    def _open(self) -> tuple[list[tuple[Path, Path, float | None]], CameraIntrinsics, float]:
        folder = _folder(self.path, "TUM RGB-D sequence")
        association = folder / (self.association or "associations.txt")
        if association.exists():
            with self.reading_attribute_file("association", "a text file of lines 'time rgb time depth'"):
                rows = _rows(association, 4)
            pairs: list[tuple[Path, Path, float | None]] = [(folder / row[1], folder / row[3], float(row[0]))
                                                            for row in rows]
        elif self.association:
            raise CameraError(f"TUM association file {association} does not exist")
        else:
            with self.reading_attribute_file("path", "a TUM sequence folder whose rgb.txt and depth.txt are "
                                             "text files of lines 'time file'"):
                rgb, depth = _rows(folder / "rgb.txt", 2), _rows(folder / "depth.txt", 2)
            pairs = associate(rgb, depth, self.max_difference, folder)
        with self.reading_attribute_file("intrinsics", "a JSON file of camera intrinsics"):
            intrinsics = _intrinsics_file(self.intrinsics, PRIMESENSE, self.frame_id)
        return pairs, intrinsics, self.depth_scale


def _rows(path: Path, columns: int) -> list[list[str]]:
    """The data lines of a TUM text file (``#`` comments skipped), each with at least ``columns`` fields."""
    if not path.exists():
        raise CameraError(f"TUM RGB-D: {path} does not exist (a TUM sequence has rgb.txt and depth.txt, "
                          "or an association file)")
    rows = []
    text = read_regular_file(path, DATA_FILE_LIMIT, "TUM list").decode("utf-8", errors="replace")
    for number, line in enumerate(text.splitlines(), 1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        if len(fields) < columns:
            raise CameraError(f"{path}:{number}: expected {columns} fields (time file ...), got {line!r}")
        try:
            float(fields[0])
        except ValueError:
            raise CameraError(f"{path}:{number}: expected a time in seconds first, got {fields[0]!r}") from None
        rows.append(fields)
    return rows


def associate(rgb: list[list[str]], depth: list[list[str]], max_difference: float,
              folder: Path) -> list[tuple[Path, Path, float | None]]:
    """Pairs colour and depth rows by nearest time, each row used once (TUM's ``associate.py``)."""
    depth_times = np.array([float(row[0]) for row in depth])
    used = np.zeros(len(depth), bool)
    pairs: list[tuple[Path, Path, float | None]] = []
    for row in rgb:
        t = float(row[0])
        if not len(depth_times):
            break
        order = np.argsort(np.abs(depth_times - t))
        for index in order[:4]:
            if not used[index] and abs(depth_times[index] - t) <= max_difference:
                used[index] = True
                pairs.append((folder / row[1], folder / depth[index][1], t))
                break
    return pairs


class RedwoodRgbdPeer(_FilePairs):
    """A Redwood / Open3D folder: ``color/`` and ``depth/`` with numbered files, a camera JSON beside them."""

    path = Attribute(str, "", "the folder holding color/ and depth/")
    intrinsics = Attribute(str, "", "JSON intrinsics (empty: the folder's *.json, else PrimeSense defaults)")
    depth_scale = Attribute(float, 1000.0, "depth units per metre (Redwood: millimetres)", min=1e-9)
    fps = Attribute(float, 30.0, "frame rate the numbered files were recorded at (for their stamps)", min=1e-3)
    frame_id = Attribute(str, "camera", "frame of the camera")

    def _open(self) -> tuple[list[tuple[Path, Path, float | None]], CameraIntrinsics, float]:
        folder = _folder(self.path, "Redwood RGB-D folder")
        colors = sorted(p for p in (folder / "color").glob("*") if p.suffix.lower() in (".jpg", ".jpeg", ".png"))
        depths = sorted((folder / "depth").glob("*.png"))
        if len(colors) != len(depths):
            raise CameraError(f"Redwood folder {folder}: {len(colors)} colour images but {len(depths)} depth "
                              "images; they must pair up by number")
        for color, depth in zip(colors, depths):
            if color.stem != depth.stem:
                raise CameraError(f"Redwood folder {folder}: colour {color.name} pairs with depth {depth.name}")
        intrinsics_path = self.intrinsics
        if not intrinsics_path:
            found = sorted(folder.glob("*.json"))
            intrinsics_path = str(found[0]) if found else ""
        pairs = [(c, d, index / self.fps) for index, (c, d) in enumerate(zip(colors, depths))]
        with self.reading_attribute_file("intrinsics", "a JSON file of camera intrinsics"):
            intrinsics = _intrinsics_file(intrinsics_path, PRIMESENSE, self.frame_id)
        return pairs, intrinsics, self.depth_scale


class BagRgbdPeer(RgbdPeer):
    """A rosbag2 bag with ``sensor_msgs/Image`` colour and depth and ``sensor_msgs/CameraInfo``.

    Colour and depth are paired by header stamp (nearest within ``max_difference``), the newest
    CameraInfo gives the intrinsics. Messages go through coco_ros's bag reader and converters. A
    malformed message (an image encoding the converter does not read, a depth image that is not
    depth, colour and depth of different sizes, images that disagree with the camera_info) is
    skipped, counted in the profile's refused column and reported as damaged input; the frames
    after it are delivered."""

    path = Attribute(str, "", "the bag folder or .mcap file")
    color_topic = Attribute(str, "/camera/color/image_raw", "colour images")
    depth_topic = Attribute(str, "/camera/depth/image_raw", "depth images registered to the colour ones")
    info_topic = Attribute(str, "/camera/color/camera_info", "camera intrinsics")
    max_difference = Attribute(float, 0.02, "largest colour/depth stamp difference paired, s", min=0.0)
    depth_scale = Attribute(float, 1000.0, "units per metre of 16UC1 depth (ROS: millimetres)", min=1e-9)
    realtime = Attribute(bool, False, "deliver the recording as the live camera did: each frame once the "
                         "time since the first one reaches its stamp's; frames the reader could not take in "
                         "time are skipped (the profile's merged column); false: the next frame at each grab")

    def on_config(self) -> None:
        from coco_ros.bag import BagReader  # ROS only for this peer
        from coco_ros.convert.images import CameraInfoConverter, ImageMessageConverter

        try:
            self._reader = BagReader(self.path)
        except Exception as error:  # noqa: BLE001 - the bag layer's errors say what is wrong
            raise CameraError(f"{self.name}: cannot read the bag {self.path!r}: {error}") from None
        topics = set(self._reader.topics)
        missing = [t for t in (self.color_topic, self.depth_topic) if t not in topics]
        if missing:
            raise CameraError(f"{self.name}: bag {self.path!r} has no topic {', '.join(missing)}; "
                              f"it has {', '.join(sorted(topics))}")
        self._images, self._infos = ImageMessageConverter(copy=True), CameraInfoConverter()
        self.refused_messages = 0
        """Malformed messages skipped, over every pass of a looped recording."""
        self._start()

    def _start(self) -> None:
        wanted = [self.color_topic, self.depth_topic, self.info_topic]
        self._messages = self._reader.messages([t for t in wanted if t in self._reader.topics])
        self._intrinsics: CameraIntrinsics | None = None
        self._color: list[Image] = []
        self._depth: list[Image] = []
        self.exhausted = False
        self._pending: RGBDFrame | None = None
        """With realtime: the next frame, read but not due yet."""
        self._offset: float | None = None
        """With realtime: perf_counter time minus stamp of the recording's clock."""

    def grab(self) -> RGBDFrame | None:
        if not self.realtime:
            return self._next_pair()
        # Why: a replay that falls behind (a loaded machine, a slow reader) would deliver a scene
        # ever older than the other streams of the same recording (a hand, a robot); a live camera
        # never waits, it drops. The frame of the recording's present is delivered, never one early.
        now = time.perf_counter()
        frame = self._pending if self._pending is not None else self._next_pair()
        self._pending = None
        if frame is None or frame.stamp is None:
            return frame
        if self._offset is None:
            self._offset = now - frame.stamp
        if frame.stamp + self._offset > now:
            self._pending = frame
            return None
        while (later := self._next_pair()) is not None:
            if later.stamp is None or later.stamp + self._offset > now:
                self._pending = later
                break
            self.record_merged()  # superseded: a later frame is due already
            frame = later
        return frame

    def _next_pair(self) -> RGBDFrame | None:
        for message in self._messages:
            try:
                frame = self._take(message)
            except Exception as error:  # noqa: BLE001 - a malformed message must cost itself only
                self._refuse(message, error)
                continue
            if frame is not None:
                return frame
        self.exhausted = True
        return None

    def _take(self, message: Any) -> RGBDFrame | None:
        """The frame ``message`` completes, if any; raises when it is malformed (an encoding the
        converter does not read, a depth that is not depth, images of sizes that disagree with each
        other or with the camera_info)."""
        if message.topic == self.info_topic:
            self._intrinsics = self._infos.to_coco(message.message)
            return None
        image = self._images.to_coco(message.message)
        (self._color if message.topic == self.color_topic else self._depth).append(image)
        return self._pair()

    def _refuse(self, message: Any, error: Exception) -> None:
        """Refuse a malformed message as damaged input (:meth:`Component.refuse_damaged_input`); the
        frames after it are delivered. Why: it raised out of the reader before, counted as the
        reader's error and nowhere else, and the run exited 0 as if the recording were sound."""
        self.refused_messages += 1
        offset = (message.log_time - self._reader.start_time) / 1e9
        self.refuse_damaged_input(self.path, f"the {message.topic} message {offset:.3f} s into the bag", error)

    def _pair(self) -> RGBDFrame | None:
        for depth in self._depth:
            for color in self._color:
                if color.stamp is not None and depth.stamp is not None and \
                        abs(color.stamp - depth.stamp) <= self.max_difference:
                    # Older unpaired images can never pair now: drop them with the pair.
                    self._color = [c for c in self._color if c.stamp is not None and c.stamp > color.stamp]
                    self._depth = [d for d in self._depth if d.stamp is not None and d.stamp > depth.stamp]
                    return RGBDFrame(color, depth, self._intrinsics, self.depth_scale)
        return None

    def rewind(self) -> bool:
        self._start()
        return True

    def on_stop(self) -> None:
        self._reader.close()


class RealSenseRgbdPeer(RgbdPeer):
    """An Intel RealSense camera through ``pyrealsense2``: depth aligned to colour, 16-bit depth at
    the device's own depth scale, intrinsics from the device."""

    width = Attribute(int, 640, "stream width", min=1)
    height = Attribute(int, 480, "stream height", min=1)
    fps = Attribute(int, 30, "stream rate", min=1)
    serial = Attribute(str, "", "serial number of the device to open (empty: the first one)")
    frame_id = Attribute(str, "camera", "frame of the camera")

    def on_config(self) -> None:
        try:
            import pyrealsense2 as rs
        except ImportError:
            raise CameraError(f"{self.name}: the RealSense peer needs pyrealsense2 (pip install pyrealsense2)") \
                from None
        devices = rs.context().query_devices()
        serials = [d.get_info(rs.camera_info.serial_number) for d in devices]
        if not serials:
            raise CameraError(f"{self.name}: no Intel RealSense device is connected")
        if self.serial and self.serial not in serials:
            raise CameraError(f"{self.name}: no RealSense with serial {self.serial}; connected: {', '.join(serials)}")
        self._rs = rs
        config = rs.config()
        if self.serial:
            config.enable_device(self.serial)
        config.enable_stream(rs.stream.color, self.width, self.height, rs.format.bgr8, self.fps)
        config.enable_stream(rs.stream.depth, self.width, self.height, rs.format.z16, self.fps)
        self._pipeline = rs.pipeline()
        profile = self._pipeline.start(config)
        self._scale = 1.0 / profile.get_device().first_depth_sensor().get_depth_scale()
        self._align = rs.align(rs.stream.color)
        stream = profile.get_stream(rs.stream.color).as_video_stream_profile().get_intrinsics()
        self._intrinsics = CameraIntrinsics(stream.width, stream.height, stream.fx, stream.fy, stream.ppx,
                                            stream.ppy, distortion=tuple(stream.coeffs), frame_id=self.frame_id)

    def grab(self) -> RGBDFrame | None:
        frames = self._pipeline.poll_for_frames()
        if not frames:
            return None
        frames = self._align.process(frames)
        color, depth = frames.get_color_frame(), frames.get_depth_frame()
        if not color or not depth:
            return None
        stamp = frames.get_timestamp() / 1000.0
        return RGBDFrame(Image(np.asanyarray(color.get_data()).copy(), ImageFormat.BGR8, stamp, self.frame_id,
                               self._intrinsics),
                         Image(np.asanyarray(depth.get_data()).copy(), ImageFormat.DEPTH16, stamp, self.frame_id,
                               self._intrinsics), self._intrinsics, self._scale)

    def on_stop(self) -> None:
        self._pipeline.stop()


BACKENDS: dict[str, type[RgbdPeer]] = {
    "tum": TumRgbdPeer, "redwood": RedwoodRgbdPeer, "bag": BagRgbdPeer, "realsense": RealSenseRgbdPeer,
}
"""The peers RgbdCameraReader makes from its ``backend`` attribute."""

__all__ = ["BACKENDS", "BagRgbdPeer", "PRIMESENSE", "RealSenseRgbdPeer", "RedwoodRgbdPeer", "RgbdPeer",
           "TumRgbdPeer", "associate"]
