"""Which output ports are mirrored, on which topics, with which policy and message type.

Two sources, merged: the file's ``<topics>`` (:class:`~coco_core.model.TopicMirrorSpec`) and the
launcher's ``--expose PATTERN`` (``distance.*``, ``tf.gripper``, ``all``), matched against
``component.port`` of every output port. A port both name keeps the file's settings; one that only a
pattern names is mirrored on ``~/<component>/<port>`` with the policy of the port's own connections
(:func:`port_policy`): a port whose readers take every value (BUFFER) is seen whole on its topic.

What cannot be mirrored is an error naming it: an unknown component or port, an input port, a port
whose declared type no converter knows (a pattern with a wildcard leaves those out, in
:attr:`MirrorPlan.skipped`, so that ``--expose all`` mirrors what it can). Ports of components that
run in another process of the application are that process's to mirror (the ROS launcher's child
processes run the same plan).
"""

from __future__ import annotations

import fnmatch
from collections.abc import Sequence
from dataclasses import dataclass, field

from coco_core import Application
from coco_core.errors import CocoError, ConfigError, ConfigErrors, UnknownNameError, did_you_mean
from coco_core.model import AppSpec, TopicMirrorSpec
from coco_core.policy import BufferPolicy
from coco_core.ports import OutputPort, PooledOutputPort, type_name

from .choice import by_value, explicit_converter, ros_type_of

ALL = "all"
"""The pattern that mirrors every output port."""
MAX_DEPTH = 1000
"""The deepest topic history ``--expose`` gives a port connected with a larger buffer (65536-sample
BUFFERs are common; DDS would keep that many messages per topic)."""


@dataclass(frozen=True)
class Mirrored:
    """One port to mirror: the port, its topic (relative names under the node), the ROS type (empty:
    chosen from its first value) and the mirror connection's policy."""

    port: OutputPort
    topic: str
    ros_type: str
    data: BufferPolicy
    size: int
    frame: str = ""
    """The frame of values that carry none (:attr:`TopicMirrorSpec.frame`)."""
    hz: float = 0.0
    """The most messages a second (the newest value each period); 0: every value."""

    def describe(self) -> str:
        kind = self.ros_type or "type of its first value"
        size = f" {self.size}" if self.data is not BufferPolicy.DATA else ""
        rate = f", at most {self.hz:g} Hz" if self.hz else ""
        return f"{self.port.qualified_name} -> {self.topic} ({kind}, {self.data.value}{size}{rate})"


@dataclass
class MirrorPlan:
    """The ports to mirror in one process, and the ports a wildcard pattern left out (with why)."""

    mirrored: list[Mirrored] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)

    def lines(self) -> list[str]:
        """What ``--check`` prints."""
        if not self.mirrored and not self.skipped:
            return []
        return (["ROS topics (port mirrors):"] + [f"  {m.describe()}" for m in self.mirrored]
                + [f"  not mirrored: {text}" for text in self.skipped])


def check_mirrors(spec: AppSpec, app: Application, patterns: Sequence[str] = (),
                  allow_unknown: bool = False) -> list[str]:
    """``--check``: the mirrors of every process of ``spec`` (``app`` is the launcher's part; each
    child's part is built here, as the child will build it), as lines to print, or a
    :class:`ConfigErrors` naming every port that cannot be mirrored."""
    from coco_core.builder import build_application

    plan = plan_mirrors(spec, app, patterns)
    for process in spec.processes if spec.topics or patterns else ():  # nothing to mirror: no part built
        part = plan_mirrors(spec, build_application(spec, process.name, allow_unknown), patterns)
        plan.mirrored += part.mirrored
        plan.skipped += part.skipped
    return plan.lines()


def default_topic(component: str, port: str) -> str:
    """``~/<component>/<port>``: ``/<node>/<component>/<port>`` once the node resolves it."""
    return f"~/{component}/{port}"


def plan_mirrors(spec: AppSpec, app: Application, patterns: Sequence[str] = ()) -> MirrorPlan:
    """The mirrors of ``spec.topics`` and ``patterns`` among ``app``'s ports; a
    :class:`ConfigErrors` listing every port that cannot be mirrored."""
    plan = MirrorPlan()
    errors: list[ConfigError] = []
    seen: set[str] = set()
    for topic in spec.topics:
        try:
            port = _output(app, topic.component, topic.port)
            if port is not None:
                plan.mirrored.append(_mirrored(port, topic))
                seen.add(port.qualified_name)
        except CocoError as error:
            errors.append(ConfigError(f"<topic task={topic.component!r} port={topic.port!r}>: {error}",
                                      topic.location))
    for pattern in patterns:
        matched = _matching(app, pattern)
        if not matched and not _elsewhere(app, pattern):
            errors.append(ConfigError(f"--expose {pattern!r} matches no output port of application {app.name} "
                                      "(expected component.port, wildcards allowed, or all)"))
        for port in matched:
            if port.qualified_name in seen:
                continue
            seen.add(port.qualified_name)
            try:
                data, size = port_policy(port)
                plan.mirrored.append(_mirrored(port, TopicMirrorSpec(*_names(port.qualified_name), data=data,
                                                                     buffersize=size)))
            except CocoError as error:
                if _wildcard(pattern):
                    plan.skipped.append(f"{port.qualified_name}: {error}")
                else:
                    errors.append(ConfigError(f"--expose {pattern!r}: {error}"))
    if errors:
        raise ConfigErrors(errors)
    return plan


def port_policy(port: OutputPort) -> tuple[BufferPolicy, int]:
    """The policy the mirror of a port ``--expose`` names takes from the port's own connections: the first
    queued one's (BUFFER or CIRCULAR, its size up to :data:`MAX_DEPTH`), else DATA."""
    for connection in port.connections:
        policy = connection.policy
        if policy.data in (BufferPolicy.BUFFER, BufferPolicy.CIRCULAR):
            return policy.data, min(policy.size, MAX_DEPTH)
    return BufferPolicy.DATA, 1


def _names(qualified: str) -> tuple[str, str]:
    """``component.port`` -> (component, port)."""
    component, _, port = qualified.rpartition(".")
    return component, port


def _wildcard(pattern: str) -> bool:
    return pattern == ALL or any(c in pattern for c in "*?[")


def _matching(app: Application, pattern: str) -> list[OutputPort]:
    ports = [port for component in app.components.values() for port in component.outputs.values()]
    if pattern == ALL:
        return ports
    return [port for port in ports if fnmatch.fnmatchcase(port.qualified_name, pattern)]


def _elsewhere(app: Application, pattern: str) -> bool:
    """Whether ``pattern`` may name ports of components that run in another process (which mirrors them)."""
    component = pattern.rpartition(".")[0] or pattern
    return pattern == ALL or any(fnmatch.fnmatchcase(name, component) for name in app.elsewhere)


def _output(app: Application, component_name: str, port_name: str) -> OutputPort | None:
    """The output port, None when its component runs in another process."""
    if component_name in app.elsewhere:
        return None
    component = app.component(component_name)
    port = component.outputs.get(port_name)
    if port is None:
        if port_name in component.inputs:
            raise UnknownNameError(f"{component_name}.{port_name} is an input port: only output ports are mirrored")
        raise UnknownNameError(f"component {component_name} has no output port {port_name!r}; "
                               f"{did_you_mean(port_name, list(component.outputs))}")
    return port


def _mirrored(port: OutputPort, topic: TopicMirrorSpec) -> Mirrored:
    where = port.qualified_name
    if isinstance(port, PooledOutputPort) and (not topic.type or topic.data is not BufferPolicy.DATA):
        raise CocoError(f"{where} is a pooled output (frames in slots): mirrored with a type= (a mesh: "
                        "sensor_msgs/msg/PointCloud2) and data=DATA (the newest frame) only")
    if topic.type:
        ros_type = explicit_converter(topic.type, where).type_name
    elif by_value(port.type):
        ros_type = ""
    else:
        known = ros_type_of(port.type) if isinstance(port.type, type) else None
        if known is None:
            raise CocoError(f"no converter knows the values of {where} ({type_name(port.type)}); give its "
                            "<topic> a type= of coco_ros.convert's, or leave it out")
        ros_type = known
    return Mirrored(port, topic.topic or default_topic(*_names(where)), ros_type, topic.data,
                    topic.buffersize, topic.frame, topic.hz)
