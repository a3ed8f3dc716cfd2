"""TransformationInterface: the component that connects the transformation graph to the data flow.

Transforms and joint states arriving on its ports update the application's graph (a URDF robot is
updated in bulk through Pinocchio); chosen lookups are published on output ports whenever an edge on
their path changes; other components may also call its ``lookup`` operation from any activity.

Each published :class:`FramePose` carries, as ``stamp``, the graph-time stamp (e.g. ROS time) of the
input sample that changed it (None when the change did not come through this component's ports).
Inputs may be :class:`~coco_core.stamps.Stamped` (e.g. a ``BagReplay`` with ``stamped``); each
input's origin (:attr:`InputPort.origin <coco_core.ports.InputPort.origin>`: a ``Stamped`` value's
own stamp, a plain value's message stamp, its write) is kept on what it changed in the graph (the
display's latency-to-pixel reads it there), and with ``stamped`` the lookups are published as
``Stamped(FramePose, stamp)`` carrying the origin of the input that caused them, so a consumer's
``record_latency`` measures from that input's origin, through the graph. With ``wait_for_joints``, a lookup through a URDF robot is not published before the robot's
first joint state (its zero-joint pose is no data), as robot_state_publisher; static lookups are.
"""

from __future__ import annotations

import logging
from functools import partial

import numpy as np

from ..attributes import Attribute
from ..component import Component
from ..errors import AttributeValueError
from ..operations import current_activity, operation
from ..ports import InputPort, OutputPort
from ..stamps import Stamp, Stamped, unstamped
from .graph import KinematicModel, Query, TransformGraph
from .samples import FramePose, JointSample, TransformSample

log = logging.getLogger("coco.transforms")


def parse_output(spec: str) -> tuple[str, str, str]:
    """``"port=target:source"`` -> (port, target, source)."""
    port, equals, pair = spec.partition("=")
    target, colon, source = pair.partition(":")
    if not (equals and colon and port.strip() and target.strip() and source.strip()):
        raise AttributeValueError(f"output {spec!r} must look like port=target:source (e.g. gripper=base:left_gripper)")
    return port.strip(), target.strip(), source.strip()


def _check_outputs(specs: list[str]) -> str | None:
    for spec in specs:
        try:
            parse_output(spec)
        except ValueError as error:
            return str(error)
    return None


class TransformationInterface(Component):
    """Feeds the transformation graph from ports and publishes lookups on ports."""

    urdf = Attribute(str, "", "URDF file or package:// URL to load into the graph; empty for none")
    prefix = Attribute(str, "", "prefix added to the URDF's frame names (several robots in one graph)")
    publish: Attribute[list[str]] = Attribute(list[str], [], "lookups to publish on output ports, each 'port=target:source' "
                        "(T_target_source)", check=_check_outputs)
    stamped = Attribute(bool, False, "publish Stamped(FramePose) with the stamp of the input that caused "
                        "the change (end-to-end latency), instead of plain FramePose")
    wait_for_joints = Attribute(bool, False, "publish no lookup through a URDF robot before its first joint "
                                "state (not its zero-joint pose)")

    transform = InputPort(object, event=True, doc="TransformSample or FramePose (target=parent, source=child), "
                          "or a list of them, to write into the graph; optionally Stamped")
    joints = InputPort(JointSample | Stamped, event=True, doc="joint values applied to axis edges and URDF "
                       "models; optionally Stamped")

    def init(self) -> None:
        if self.urdf:
            from .urdf import load_urdf

            self.model = load_urdf(self.transform_graph, self.urdf, prefix=self.prefix)
        self._lookups: list[tuple[OutputPort, Query]] = []
        self._published: set[OutputPort] = set()
        self._cause: tuple[Stamp | None, float | None] = (None, None)
        """(stamp, graph time) of the input being applied, for the lookups its change publishes."""
        for spec in self.publish:
            port_name, target, source = parse_output(spec)
            port = self.add_output(port_name, Stamped if self.stamped else FramePose, f"T_{target}_{source}")
            query = self.transform_graph.query(target, source)
            # The path may not exist yet: the callback runs once it does, whoever completes it.
            query.on_change(partial(self._publish, port, query))
            self._lookups.append((port, query))

    def on_config(self) -> None:
        """Publish what is already known, so readers start with the current poses (unless the path
        was completed before the start, in which case its callback published it already)."""
        for port, query in self._lookups:
            if port in self._published:
                continue
            try:
                self._publish(port, query, query.current())
            except LookupError:  # no path or no sample yet: the callback publishes it when there is
                pass

    def on_update(self) -> None:
        try:
            self._apply_inputs()
        finally:
            self._cause = (None, None)

    def _apply_inputs(self) -> None:
        """Apply every sample read in this cycle; a malformed one (non-finite values or stamp, a
        matrix that is not a rigid transform, positions that do not match the names) is refused and
        counted (:meth:`record_refusal`), and the samples after it are still applied."""
        graph = self.transform_graph
        for item, origin in self.transform.read_all_origins():
            item = unstamped(item)[0]
            for sample in item if isinstance(item, (list, tuple)) else (item,):
                self._cause = (origin, sample.stamp)
                try:
                    self._apply_transform(graph, sample, origin)
                except (ValueError, LookupError) as error:
                    self.record_refusal(f"a transform sample on port {self.transform.name}", error)
        for joints, origin in self.joints.read_all_origins():
            joints = unstamped(joints)[0]
            self._cause = (origin, joints.stamp)
            try:  # the positions stay an array down to the kinematic models
                graph.set_joint_array(joints.names, joints.positions, origin)
            except (ValueError, LookupError) as error:
                self.record_refusal(f"a joint sample on port {self.joints.name}", error)

    def _apply_transform(self, graph: TransformGraph, sample: TransformSample | FramePose, origin: Stamp | None) -> None:
        if isinstance(sample, FramePose):  # T_target_source: target is the parent, source the child
            if not sample.source:
                self._warn_unnamed(sample)
                return
            graph.set_transform(sample.target, sample.source, sample.transform, sample.stamp, origin)
        elif sample.static:  # /tf_static: a static edge, whatever its stamp (0 is usual)
            graph.place_static(sample.parent, sample.child, sample.transform)
        else:
            graph.set_transform(sample.parent, sample.child, sample.transform, sample.stamp, origin)

    def _warn_unnamed(self, sample: FramePose) -> None:
        if not getattr(self, "_warned_unnamed", False):
            self._warned_unnamed = True
            log.error("component %s: a FramePose in %r without a source frame cannot be written into the graph "
                      "(give the converter a child_frame); such poses are ignored", self.name, sample.target)

    def _publish(self, port: OutputPort, query: Query, value: np.ndarray) -> None:
        """Write in this component's thread: callbacks run in whichever thread changed the graph
        (only a change made here, in ``on_update``, has a known cause to stamp the pose with)."""
        if self.wait_for_joints and any(isinstance(dependency, KinematicModel) and dependency.version == 0
                                        for dependency in query.dependencies):
            return  # the robot has had no joint state yet (a model's version counts its changes)
        self._published.add(port)
        activity = self.activity
        own = activity is None or current_activity() is activity or not activity.running
        origin, time = self._cause if own else (None, None)
        pose = FramePose(query.target, query.source, value, time)
        out = Stamped(pose, origin or Stamp.now(source=self.name)) if self.stamped else pose
        if own:
            port.write(out)
        else:
            assert activity is not None  # `own` when there is none
            activity.enqueue(lambda: port.write(out))

    @operation
    def lookup(self, target: str, source: str, time: float | None = None) -> np.ndarray:
        """``T_target_source`` now, or interpolated at ``time``."""
        return self.transform_graph.lookup(target, source, time)

