"""converter_for: the registry a ROSInterface uses to find the converter of a configured type."""

from __future__ import annotations

import numpy as np
import pytest
from coco_core.transforms.samples import FramePose, JointSample, TransformSample
from coco_mr_vision.image import CameraIntrinsics, Image
from coco_mr_vision.pointcloud import PointCloud
from coco_ros.convert import Converter, converter_for, normalize_type_name, supported_types
from sensor_msgs.msg import Image as ImageMsg

REQUIRED = {
    "sensor_msgs/msg/JointState": JointSample,
    "sensor_msgs/msg/Image": Image,
    "sensor_msgs/msg/CameraInfo": CameraIntrinsics,
    "sensor_msgs/msg/PointCloud2": PointCloud,
    "geometry_msgs/msg/PoseStamped": FramePose,
    "geometry_msgs/msg/TransformStamped": TransformSample,
    "tf2_msgs/msg/TFMessage": list,
    "std_msgs/msg/Float64MultiArray": np.ndarray,
    "std_msgs/msg/Float64": float,
}


def test_every_required_type_is_supported():
    assert set(REQUIRED) <= set(supported_types())
    for name, coco_type in REQUIRED.items():
        converter = converter_for(name)
        assert isinstance(converter, Converter)
        assert converter.type_name == name and converter.coco_type is coco_type
        assert converter.message_type.__name__ == name.rsplit("/", 1)[1]


@pytest.mark.parametrize("spelling", ["sensor_msgs/msg/Image", "sensor_msgs/Image", "sensor_msgs.msg.Image",
                                      " sensor_msgs/Image ", ImageMsg])
def test_type_names_in_every_usual_spelling(spelling):
    assert normalize_type_name(spelling) == "sensor_msgs/msg/Image"
    assert converter_for(spelling).type_name == "sensor_msgs/msg/Image"


def test_unknown_types_list_the_supported_ones():
    with pytest.raises(ValueError, match="no converter for ROS message type 'nav_msgs/Odometry'; supported: "
                                         "geometry_msgs/msg/PoseStamped, .*sensor_msgs/msg/Image, "
                                         ".*tf2_msgs/msg/TFMessage"):
        converter_for("nav_msgs/Odometry")


def test_options_are_checked():
    assert converter_for("geometry_msgs/PoseStamped", child_frame="tool").child_frame == "tool"
    assert converter_for("sensor_msgs/Image", copy=True).copy is True
    with pytest.raises(ValueError, match="geometry_msgs/msg/PoseStamped converter has no option.s. child; its "
                                         "options: child_frame"):
        converter_for("geometry_msgs/PoseStamped", child="tool")
    with pytest.raises(ValueError, match="has no option.s. frame; its options: none"):
        converter_for("geometry_msgs/TransformStamped", frame="x")
    with pytest.raises(ValueError, match="its options: labels"):
        converter_for("std_msgs/Float32MultiArray", label=["a"])


def test_converters_are_stateless_and_reusable():
    converter = converter_for("std_msgs/Int16MultiArray")
    assert repr(converter) == "MultiArrayConverter(std_msgs/msg/Int16MultiArray)"
    first = converter.to_coco(converter.to_ros(np.array([1, 2])))
    second = converter.to_coco(converter.to_ros(np.array([3])))
    np.testing.assert_array_equal(first, [1, 2])
    np.testing.assert_array_equal(second, [3])


def test_every_converter_reads_cdr_bytes_as_it_reads_the_message():
    """``from_cdr`` (what BagReplay uses) agrees with ``to_coco`` for every registered type: same
    value type, or the same refusal, on each type's default message."""
    from rclpy.serialization import serialize_message

    from coco_ros.convert import converter_for, supported_types

    def outcome(call):
        try:
            return "value", type(call()).__name__
        except ValueError as error:
            return "refused", str(error)

    for type_name in supported_types():
        converter = converter_for(type_name)
        message = converter.message_type()
        data = serialize_message(message)
        assert outcome(lambda: converter.from_cdr(data)) == outcome(lambda: converter.to_coco(message)), type_name
