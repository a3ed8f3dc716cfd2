"""coco_ros errors are CocoErrors (the launchers report them as messages) that keep the built-in class
callers catch (ValueError, TypeError)."""

from __future__ import annotations

import pytest
from coco_core.errors import (
    BagFormatError,
    CocoError,
    GeometryError,
    MessageError,
    ReplayError,
    SpecError,
    WrongTypeError,
)
from coco_ros.bag.qos import parse_profiles
from coco_ros.convert import converter_for
from coco_ros.convert.geometry import matrix_of
from coco_ros.interface.topic import parse_spec
from coco_ros.replay.clock import PlaybackClock
from geometry_msgs.msg import Quaternion, Vector3
from sensor_msgs.msg import Image as ImageMsg


def both(error: BaseException, builtin: type[BaseException]) -> bool:
    """Whether ``error`` is caught by ``except CocoError`` and by ``except <builtin>`` alike."""
    return isinstance(error, CocoError) and isinstance(error, builtin)


def test_a_bad_topic_spec_is_a_spec_error_and_a_value_error() -> None:
    with pytest.raises(SpecError) as caught:
        parse_spec("not a spec")
    assert both(caught.value, ValueError)


def test_a_negative_replay_rate_is_a_replay_error_and_a_value_error() -> None:
    with pytest.raises(ReplayError, match="replay rate") as caught:
        PlaybackClock(rate=-1.0)
    assert both(caught.value, ValueError)


def test_an_unsupported_image_encoding_is_a_message_error_and_a_value_error() -> None:
    msg = ImageMsg(encoding="bayer_rggb16", width=1, height=1, step=2, data=b"\0\0")
    with pytest.raises(MessageError, match="not supported") as caught:
        converter_for("sensor_msgs/msg/Image").to_coco(msg)
    assert both(caught.value, ValueError)


def test_a_zero_quaternion_is_a_geometry_error_and_a_value_error() -> None:
    with pytest.raises(GeometryError, match="not a rotation") as caught:
        matrix_of(Vector3(), Quaternion(x=0.0, y=0.0, z=0.0, w=0.0))
    assert both(caught.value, ValueError)


def test_a_value_of_the_wrong_kind_is_a_wrong_type_error_and_a_type_error() -> None:
    with pytest.raises(WrongTypeError, match="publishes real numbers") as caught:
        converter_for("std_msgs/msg/Float64").to_ros("1.0")
    assert both(caught.value, TypeError)


def test_bad_qos_profiles_are_a_bag_format_error_and_a_value_error() -> None:
    with pytest.raises(BagFormatError, match="offered_qos_profiles") as caught:
        parse_profiles("{")
    assert both(caught.value, ValueError)
