"""MarkerRegistration: a camera registered to a robot from a marker the robot holds (paper, Fig. 2).

The camera's pose relative to the robot is unknown; a marker is fixed on the robot's gripper at a
known place (a static edge ``gripper -> marker`` in the graph). While the registration runs, the
MarkerTracker's ``camera -> marker`` edge is the temporary path that joins the camera to the robot:
each sample of ``T_parent_camera`` is the chain ``parent -> ... -> gripper -> marker <- camera``
(:class:`~coco_core.transforms.registration.Registration`). When enough samples are in, their robust
mean is installed as the static edge ``parent -> camera``, the temporary edge goes, the result is
logged (and written as JSON), and the application may stop.

A sample combines the tracker's measurement with the joint values of the moment it is taken, so it
is taken only while the arm is at rest, and once per rest: when ``still_frames`` consecutive
detections of the marker agree within ``still_translation`` and ``still_rotation`` (the camera is
fixed, so a marker still in the image is an arm at rest), and so does the marker's pose through the
kinematic chain, read from the graph at each of them; not again until the marker moved. The second
test matters when the images lag behind the joint states (a loaded machine): three images of the
old pose processed after the graph took the new one agree with each other but not with the graph.
With the newest image only on the camera's connections (DATA), an image is never older than the
detection before it, so when both agree over three detections they show the same rest.
Nothing here depends on where the images come from: a camera, a bag, or a SimulatedCamera.

With ``truth`` (a frame of the graph at the camera's true pose, known in a simulation), the result
is also compared with it: the error is logged, written, and is what the registration's goal is
measured on.
"""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path
from typing import Any

import numpy as np

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.ports import InputPort
from coco_core.stamps import Stamped, unstamped
from coco_core.transforms.averaging import transform_residuals
from coco_core.transforms.registration import Registration, RegistrationResult

from .marker_tracker import MarkerDetections

log = logging.getLogger("coco.vision")


class MarkerRegistration(Component):
    """Samples the marker path while the arm is at rest, installs ``parent -> camera`` (see the module)."""

    parent = Attribute(str, "base", "the robot's frame the camera is registered to")
    camera = Attribute(str, "camera", "the camera's frame (MarkerTracker's camera_frame)")
    marker_id = Attribute(int, 0, "id of the marker on the robot", min=0)
    marker_frame = Attribute(str, "marker_{id}", "its frame (MarkerTracker's marker_frame); {id} is replaced")
    samples = Attribute(int, 8, "samples (arm rests) before the result is installed", min=3)
    still_frames = Attribute(int, 3, "consecutive detections that must agree for the arm to be at rest", min=2)
    still_translation = Attribute(float, 0.001, "metres two detections of a still marker may differ by", min=0.0)
    still_rotation = Attribute(float, 0.3, "degrees two detections of a still marker may differ by", min=0.0)
    truth = Attribute(str, "", "frame at the camera's true pose, to report the error against (empty: none)")
    output = Attribute(Path, Path(""), "JSON file of the result (empty: none)")
    stop_when_done = Attribute(bool, True, "request the application stop once the result is installed")

    markers = InputPort(Stamped, event=True, doc="Stamped(MarkerDetections) of the camera (MarkerTracker.markers)")

    def init(self) -> None:
        self.result: RegistrationResult | None = None
        self.error: tuple[float, float] | None = None
        """(metres, radians) between the installed pose and ``truth``, when there is a truth."""
        self._registration: Registration | None = None
        self._last: tuple[np.ndarray, np.ndarray] | None = None
        """The last detection's marker pose in the camera and, through the kinematic chain, in ``parent``."""
        self._still = 0
        self._armed = True

    def on_config(self) -> None:
        self._marker = self.marker_frame.format(id=self.marker_id)
        self._registration = Registration(self.transform_graph, self.parent, self.camera,
                                          via=(self.camera, self._marker))

    def on_update(self) -> None:
        for value in self.markers.read_all():
            detections, _ = unstamped(value)
            self._detected(detections)

    def _detected(self, detections: MarkerDetections) -> None:
        registration = self._registration
        if registration is None or self.result is not None:
            return
        found = np.flatnonzero(detections.ids == self.marker_id)
        pose = detections.poses[found[0]] if found.size else None
        if pose is None or not np.isfinite(pose).all():
            self._last, self._still = None, 0  # out of sight: a rest counts from the next sighting
            return
        arm = self.transform_graph.lookup(self.parent, self._marker)  # through the kinematic chain
        if self._last is not None and self._agrees(self._last[0], pose) and self._agrees(self._last[1], arm):
            self._still += 1
        else:
            self._still, self._armed = 1, True  # moved (or first seen): the next rest gives a sample
        self._last = (pose, arm)
        if self._armed and self._still >= self.still_frames and registration.sample() == 1:
            self._armed = False
            log.info("%s: sample %d of %d", self.name, registration.sample_count, self.samples)
            if registration.sample_count >= self.samples:
                self._install()
                if self.stop_when_done and self.app is not None:
                    self.app.request_stop(f"{self.name}: {self.parent} -> {self.camera} registered")

    def _agrees(self, a: np.ndarray, b: np.ndarray) -> bool:
        translation, rotation = transform_residuals(a, b[None])
        return bool(translation[0] <= self.still_translation and math.degrees(rotation[0]) <= self.still_rotation)

    def on_stop(self) -> None:
        """An application stopped before enough rests (a bag that ended, a duration) installs what it
        has, when that is enough for a robust mean; otherwise it says how many samples it got, and the
        application's outcome is a failure."""
        registration = self._registration
        if registration is None or self.result is not None:
            return
        if registration.sample_count >= registration.min_samples:
            self._install()
        else:  # the input could not give a registration: the launcher exits non-zero (Application.damage)
            message = (f"{self.name}: {registration.sample_count} sample(s) of {self.parent} -> {self.camera} when "
                       f"the application stopped, {registration.min_samples} needed: nothing registered (was "
                       f"marker {self.marker_id} in sight, and did the arm rest?)")
            log.error("%s", message)
            if self.app is not None:
                self.app.report_damage(message)
            registration.cancel()

    def _install(self) -> None:
        assert self._registration is not None
        result = self.result = self._registration.install()
        found = result.transform  # T_parent_camera, the static edge just installed
        report: dict[str, Any] = result.describe()
        message = f"{self.name}: registered {result.summary()}"
        if self.truth:
            truth = self.transform_graph.lookup(self.parent, self.truth)
            translation, rotation = transform_residuals(truth, found[None])
            self.error = (float(translation[0]), float(rotation[0]))
            report.update(truth=truth.tolist(), error_m=self.error[0], error_deg=math.degrees(self.error[1]))
            message += (f"; error against {self.truth}: {self.error[0] * 1000:.2f} mm, "
                        f"{math.degrees(self.error[1]):.3f} deg")
        log.info("%s\n%s -> %s:\n%s", message, self.parent, self.camera, np.array2string(found, precision=4))
        if str(self.output) not in ("", "."):
            self.output.parent.mkdir(parents=True, exist_ok=True)
            self.output.write_text(json.dumps(report, indent=2) + "\n")
