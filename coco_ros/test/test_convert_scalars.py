"""std_msgs/Float64 <-> float: real numbers out, through the wire and back; anything else refused."""

from __future__ import annotations

import math

import numpy as np
import pytest
from coco_ros.convert import converter_for
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64, Float64MultiArray

scalar = converter_for("std_msgs/Float64")


def through_the_wire(msg: Float64) -> Float64:
    return deserialize_message(serialize_message(msg), Float64)


@pytest.mark.parametrize("value", [0.0, -2.5, 1e-300, 1.7e308, 3, np.float32(0.5), np.float64(-7.25), np.int64(4)])
def test_real_numbers_round_trip_as_floats(value):
    msg = scalar.to_ros(value)
    back = scalar.to_coco(through_the_wire(msg))
    assert type(back) is float and back == float(value)


def test_non_finite_values_pass_unchanged():
    assert math.isnan(scalar.to_coco(through_the_wire(scalar.to_ros(math.nan))))
    assert scalar.to_coco(through_the_wire(scalar.to_ros(-math.inf))) == -math.inf


@pytest.mark.parametrize("value", [True, "1.0", None, np.array([1.0]), 1 + 2j])
def test_anything_but_a_real_number_is_refused_naming_the_type(value):
    with pytest.raises(TypeError, match=f"publishes real numbers as std_msgs/msg/Float64, got {type(value).__name__}"):
        scalar.to_ros(value)


def test_another_message_type_is_refused():
    with pytest.raises(TypeError, match="converts std_msgs/msg/Float64 messages, got Float64MultiArray"):
        scalar.to_coco(Float64MultiArray(data=[1.0]))


@pytest.mark.parametrize("value", [0.0, -2.5, 1.7e308, 3, np.float32(0.5), np.int64(4), math.inf])
def test_the_cdr_bytes_it_writes_are_rclpy_s_serialization(value):
    assert scalar.writes_cdr
    assert scalar.to_cdr(value) == serialize_message(scalar.to_ros(value))


@pytest.mark.parametrize("value", [True, "1.0", None])
def test_writing_cdr_refuses_what_to_ros_refuses(value):
    with pytest.raises(TypeError, match=f"publishes real numbers as std_msgs/msg/Float64, got {type(value).__name__}"):
        scalar.to_cdr(value)
