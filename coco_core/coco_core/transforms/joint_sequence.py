"""JointSequence: a robot stepped through a list of joint poses, as a joint-state source.

Calibration and registration move a robot through poses and hold each while something measures
(the paper's Fig. 2: the arm shows a marker to a camera from several poses). Where the robot is a
model in the graph and not a machine, this component is its controller and its ``joint_states``
publisher at once: every update writes the current pose (a real robot publishes its joint states
continuously, whether it moves or not), and the pose changes every ``hold`` seconds. At the end it
keeps the last pose, or stops the application (``stop_at_end``).

What measures a pose may lag behind the wall clock: a software-rendered camera on a loaded machine
takes one frame where a quiet one takes five, and a pose held a fixed time then gives it too few
frames to see the arm at rest. With ``frames`` and the ``seen`` input connected to what the
measurement produces (a marker tracker's detections, one per processed image), a pose is held
``hold`` seconds *and* until ``frames`` values arrived on ``seen`` since it began, so the sequence
paces itself by the measurement instead of by the clock.

The poses are a CSV file: a header of joint names, one pose per row (radians or metres), ``#``
comments. A joint the rows do not name keeps its value in the graph.
"""

from __future__ import annotations

import csv
import math
import time
from pathlib import Path

import numpy as np

from ..attributes import Attribute, FileAttribute
from ..component import Component
from ..errors import ConfigError, Location
from ..files import DATA_FILE_LIMIT, read_regular_file
from ..ports import InputPort, OutputPort
from .samples import JointSample

def read_poses(path: Path) -> tuple[tuple[str, ...], np.ndarray]:
    """(joint names, one row of values per pose) of a poses CSV; errors name the file and line."""
    text = read_regular_file(path, DATA_FILE_LIMIT, "poses file").decode("utf-8")
    rows = [(number, row) for number, row in enumerate(csv.reader(text.splitlines()), start=1)
            if row and not row[0].lstrip().startswith("#")]
    if not rows:
        raise ConfigError("a poses file needs a header of joint names and at least one pose", Location(str(path), 1))
    header_line, header = rows[0]
    names = tuple(name.strip() for name in header)
    if not all(names) or len(set(names)) != len(names):
        raise ConfigError(f"the header must name each joint once, got {', '.join(names)}",
                          Location(str(path), header_line))
    poses = []
    for number, row in rows[1:]:
        try:
            values = [float(value) for value in row]
        except ValueError:
            values = []
        if len(values) != len(names) or not all(math.isfinite(value) for value in values):
            raise ConfigError(f"expected {len(names)} finite numbers ({', '.join(names)}), got {', '.join(row)}",
                              Location(str(path), number))
        poses.append(values)
    if not poses:
        raise ConfigError("the poses file has a header but no pose", Location(str(path), header_line))
    return names, np.array(poses, dtype=float)


class JointSequence(Component):
    """Writes each pose of a CSV file for ``hold`` seconds, every update (see the module)."""

    poses = FileAttribute("", "CSV file: a header of joint names, one pose per row",
                          expected="a CSV file: a header of joint names, one pose per row")
    hold = Attribute(float, 1.0, "seconds each pose is held", min=1e-3)
    stop_at_end = Attribute(bool, False, "request the application stop once the last pose was held")
    frames = Attribute(int, 0, "values that must arrive on `seen` during each pose before the next (0: the clock "
                       "alone)", min=0)

    joints = OutputPort(JointSample, "the current pose, every update (stamped with the wall clock)")
    seen = InputPort(object, doc="what measures the poses (e.g. marker detections): counted against `frames`")

    def init(self) -> None:
        if not self.poses:
            raise ConfigError(f"component {self.name}: the poses attribute is empty; give a CSV file of poses")
        with self.reading_attribute_file("poses"):
            self.names, self.values = read_poses(Path(self.poses))
        self.pose = 0
        """Index of the pose being held."""
        self._since: float | None = None
        """When the pose being held began (None before the first update)."""
        self._seen = 0
        """Values read on ``seen`` since then."""

    def on_update(self) -> None:
        now = time.time()
        self._seen += len(self.seen.read_all())
        if self._since is None:
            self._since = now
        elif now - self._since >= self.hold and self._seen >= self.frames and self.pose < len(self.values):
            self.pose += 1
            self._since, self._seen = now, 0
        if self.pose >= len(self.values):
            if self.stop_at_end and self.app is not None:
                self.app.request_stop(f"{self.name}: the last of {len(self.values)} poses was held")
                return
            self.pose = len(self.values) - 1  # kept from now on
        self.joints.write(JointSample(self.names, self.values[self.pose].copy(), now))
