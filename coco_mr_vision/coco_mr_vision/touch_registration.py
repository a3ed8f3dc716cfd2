"""TouchRegistration: a hand tracker registered to a remote camera by a touch on a marker (paper, 6.1).

In the remote palpation application, the remote scene (a camera's frame) and the user's hand (a
tracker's frame) have no common reference. The paper's calibration: a marker stuck on the body is
seen by the camera, and the user holds the hand still on the marker, aligned with it; while the hand
rests, each detection of the marker gives one sample of the camera -> tracker transform,
``T_camera_tracker = T_camera_marker @ inverse(T_tracker_hand)``, with the hand's pose of the
detection's instant (the nearest by stamp). When ``samples`` are in, their robust mean
(:class:`~coco_core.transforms.registration.Registration`) is installed as the static edge
``camera -> tracker``, so that every hand, device and proxy pose flows through the graph from then on.

The *residual* reported is what a user would check: over the samples, the distance between the
marker's centre and the hand's touch point mapped into the camera by the installed transform (RMS,
metres); it is written on ``residual`` and in the JSON ``output``, with ``stamp``: the time (the
detections' time base, a recording's) of the newest detection sampled. An application that stops
before the touch installs nothing and records it as damaged input (the launcher exits 1).
"""

from __future__ import annotations

import json
import logging
import math
from collections import deque
from pathlib import Path

import numpy as np

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import GeometryError
from coco_core.ports import InputPort, OutputPort
from coco_core.stamps import Stamped, unstamped
from coco_core.transforms import se3
from coco_core.transforms.registration import Registration
from coco_core.transforms.samples import FramePose

from .marker_tracker import MarkerDetections

log = logging.getLogger("coco.vision")

HISTORY = 4.0
"""Seconds of hand poses kept to match detections with."""


class TouchRegistration(Component):
    """Installs ``camera -> tracker`` from a hand held still on a marker (see the module)."""

    camera = Attribute(str, "camera", "the camera's frame (the marker detections')")
    tracker = Attribute(str, "hand_tracker", "the hand tracker's frame (the hand poses' parent)")
    marker_id = Attribute(int, 0, "id of the marker the hand touches", min=0)
    still_time = Attribute(float, 0.4, "s the hand must have rested before a detection counts", min=0.0)
    still_translation = Attribute(float, 0.002, "m the hand may wander while resting", min=0.0)
    samples = Attribute(int, 10, "detections during the rest before the result is installed", min=3)
    output = Attribute(Path, Path(""), "JSON file of the result (empty: none)")

    markers = InputPort(Stamped | MarkerDetections, event=True, doc="MarkerTracker.markers")
    hand = InputPort(Stamped | FramePose, event=True, doc="hand poses in the tracker's frame (T_tracker_hand), "
                     "stamped on the detections' time base")
    residual = OutputPort(float, "RMS distance (m) between the marker and the touch mapped by the result")

    def init(self) -> None:
        self.installed: np.ndarray | None = None
        """T_camera_tracker once installed."""
        self.rms = math.nan
        self._hands: deque[tuple[float, np.ndarray]] = deque()
        self._pending: list[MarkerDetections] = []
        self._pairs: list[tuple[np.ndarray, np.ndarray]] = []
        """(T_camera_marker, T_tracker_hand) of each sample."""
        self.installed_stamp: float | None = None
        """The stamp of the newest sample's detection (the detections' time base: a recording's
        time); once installed, when the samples were complete."""

    def on_update(self) -> None:
        for value in self.hand.read_all():
            pose, _ = unstamped(value)
            if pose.stamp is None:
                continue  # a pose without its time cannot be matched
            if not np.isfinite(pose.transform).all():  # no rest, and a NaN in the mean would spoil it
                self.record_refusal("a hand pose", GeometryError(f"non-finite hand pose at {pose.stamp}"))
                continue
            self._hands.append((float(pose.stamp), np.asarray(pose.transform, float)))
        while self._hands and self._hands[0][0] < self._hands[-1][0] - HISTORY:
            self._hands.popleft()
        for value in self.markers.read_all():
            detections, _ = unstamped(value)
            if detections.stamp is not None and self.marker_id in detections.ids.tolist():
                self._pending.append(detections)
        if self.installed is None:
            self._match()

    def _match(self) -> None:
        """Pair each pending detection with the resting hand of its instant, once the hand poses
        cover that instant."""
        if not self._hands:
            return
        newest = self._hands[-1][0]
        waiting = []
        for detections in self._pending:
            stamp = float(detections.stamp)  # type: ignore[arg-type]  # kept only with a stamp
            if stamp > newest:
                waiting.append(detections)
                continue
            hand = self._resting_hand(stamp)
            marker = detections.pose(self.marker_id)
            if hand is not None and np.isfinite(marker).all():
                self._pairs.append((marker, hand))
                self.installed_stamp = stamp  # the newest sample's, kept once installed
        self._pending = waiting
        if len(self._pairs) >= self.samples:
            self._install()

    def _resting_hand(self, stamp: float) -> np.ndarray | None:
        """The hand's pose nearest ``stamp`` if it rested over the ``still_time`` before it."""
        window = [pose for when, pose in self._hands if stamp - self.still_time <= when <= stamp + 0.02]
        if not window or self._hands[0][0] > stamp - self.still_time:
            return None
        points = np.array([pose[:3, 3] for pose in window])
        if np.linalg.norm(points - points.mean(axis=0), axis=1).max() > self.still_translation:
            return None
        return min(((abs(when - stamp), pose) for when, pose in self._hands), key=lambda item: item[0])[1]

    def _install(self) -> None:
        registration = Registration(self.transform_graph, self.camera, self.tracker)
        for marker, hand in self._pairs:
            registration.add_sample(marker @ se3.inverse(hand), label="touch")
        result = registration.install()
        found = self.installed = result.transform
        errors = [np.linalg.norm((found @ hand)[:3, 3] - marker[:3, 3]) for marker, hand in self._pairs]
        self.rms = float(math.sqrt(np.mean(np.square(errors))))
        self.residual.write(self.rms)
        log.info("%s: %s -> %s registered from %d detections of marker %d during the touch: residual %.2f mm "
                 "RMS\n%s", self.name, self.camera, self.tracker, len(self._pairs), self.marker_id, 1e3 * self.rms,
                 np.array2string(found, precision=4))
        if str(self.output) not in ("", "."):
            report = result.describe()
            report.update(residual_m=self.rms, samples=len(self._pairs), marker_id=self.marker_id,
                          stamp=self.installed_stamp)
            self.output.parent.mkdir(parents=True, exist_ok=True)
            self.output.write_text(json.dumps(report, indent=2) + "\n")

    def on_stop(self) -> None:
        if self.installed is not None:
            return
        message = (f"{self.name}: {len(self._pairs)} of {self.samples} samples of {self.camera} -> {self.tracker} "
                   f"when the application stopped: nothing registered (was marker {self.marker_id} in sight "
                   "while the hand rested on it?)")
        log.error("%s", message)
        if self.app is not None:
            self.app.report_damage(message)
