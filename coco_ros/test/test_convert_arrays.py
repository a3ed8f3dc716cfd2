"""std_msgs numeric MultiArrays <-> numpy arrays: layout dims give the shape."""

from __future__ import annotations

import numpy as np
import pytest
from coco_ros.convert import converter_for
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray, Int32MultiArray, MultiArrayDimension, MultiArrayLayout, UInt8MultiArray

arrays = converter_for("std_msgs/msg/Float64MultiArray")


def through_the_wire(msg):
    received = deserialize_message(serialize_message(msg), type(msg))
    assert received == msg
    return received


def dims(*triples):
    return [MultiArrayDimension(label=label, size=size, stride=stride) for label, size, stride in triples]


def test_a_matrix_round_trips_with_its_labels():
    msg = Float64MultiArray(layout=MultiArrayLayout(dim=dims(("rows", 2, 6), ("cols", 3, 3))),
                            data=[1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    received = through_the_wire(msg)
    matrix = arrays.to_coco(received)
    np.testing.assert_array_equal(matrix, [[1, 2, 3], [4, 5, 6]])
    assert np.shares_memory(matrix, np.frombuffer(received.data, np.float64)) and not matrix.flags.writeable
    labelled = converter_for("std_msgs/Float64MultiArray", labels=["rows", "cols"])
    assert labelled.to_ros(matrix) == msg
    assert [d.label for d in arrays.to_ros(matrix).layout.dim] == ["", ""]


def test_numpy_arrays_round_trip():
    for value in (np.arange(24.0).reshape(2, 3, 4), np.array([0.5, -1.5]), np.array(7.0), np.zeros((0, 3))):
        msg = through_the_wire(arrays.to_ros(value))
        assert [(d.size, d.stride) for d in msg.layout.dim] == [
            (n, int(np.prod(np.atleast_1d(value).shape[k:]))) for k, n in enumerate(np.atleast_1d(value).shape)]
        back = arrays.to_coco(msg)
        assert back.dtype == np.float64
        np.testing.assert_array_equal(back, np.atleast_1d(value))


def test_offset_and_padded_strides_are_followed():
    # A 2x2 block inside a 3x4 buffer, starting at element 5: rows 4 apart.
    msg = Float64MultiArray(layout=MultiArrayLayout(dim=dims(("", 2, 8), ("", 2, 4)), data_offset=5),
                            data=list(np.arange(12.0)))
    np.testing.assert_array_equal(arrays.to_coco(msg), [[5, 6], [9, 10]])


def test_layouts_without_strides_or_dims():
    msg = Float64MultiArray(layout=MultiArrayLayout(dim=dims(("", 2, 0), ("", 3, 0))), data=list(np.arange(6.0)))
    np.testing.assert_array_equal(arrays.to_coco(msg), [[0, 1, 2], [3, 4, 5]])
    msg = Float64MultiArray(layout=MultiArrayLayout(data_offset=1), data=[9.0, 1.0, 2.0])
    np.testing.assert_array_equal(arrays.to_coco(msg), [1.0, 2.0])


def test_layouts_that_do_not_fit_the_data_are_refused():
    msg = Float64MultiArray(layout=MultiArrayLayout(dim=dims(("rows", 3, 6), ("cols", 2, 2))), data=[1.0] * 5)
    with pytest.raises(ValueError, match=r"\(rows: size 3 stride 6, cols: size 2 stride 2; data_offset 0\) needs 6 "
                                         "elements, the data has 5"):
        arrays.to_coco(msg)
    with pytest.raises(ValueError, match="data_offset 4 is past the 3 elements"):
        arrays.to_coco(Float64MultiArray(layout=MultiArrayLayout(data_offset=4), data=[1.0, 2.0, 3.0]))


def test_other_element_types():
    ints = converter_for("std_msgs/msg/Int32MultiArray")
    msg = through_the_wire(ints.to_ros(np.array([[1, -2], [3, 4]], dtype=np.int64)))
    assert isinstance(msg, Int32MultiArray)
    back = ints.to_coco(msg)
    assert back.dtype == np.int32
    np.testing.assert_array_equal(back, [[1, -2], [3, 4]])
    with pytest.raises(TypeError, match="cannot publish float64 values as std_msgs/msg/Int32MultiArray"):
        ints.to_ros(np.array([0.5]))
    raw = converter_for("std_msgs/UInt8MultiArray")
    assert isinstance(raw.to_ros(np.arange(5, dtype=np.uint8)), UInt8MultiArray)
    np.testing.assert_array_equal(arrays.to_coco(arrays.to_ros(np.arange(3))), [0.0, 1.0, 2.0])  # ints into floats
    with pytest.raises(TypeError, match="converts std_msgs/msg/Float64MultiArray messages, got Int32MultiArray"):
        arrays.to_coco(msg)
    with pytest.raises(TypeError, match="publishes numeric arrays"):
        arrays.to_ros(["a", object()])


def test_a_large_array_is_a_view_of_the_message():
    msg = arrays.to_ros(np.random.default_rng(0).normal(size=(500, 400)))
    back = arrays.to_coco(msg)
    assert back.shape == (500, 400) and np.shares_memory(back, np.frombuffer(msg.data, np.float64))
