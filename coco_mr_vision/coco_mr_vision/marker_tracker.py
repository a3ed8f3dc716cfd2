"""MarkerTracker: square fiducial markers (ArUco, AprilTag families of ``cv2.aruco``) and their poses.

Each image is searched with ``cv2.aruco.ArucoDetector`` in the chosen predefined dictionary, corners
refined to sub-pixel accuracy, and each marker's pose found by ``solvePnP`` with the square-marker
method (IPPE_SQUARE) from the image's own intrinsics and distortion. The poses are written on a port
and, when ``publish`` is on, into the transformation graph as dynamic edges ``camera -> marker``
stamped with the image's acquisition time, so that any lookup through a marker (a registration's
temporary path, a hand-held tool) follows it.

Marker frame convention (OpenCV's): origin at the marker's centre, x to the right, y up, z out of the
marker towards the camera; corners in the order top-left, top-right, bottom-right, bottom-left.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import UnknownNameError, did_you_mean
from coco_core.ports import InputPort, OutputPort
from coco_core.stamps import Stamped, unstamped

from .image import CameraIntrinsics, Image, ImageFormat
from .rgbd import RGBDFrame
from coco_core.wire import value_type

log = logging.getLogger("coco.vision")

DICTIONARIES = sorted(name for name in dir(cv2.aruco) if name.startswith("DICT_"))
"""The predefined dictionaries of this OpenCV, by their OpenCV names."""


def _check_dictionary(name: str) -> str | None:
    if name not in DICTIONARIES:
        return f"unknown marker dictionary {name!r}; {did_you_mean(name, DICTIONARIES)}"
    return None


@value_type
@dataclass(frozen=True, eq=False)
class MarkerDetections:
    """The markers found in one image: ``ids`` (N), ``corners`` (Nx4x2 px), ``poses`` (Nx4x4
    ``T_camera_marker``, NaN when the image had no intrinsics), with the image's stamp and frame."""

    ids: np.ndarray
    corners: np.ndarray
    poses: np.ndarray
    stamp: float | None
    frame_id: str

    def pose(self, marker_id: int) -> np.ndarray:
        """``T_camera_marker`` of one marker id (the first if it was seen twice)."""
        found = np.flatnonzero(self.ids == marker_id)
        if not found.size:
            raise UnknownNameError(f"marker {marker_id} was not detected; detected: {self.ids.tolist()}")
        return self.poses[found[0]]


def square_points(length: float) -> np.ndarray:
    """The corners of a square marker of side ``length`` in its own frame, in ArUco's order."""
    h = length / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def marker_pose(corners: np.ndarray, length: float, intrinsics: CameraIntrinsics) -> np.ndarray:
    """``T_camera_marker`` from the 4 image corners of a square marker of side ``length``."""
    ok, rvec, tvec = cv2.solvePnP(square_points(length), corners.reshape(4, 1, 2).astype(np.float64),
                                  intrinsics.K, intrinsics.D, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    if not ok:
        return np.full((4, 4), np.nan)
    pose = np.eye(4)
    pose[:3, :3] = cv2.Rodrigues(rvec)[0]
    pose[:3, 3] = tvec.ravel()
    return pose


class MarkerTracker(Component):
    """Detects markers in each image, estimates their poses, and publishes them into the graph."""

    dictionary = Attribute(str, "DICT_5X5_1000", "cv2.aruco predefined dictionary", check=_check_dictionary)
    marker_length = Attribute(float, 0.1, "side of the markers' black square, in metres", min=1e-6)
    ids: Attribute[list[int]] = Attribute(list[int], [], "marker ids to report (empty: every id)")
    subpixel = Attribute(bool, True, "refine corners to sub-pixel accuracy (cornerSubPix)")
    publish = Attribute(bool, True, "write each pose into the transformation graph as camera -> marker")
    camera_frame = Attribute(str, "", "camera frame of the published edges (empty: the image's frame_id, "
                             "else 'camera')")
    marker_frame = Attribute(str, "marker_{id}", "name of a marker's frame; {id} is replaced by its id")

    image = InputPort(Image | RGBDFrame | Stamped, event=True, doc="camera images (any colour format), with "
                      "intrinsics, or RGB-D frames (their colour image and intrinsics: a streamed RGB-D camera)")
    camera_info = InputPort(CameraIntrinsics, doc="the camera's intrinsics, for images that carry none (a ROS "
                            "Image topic with its camera_info topic beside it); the newest is used")
    markers = OutputPort(Stamped, "Stamped(MarkerDetections), with the image's stamp when it had one")

    def init(self) -> None:
        self.frames = 0
        self.detected = 0
        self.without_intrinsics = 0
        """Images whose markers got no pose because the image carried no intrinsics."""

    def on_config(self) -> None:
        parameters = cv2.aruco.DetectorParameters()
        if self.subpixel:
            parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        self._detector = cv2.aruco.ArucoDetector(dictionary, parameters)

    def detect(self, image: Image) -> MarkerDetections:
        """The markers of one image (also usable without running the component)."""
        grey = image.to(ImageFormat.GRAY8).data
        corners, found, _ = self._detector.detectMarkers(grey)
        ids = np.array([], int) if found is None else found.ravel().astype(int)
        stack = np.array(corners, dtype=np.float64).reshape(-1, 4, 2)
        if self.ids and ids.size:
            keep = np.isin(ids, self.ids)
            ids, stack = ids[keep], stack[keep]
        if image.intrinsics is None:
            poses = np.full((ids.size, 4, 4), np.nan)
            if ids.size:
                self.without_intrinsics += 1
        else:
            poses = np.array([marker_pose(c, self.marker_length, image.intrinsics) for c in stack]).reshape(-1, 4, 4)
        return MarkerDetections(ids, stack, poses, image.stamp, image.frame_id)

    def on_update(self) -> None:
        status, info = self.camera_info.read_newest()
        for value in self.image.read_all():
            image, stamp = unstamped(value)
            if isinstance(image, RGBDFrame):
                color = image.color
                image = Image(color.data, color.format, color.stamp, color.frame_id, image.intrinsics)
            if image.intrinsics is None and status:
                image = Image(image.data, image.format, image.stamp, image.frame_id, info)
            detections = self.detect(image)
            self.frames += 1
            self.detected += detections.ids.size
            if self.publish and detections.ids.size and image.intrinsics is not None:
                camera = self.camera_frame or image.frame_id or "camera"
                graph = self.transform_graph
                for marker_id, pose in zip(detections.ids, detections.poses):
                    if np.isfinite(pose).all():
                        graph.set_transform(camera, self.marker_frame.format(id=int(marker_id)), pose,
                                            stamp=image.stamp)
            self.markers.write(Stamped(detections, stamp) if stamp is not None else Stamped(detections))
