"""sensor_msgs/PointCloud2 <-> PointCloud: fields at any offsets, extra fields, padded rows, packed
colours, byte order, NaN points."""

from __future__ import annotations

import array

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from conftest import python_lines
from coco_mr_vision.pointcloud import PointCloud
from coco_ros.convert import converter_for
from coco_ros.convert.stamps import RosTime
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header

clouds = converter_for("sensor_msgs/msg/PointCloud2")
rng = np.random.default_rng(11)


def through_the_wire(msg):
    received = deserialize_message(serialize_message(msg), type(msg))
    assert received == msg
    return received


def cloud_message(records: np.ndarray, fields: list[tuple[str, int, int]], height: int, width: int,
                  row_step: int | None = None, bigendian: bool = False, dense: bool = False) -> PointCloud2:
    """A PointCloud2 of structured ``records`` (height*width of them), rows padded to ``row_step``."""
    point_step = records.dtype.itemsize
    row_step = row_step or point_step * width
    rows = np.full((height, row_step), 0xCD, np.uint8)
    rows[:, :point_step * width] = records.view(np.uint8).reshape(height, point_step * width)
    msg = PointCloud2(header=Header(stamp=Time(sec=1_700_000_001, nanosec=999_999_999), frame_id="lidar"),
                      height=height, width=width, is_bigendian=bigendian, point_step=point_step,
                      row_step=row_step, is_dense=dense,
                      fields=[PointField(name=name, offset=offset, datatype=datatype, count=1)
                              for name, offset, datatype in fields])
    msg.data = array.array("B", rows.tobytes())
    return msg


def packed(colors: np.ndarray) -> np.ndarray:
    c = colors.astype(np.uint32)
    return (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]


# An Ouster/PCL-like layout: x y z, padding, intensity, rgb, normals, ring; point_step 48.
RICH = np.dtype({"names": ["x", "y", "z", "intensity", "rgb", "normal_x", "normal_y", "normal_z", "ring"],
                 "formats": ["<f4", "<f4", "<f4", "<f4", "<u4", "<f4", "<f4", "<f4", "<u2"],
                 "offsets": [0, 4, 8, 16, 20, 32, 36, 40, 44], "itemsize": 48})
RICH_FIELDS = [("x", 0, PointField.FLOAT32), ("y", 4, PointField.FLOAT32), ("z", 8, PointField.FLOAT32),
               ("intensity", 16, PointField.FLOAT32), ("rgb", 20, PointField.FLOAT32),
               ("normal_x", 32, PointField.FLOAT32), ("normal_y", 36, PointField.FLOAT32),
               ("normal_z", 40, PointField.FLOAT32), ("ring", 44, PointField.UINT16)]


def rich_records(count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    points = rng.normal(0, 5, (count, 3)).astype(np.float32)
    colors = rng.integers(0, 256, (count, 3), dtype=np.uint8)
    records = np.zeros(count, RICH)
    for k, name in enumerate("xyz"):
        records[name] = points[:, k]
    records["rgb"] = packed(colors)
    records["intensity"] = 7.5
    records["ring"] = 3
    return records, points, colors


def test_extra_fields_and_a_large_point_step_read_as_a_view():
    records, points, colors = rich_records(10)
    msg = through_the_wire(cloud_message(records, RICH_FIELDS, 1, 10, dense=True))
    cloud = clouds.to_coco(msg)
    np.testing.assert_array_equal(cloud.points, points)
    np.testing.assert_array_equal(cloud.colors, colors)
    assert cloud.frame_id == "lidar" and cloud.organized is None
    assert cloud.stamp == RosTime(1_700_000_001, 999_999_999) and cloud.stamp.nanosec == 999_999_999
    assert np.shares_memory(cloud.points, np.frombuffer(msg.data, np.uint8))  # no copy of the points
    assert not cloud.points.flags.writeable
    out = through_the_wire(clouds.to_ros(cloud))
    assert [(f.name, f.offset, f.datatype, f.count) for f in out.fields] == [
        ("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("rgb", 12, 7, 1)]
    assert (out.point_step, out.row_step, out.height, out.width, out.is_dense) == (16, 160, 1, 10, True)
    assert out.header == msg.header
    again = clouds.to_coco(out)
    np.testing.assert_array_equal(again.points, points)
    np.testing.assert_array_equal(again.colors, colors)


def test_organized_cloud_with_padded_rows_and_nan_points():
    records, points, colors = rich_records(12)
    points[[1, 7]] = np.nan
    for k, name in enumerate("xyz"):
        records[name] = points[:, k]
    msg = through_the_wire(cloud_message(records, RICH_FIELDS, 3, 4, row_step=4 * 48 + 20))
    cloud = clouds.to_coco(msg)
    assert cloud.organized == (3, 4) and len(cloud) == 12 and not cloud.is_dense
    np.testing.assert_array_equal(cloud.points, points)  # NaN where NaN: kept in place
    np.testing.assert_array_equal(cloud.colors, colors)
    out = through_the_wire(clouds.to_ros(cloud))
    assert (out.height, out.width, out.row_step, out.is_dense) == (3, 4, 64, False)
    np.testing.assert_array_equal(clouds.to_coco(out).points, points)
    dropped = converter_for("sensor_msgs/PointCloud2", drop_invalid=True).to_coco(msg)
    assert len(dropped) == 10 and dropped.organized is None and dropped.is_dense
    np.testing.assert_array_equal(dropped.points, np.delete(points, [1, 7], axis=0))
    np.testing.assert_array_equal(dropped.colors, np.delete(colors, [1, 7], axis=0))


def test_fields_out_of_order_and_of_other_types():
    layout = np.dtype({"names": ["y", "z", "x"], "formats": ["<f8", "<i2", "<f4"], "offsets": [0, 8, 12],
                       "itemsize": 20})
    records = np.zeros(5, layout)
    records["x"], records["y"], records["z"] = [1, 2, 3, 4, 5], [0.5, 1.5, 2.5, 3.5, 4.5], [-1, -2, -3, -4, -5]
    msg = cloud_message(records, [("y", 0, PointField.FLOAT64), ("z", 8, PointField.INT16),
                                  ("x", 12, PointField.FLOAT32)], 1, 5)
    cloud = clouds.to_coco(through_the_wire(msg))
    assert cloud.points.dtype == np.float32 and cloud.colors is None
    np.testing.assert_array_equal(cloud.points, np.stack([records["x"], records["y"], records["z"]], axis=1))
    # Evenly spaced but of different types: no single strided view can read them.
    layout = np.dtype({"names": ["x", "y", "z"], "formats": ["<f4", "<f4", "<f8"], "offsets": [0, 4, 8],
                       "itemsize": 16})
    records = np.zeros(3, layout)
    records["x"], records["y"], records["z"] = [1, 2, 3], [4, 5, 6], [0.25, 0.5, 0.75]
    cloud = clouds.to_coco(cloud_message(records, [("x", 0, PointField.FLOAT32), ("y", 4, PointField.FLOAT32),
                                                   ("z", 8, PointField.FLOAT64)], 1, 3))
    np.testing.assert_array_equal(cloud.points, [[1, 4, 0.25], [2, 5, 0.5], [3, 6, 0.75]])


def test_big_endian_cloud():
    layout = np.dtype({"names": ["x", "y", "z", "rgba"], "formats": [">f4", ">f4", ">f4", ">u4"],
                       "offsets": [0, 4, 8, 12], "itemsize": 16})
    points = rng.normal(size=(6, 3)).astype(np.float32)
    colors = rng.integers(0, 256, (6, 3), dtype=np.uint8)
    records = np.zeros(6, layout)
    for k, name in enumerate("xyz"):
        records[name] = points[:, k]
    records["rgba"] = packed(colors) | 0xFF000000
    cloud = clouds.to_coco(cloud_message(records, [("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("rgba", 12, 6)], 2, 3,
                                         bigendian=True))
    assert cloud.points.dtype.isnative
    np.testing.assert_array_equal(cloud.points, points)
    np.testing.assert_array_equal(cloud.colors, colors)


def test_coco_to_ros_to_coco():
    points = rng.normal(size=(2, 3, 3)).reshape(6, 3).astype(np.float32)
    points[4] = [np.nan, np.nan, np.nan]
    colors = rng.integers(0, 256, (6, 3), dtype=np.uint8)
    for cloud in (PointCloud(points, colors, 42.25, "map", organized=(2, 3)), PointCloud(points[:3], None, None, "")):
        msg = through_the_wire(clouds.to_ros(cloud))
        assert msg.is_bigendian is False and msg.is_dense == cloud.is_dense
        back = clouds.to_coco(msg)
        np.testing.assert_array_equal(back.points, cloud.points)
        assert (back.colors is None) == (cloud.colors is None)
        if cloud.colors is not None:
            np.testing.assert_array_equal(back.colors, cloud.colors)
        assert (back.stamp, back.frame_id, back.organized) == (cloud.stamp, cloud.frame_id, cloud.organized)


def test_nan_payload_bits_are_copied_not_converted():
    points = np.zeros((1, 3), np.float32)
    points.view(np.uint32)[0, 0] = 0x7FA00001  # a signalling NaN: float conversions would change it
    msg = clouds.to_ros(PointCloud(points))
    assert np.frombuffer(msg.data, "<u4")[0] == 0x7FA00001


def test_empty_clouds():
    msg = through_the_wire(clouds.to_ros(PointCloud(np.empty((0, 3), np.float32))))
    assert (msg.height, msg.width, len(msg.data), msg.is_dense) == (1, 0, 0, True)
    assert len(clouds.to_coco(msg)) == 0


@pytest.mark.parametrize("change, error", [
    (dict(fields=[PointField(name="x", offset=0, datatype=7, count=1)]), "lacks field.s. y, z; it has: x"),
    (dict(point_step=8), "point_step 8 is smaller than its fields"),
    (dict(height=2, width=2, row_step=20), "row_step 20 is smaller than width"),
    (dict(width=9), "needs 144 bytes of data, got 128"),
    (dict(fields=[PointField(name=n, offset=4 * k, datatype=42, count=1) for k, n in enumerate("xyz")]),
     "field 'x' has unknown datatype 42"),
])
def test_bad_clouds_are_refused(change, error):
    msg = clouds.to_ros(PointCloud(np.zeros((8, 3), np.float32), np.zeros((8, 3), np.uint8)))
    for name, value in change.items():
        setattr(msg, name, value)
    with pytest.raises(ValueError, match=error):
        clouds.to_coco(msg)


def test_a_large_cloud_is_converted_without_a_python_loop():
    def lines(count):
        records, points, _ = rich_records(count)
        msg = cloud_message(records, RICH_FIELDS, 1, count)
        cloud, to_coco_lines = python_lines(lambda: clouds.to_coco(msg))
        _, to_ros_lines = python_lines(lambda: clouds.to_ros(cloud))
        np.testing.assert_array_equal(cloud.points, points)
        return to_coco_lines, to_ros_lines

    lines(4)
    assert lines(100_000) == lines(4)
