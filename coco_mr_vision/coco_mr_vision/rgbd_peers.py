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

from pathlib import Path

import numpy as np

from coco_core.attributes import Attribute, FileAttribute
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
    intrinsics = FileAttribute("", "JSON intrinsics (empty: PrimeSense defaults, as Open3D uses for TUM)",
                               expected="a JSON file of camera intrinsics")
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
        with self.reading_attribute_file("intrinsics"):
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
    intrinsics = FileAttribute("", "JSON intrinsics (empty: the folder's *.json, else PrimeSense defaults)",
                               expected="a JSON file of camera intrinsics")
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
        with self.reading_attribute_file("intrinsics"):
            intrinsics = _intrinsics_file(intrinsics_path, PRIMESENSE, self.frame_id)
        return pairs, intrinsics, self.depth_scale


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


BACKENDS: dict[str, str] = {
    "tum": "TumRgbdPeer", "redwood": "RedwoodRgbdPeer", "bag": "BagRgbdPeer", "realsense": "RealSenseRgbdPeer",
    "topic": "TopicRgbdPeer",
}
"""The peers RgbdCameraReader makes from its ``backend`` attribute, by registered component name:
the bag and topic peers are coco_ros's (:mod:`coco_ros.vision.rgbd_bag`,
:mod:`coco_ros.vision.rgbd_topics`), which depends on this package, not the other way round."""

__all__ = ["BACKENDS", "PRIMESENSE", "RealSenseRgbdPeer", "RedwoodRgbdPeer", "RgbdPeer",
           "TumRgbdPeer", "associate"]
