"""Poses and transforms: ``geometry_msgs/PoseStamped``, ``geometry_msgs/TransformStamped`` and
``tf2_msgs/TFMessage`` <-> the 4x4 samples of the transformation graph.

Frames follow tf2: a TransformStamped from ``header.frame_id`` (parent) to ``child_frame_id`` is
``T_parent_child``, a :class:`TransformSample` ``(parent, child)``; a PoseStamped is the pose of
something in ``header.frame_id``, a :class:`FramePose` with that frame as ``target`` and, since the
message names no source frame, the converter's ``child_frame`` as ``source``. A FramePose may also
be published as a TransformStamped or in a TFMessage (``target`` -> parent, ``source`` -> child),
so that lookups of the graph can be broadcast on /tf.

Quaternions are normalised on the way in (a zero quaternion is refused) and written with ``w >= 0``
on the way out, so a rotation survives ROS -> CoCo -> ROS up to the sign of its quaternion and
floating-point rounding (about 1e-16).
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from typing import Any

import numpy as np
from coco_core.errors import GeometryError, MessageError, MissingPackageError, WrongTypeError
from coco_core.transforms import se3
from coco_core.transforms.samples import FramePose, TransformSample
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion, Transform, TransformStamped, Vector3

from .base import Converter, header_stamp, make_header, message_class
from .cdr_writer import align, with_header
from .stamps import received_time


def matrix_of(translation: Any, rotation: Any) -> np.ndarray:
    """4x4 transform of a message's translation (Point or Vector3) and rotation (Quaternion)."""
    quaternion = (rotation.x, rotation.y, rotation.z, rotation.w)
    if sum(c * c for c in quaternion) < 1e-12:
        raise GeometryError(f"quaternion {quaternion} is zero: not a rotation")
    return se3.from_pose((translation.x, translation.y, translation.z), quaternion)


def _pose_parts(transform: np.ndarray) -> tuple[list[float], list[float]]:
    matrix = np.asarray(transform, dtype=float)
    if matrix.shape != (4, 4):
        raise GeometryError(f"expected a 4x4 transform, got shape {matrix.shape}")
    translation, quaternion = se3.to_pose(matrix)
    return translation.tolist(), quaternion.tolist()


def pose_of(transform: np.ndarray) -> Pose:
    (x, y, z), (qx, qy, qz, qw) = _pose_parts(transform)
    return Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def transform_of(transform: np.ndarray) -> Transform:
    (x, y, z), (qx, qy, qz, qw) = _pose_parts(transform)
    return Transform(translation=Vector3(x=x, y=y, z=z), rotation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def _frames(value: TransformSample | FramePose) -> tuple[str, str]:
    return (value.parent, value.child) if isinstance(value, TransformSample) else (value.target, value.source)


class PoseStampedConverter(Converter[PoseStamped, FramePose]):
    """``geometry_msgs/PoseStamped`` <-> :class:`FramePose` (``T_frame_id_child_frame``)."""

    type_name = "geometry_msgs/msg/PoseStamped"
    coco_type = FramePose
    writes_cdr = True

    def __init__(self, child_frame: str = "") -> None:
        self.child_frame = child_frame

    def to_coco(self, msg: PoseStamped) -> FramePose:
        self._check_message(msg)
        pose = msg.pose
        return FramePose(msg.header.frame_id, self.child_frame, matrix_of(pose.position, pose.orientation),
                         header_stamp(msg.header))

    def to_ros(self, value: FramePose) -> PoseStamped:
        """The pose of ``value.source`` in ``value.target`` (the source's name is not carried)."""
        self._check_value(value)
        return PoseStamped(header=make_header(value.stamp, value.target), pose=pose_of(value.transform))

    def to_cdr(self, value: FramePose) -> bytes:
        self._check_value(value)
        buffer = align(with_header(value.stamp, value.target), 8)
        translation, quaternion = _pose_parts(value.transform)
        buffer += _POSE.pack(*translation, *quaternion)
        return bytes(buffer)


class TransformStampedConverter(Converter[TransformStamped, TransformSample]):
    """``geometry_msgs/TransformStamped`` <-> :class:`TransformSample` (a FramePose is also written)."""

    type_name = "geometry_msgs/msg/TransformStamped"
    coco_type = TransformSample

    def to_coco(self, msg: TransformStamped) -> TransformSample:
        self._check_message(msg)
        return transform_sample(msg)

    def to_ros(self, value: TransformSample | FramePose) -> TransformStamped:
        self._check_value(value, (TransformSample, FramePose))
        return transform_stamped(value)


def transform_sample(msg: TransformStamped) -> TransformSample:
    transform = msg.transform
    return TransformSample(msg.header.frame_id, msg.child_frame_id,
                           matrix_of(transform.translation, transform.rotation), header_stamp(msg.header))


_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")
_POSE = struct.Struct("<7d")


def _tf_samples_from_cdr(data: bytes, static: bool) -> list[TransformSample]:
    """XCDR1 little-endian tf2_msgs/TFMessage: a sequence of TransformStamped (header stamp and
    frame_id, child_frame_id, translation x y z and rotation x y z w as doubles aligned to 8 from
    byte 4)."""

    def string_at(position: int) -> tuple[str, int]:
        position += -(position - 4) % 4
        length = _U32.unpack_from(data, position)[0]
        start = position + 4
        if start + length > len(data) or length == 0:
            raise struct.error(f"a string of {length} bytes at byte {position}")
        return data[start:start + length - 1].decode("utf-8"), start + length

    count = _U32.unpack_from(data, 4)[0]
    position = 8
    samples = []
    for _ in range(count):
        position += -(position - 4) % 4
        sec, nanosec = _STAMP.unpack_from(data, position)
        parent, position = string_at(position + 8)
        child, position = string_at(position)
        position += -(position - 4) % 8
        tx, ty, tz, qx, qy, qz, qw = _POSE.unpack_from(data, position)
        position += _POSE.size
        if qx * qx + qy * qy + qz * qz + qw * qw < 1e-12:
            raise GeometryError(f"quaternion {(qx, qy, qz, qw)} is zero: not a rotation")
        matrix = se3.from_pose((tx, ty, tz), (qx, qy, qz, qw))
        if static:
            samples.append(TransformSample(parent, child, matrix, received_time(sec, nanosec), static=True))
        else:
            stamp = None if sec == 0 and nanosec == 0 else received_time(sec, nanosec)
            samples.append(TransformSample(parent, child, matrix, stamp))
    return samples


def static_sample(msg: TransformStamped) -> TransformSample:
    """A /tf_static transform: a static sample, its stamp kept as given (0 included)."""
    transform = msg.transform
    stamp = msg.header.stamp
    return TransformSample(msg.header.frame_id, msg.child_frame_id,
                           matrix_of(transform.translation, transform.rotation),
                           received_time(stamp.sec, stamp.nanosec), static=True)


def transform_stamped(value: TransformSample | FramePose) -> TransformStamped:
    parent, child = _frames(value)
    return TransformStamped(header=make_header(value.stamp, parent), child_frame_id=child,
                            transform=transform_of(value.transform))


class TFMessageConverter(Converter[Any, list]):
    """``tf2_msgs/TFMessage`` (/tf, /tf_static) <-> a list of :class:`TransformSample`.

    ``to_ros`` takes one sample or any iterable of them (FramePose values too), which is what the
    transformation interface's ``transform`` port accepts. ``tf2_msgs`` is imported when the
    converter is made: no PyPI wheel carries it, the workspace builds it (``vendor/tf2_msgs``), so a
    shell that did not source the workspace's ``install/setup.bash`` gets an error saying so, while
    the other geometry converters still work.

    ``static``: the messages come from /tf_static (or another latched TF topic): their samples are
    marked ``static`` and become static edges of the graph, like TFBridge makes them, whatever their
    stamp (a static broadcaster's stamp is often 0, which is no "unset" here).
    """

    type_name = "tf2_msgs/msg/TFMessage"
    coco_type = list

    def __init__(self, static: bool = False) -> None:
        self.static = static
        try:
            self._message = message_class(self.type_name)
        except ImportError as error:
            raise MissingPackageError(f"the {self.type_name} converter needs the tf2_msgs Python package ({error}); "
                                      "it is built in the workspace from vendor/tf2_msgs: run scripts/setup.sh, or "
                                      "source install/setup.bash") from error

    @property
    def message_type(self) -> type:
        return self._message

    def from_cdr(self, data: bytes) -> list[TransformSample]:
        """Read a TFMessage's CDR bytes directly (a recorded /tf): the same samples as
        :meth:`to_coco` without building rclpy's TransformStamped, Header, Vector3 and Quaternion
        objects. A big-endian message goes through rclpy."""
        if len(data) < 4 or data[1] != 1:  # encapsulation: CDR little-endian is 00 01
            return super().from_cdr(data)
        try:
            return _tf_samples_from_cdr(data, self.static)
        except (struct.error, UnicodeDecodeError) as error:
            raise MessageError(f"malformed TFMessage CDR ({len(data)} bytes): {error}") from None

    def to_coco(self, msg: Any) -> list[TransformSample]:
        self._check_message(msg)
        if self.static:
            return [static_sample(transform) for transform in msg.transforms]
        return [transform_sample(transform) for transform in msg.transforms]

    def to_ros(self, value: TransformSample | FramePose | Iterable[TransformSample | FramePose]) -> Any:
        if isinstance(value, (TransformSample, FramePose)):
            samples = [value]
        elif isinstance(value, Iterable):
            samples = list(value)
        else:
            raise WrongTypeError(f"{type(self).__name__} publishes a TransformSample or FramePose, or a list of them, "
                                 f"got {type(value).__name__}")
        for sample in samples:
            self._check_value(sample, (TransformSample, FramePose))
        return self._message(transforms=[transform_stamped(sample) for sample in samples])
