"""std_msgs/ColorRGBA and geometry_msgs/WrenchStamped: the colours and forces of the applications as
RViz and Foxglove take them; what is not a colour or a force is refused."""

from __future__ import annotations

import math
from dataclasses import dataclass

import pytest
from coco_core.errors import WrongTypeError
from coco_ros.convert import converter_for
from rclpy.serialization import deserialize_message


def test_a_colour_goes_out_with_alpha_one_and_comes_back() -> None:
    converter = converter_for("std_msgs/msg/ColorRGBA")
    msg = converter.to_ros((0.0, 1.0, 0.5))
    assert (msg.r, msg.g, msg.b, msg.a) == (0.0, 1.0, 0.5, 1.0)
    assert converter.to_coco(deserialize_message(converter.to_cdr((0.2, 0.4, 0.6, 0.8)),
                                                 converter.message_type)) == pytest.approx((0.2, 0.4, 0.6, 0.8))


@pytest.mark.parametrize("value", [(1.0, 0.0), (0.0, 2.0, 0.0), (math.nan, 0.0, 0.0), "red", 3.0])
def test_what_is_not_a_colour_is_refused(value) -> None:
    with pytest.raises(WrongTypeError, match="r, g, b"):
        converter_for("std_msgs/msg/ColorRGBA").to_ros(value)


@dataclass
class Force:
    """A HapticForce's shape: a force (N) and its stamp."""

    force: tuple[float, float, float]
    stamp: float = 0.0


def test_forces_and_wrenches_go_out_in_the_converters_frame() -> None:
    converter = converter_for("geometry_msgs/msg/WrenchStamped", frame_id="device")
    msg = converter.to_ros(Force((1.0, 2.0, 3.0), stamp=12.5))
    assert msg.header.frame_id == "device" and msg.header.stamp.sec == 12 and msg.header.stamp.nanosec == 500_000_000
    assert converter.to_coco(msg) == (1.0, 2.0, 3.0, 0.0, 0.0, 0.0)
    assert converter.to_coco(converter.to_ros((1, 2, 3, 4, 5, 6))) == (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)


@pytest.mark.parametrize("value", [(1.0, 2.0), (1.0, math.inf, 0.0), Force((math.nan, 0.0, 0.0)), "up"])
def test_what_is_not_a_force_is_refused(value) -> None:
    with pytest.raises(WrongTypeError, match="force"):
        converter_for("geometry_msgs/msg/WrenchStamped").to_ros(value)


def test_a_force_at_a_point_is_an_arrow_and_reads_back() -> None:
    converter = converter_for("visualization_msgs/msg/Marker", frame_id="camera", scale=0.1)
    arrow = converter.to_ros(((0.0, 0.0, 1.0), (0.0, 2.0, 0.0)))
    assert arrow.header.frame_id == "camera" and [(p.x, p.y, p.z) for p in arrow.points] == [
        (0.0, 0.0, 1.0), (0.0, pytest.approx(0.2), 1.0)]
    assert converter.to_coco(arrow) == ((0.0, 0.0, 1.0), (0.0, pytest.approx(2.0), 0.0))
    with pytest.raises(WrongTypeError, match="proxy and a force"):
        converter.to_ros(((0.0, 0.0), (1.0, 0.0, 0.0)))
