"""``EndEffectorDistance``: the paper's *UpdateColorCalc* — end-effector to bowl distance and its colour.

Inputs (event ports, a triggered activity runs the component whenever either changes), each a
:class:`FramePose` or a ``Stamped(FramePose)`` (a ``TransformationInterface`` with ``stamped``):

- ``gripper``: ``T_base_gripper`` (e.g. the lookup ``gripper=base:left_gripper``);
- ``bowl``: ``T_base_bowl`` (e.g. the lookup ``bowl=base:bowl`` of ``/bowl/pose`` in the graph).
  Both must be expressed in the same frame (their ``target``); a mismatch is logged once.

Every sample (the paper's "for every change"): each input pose read is one change, taken in order
of emission (the ports are drained, the values of both merged by their stamps' ``time``), and each
change that alters a pose gives one sample once both poses are known. A pose equal to the one it
replaces (e.g. a joint state that moved only the other arm) changes nothing and gives no sample. A
pose that a newer one replaces before any sample showed it (gripper poses before the first bowl
pose: only the last of them reaches the first sample) is counted as *merged* in the profile
(:meth:`~coco_core.component.Component.record_merged`), as is a change no sample showed by the stop,
so that the CSV's rows and the poses read always add up. The
connections into this component must therefore keep every pose (BUFFER, sized for the backlog a
fast replay builds up); with a DATA or CIRCULAR connection the poses it discards are counted as
dropped in the profile, never silently lost.

Outputs, written once per sample, all with the same :class:`Stamp`:

- ``distance``: ``Stamped[float]``, the Euclidean distance between the two frame origins (m);
- ``color``: ``Stamped[tuple[float, float, float]]``, RGB in 0..1 (see :func:`distance_color`);
- ``bag_time``: ``Stamped[float]``, the ROS time (s since the epoch) of the newest pose stamp the
  outputs were computed from (``nan`` when no pose carries one).

UpdateColorCalc mapping (:func:`distance_color`): green ``(0, 1, 0)`` at ``near`` m or closer, red
``(1, 0, 0)`` at ``far`` m or farther, through yellow ``(1, 1, 0)`` half-way; with
``s = (d - near) / (far - near)``: ``r = min(1, 2 s)``, ``g = min(1, 2 (1 - s))``, ``b = 0``.

Latency (``record_latency``, reported by ``--profile``): the outputs' stamp keeps the ``time`` (and
``source``) of the oldest :class:`Stamp` among the input poses the sample is the first to show (the
pose that made it, or an earlier one that waited for the other pose), so the interval measured runs **from the emission of that input upstream** (e.g. ``BagReplay`` with ``stamped``: the
joint state or bowl pose leaving the replay, through the graph) **to the outputs written here**; its
``seq`` counts this component's samples. A plain (unstamped) input counts from its message stamp:
its write on the port that fed this one (:attr:`InputPort.origin <coco_core.ports.InputPort.origin>`,
whose source is that port); only a value pushed without a port counts from the moment it is read
here. The stamp travels with the outputs, so ``TeleopSummary`` measures *emission -> CSV row* with it.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from coco_core.attributes import Attribute
from coco_core.colors import green_yellow_red
from coco_core.component import Component
from coco_core.errors import SetupError
from coco_core.ports import InputPort, OutputPort
from coco_core.stamps import Stamp, Stamped, unstamped
from coco_core.transforms.samples import FramePose

log = logging.getLogger("coco.teleop")



def distance_color(distance: float, near: float = 0.02, far: float = 0.5) -> tuple[float, float, float]:
    """The UpdateColorCalc colour of a distance: green at ``<= near``, red at ``>= far``, yellow
    half-way, linear in between (see the module docstring)."""
    if not far > near:
        raise SetupError(f"far ({far}) must be greater than near ({near})")
    return green_yellow_red((distance - near) / (far - near))


def frame_distance(a: FramePose, b: FramePose) -> float:
    """Distance between the origins of two poses expressed in the same frame (``math.dist`` on the
    two translations as floats: a fifth of ``np.linalg.norm`` on their difference, once per sample)."""
    return math.dist(np.asarray(a.transform)[:3, 3].tolist(), np.asarray(b.transform)[:3, 3].tolist())


def _check_far(value: float) -> str | None:
    return None if value > 0 else "far must be positive"


class EndEffectorDistance(Component):
    """UpdateColorCalc: gripper-to-bowl distance and its colour; see the module docstring."""

    near = Attribute(float, 0.02, "distance (m) at or below which the colour is green", min=0.0, live=True)
    far = Attribute(float, 0.5, "distance (m) at or above which the colour is red", check=_check_far,
                    live=True)

    gripper = InputPort(FramePose | Stamped, event=True, doc="T_base_gripper, optionally Stamped")
    bowl = InputPort(FramePose | Stamped, event=True, doc="T_base_bowl, optionally Stamped")

    distance = OutputPort(Stamped, "end-effector to bowl distance (m)")
    color = OutputPort(Stamped, "UpdateColorCalc RGB colour (0..1) of the distance")
    bag_time = OutputPort(Stamped, "ROS time (s) of the newest input the outputs were computed from")

    def init(self) -> None:
        self._gripper: FramePose | None = None
        self._bowl: FramePose | None = None
        self._seq = 0
        self._unshown: Stamp | None = None
        """The oldest origin among the changes no sample has shown yet (a gripper pose before the first bowl pose)."""
        self._unshown_poses: set[str] = set()
        """The inputs (``_gripper``, ``_bowl``) whose current pose no sample has shown yet."""
        self._warned = False
        self.last_distance = math.nan

    def on_config(self) -> None:
        if not self.far > self.near:
            raise SetupError(f"component {self.name}: far ({self.far}) must be greater than near ({self.near})")

    def on_update(self) -> None:
        read = Stamp.now()
        changes: list[tuple[Stamp, str, FramePose]] = []
        for port, attr in ((self.gripper, "_gripper"), (self.bowl, "_bowl")):
            for value, origin in port.read_all_origins():
                changes.append((origin or read, attr, unstamped(value)[0]))
        changes.sort(key=lambda change: change[0].time)  # stable: each port's own order is kept
        for origin, attr, pose in changes:
            previous = getattr(self, attr)
            setattr(self, attr, pose)
            if previous is not None and np.array_equal(previous.transform, pose.transform):
                continue
            if self._unshown is None or origin.time < self._unshown.time:
                self._unshown = origin
            if attr in self._unshown_poses:  # the pose it replaces was never shown
                self.record_merged()
            self._unshown_poses.add(attr)
            self._sample()

    def on_stop(self) -> None:
        if self._unshown_poses:  # changes no sample showed: the other pose never came
            self.record_merged(len(self._unshown_poses))
            self._unshown_poses.clear()

    def _sample(self) -> None:
        """One sample from the current poses, stamped with the oldest change it is the first to show."""
        gripper, bowl, origin = self._gripper, self._bowl, self._unshown
        if gripper is None or bowl is None or origin is None:
            return
        self._unshown = None
        self._unshown_poses.clear()
        if gripper.target != bowl.target and not self._warned:
            self._warned = True
            log.warning("component %s: gripper pose is in %r but bowl pose in %r; the distance assumes one frame",
                        self.name, gripper.target, bowl.target)
        self._seq += 1
        stamp = Stamp(origin.time, self._seq, origin.source or self.name)
        distance = frame_distance(gripper, bowl)
        self.last_distance = distance
        times = [t for t in (gripper.stamp, bowl.stamp) if t is not None]
        self.distance.write(Stamped(distance, stamp))
        self.color.write(Stamped(distance_color(distance, self.near, self.far), stamp))
        self.bag_time.write(Stamped(max(times) if times else math.nan, stamp))
        self.record_latency(stamp)
