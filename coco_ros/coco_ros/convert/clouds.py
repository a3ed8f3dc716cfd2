"""``sensor_msgs/PointCloud2`` <-> :class:`coco_mr_vision.pointcloud.PointCloud`.

Reading: the ``x``, ``y`` and ``z`` fields may sit at any offsets, in any numeric PointField type,
within points of any ``point_step`` and rows of any ``row_step``; each is a strided numpy view of
the message's buffer, and when they are float32 in native byte order, evenly spaced and rows are
unpadded (the usual PCL layout, extra fields or not), the Nx3 points are one read-only view with no
copy at all. Other layouts cost one vectorised copy. A colour field named ``rgb`` or ``rgba``
(PCL's packed 0x00RRGGBB, declared FLOAT32 or UINT32) becomes Nx3 uint8 colours. Other fields
(intensity, normals, ring...) are not carried.

Invalid points: points are kept as they are, NaN included, and a cloud of more than one row stays
*organized* (its height and width are kept) whatever ``is_dense`` says; ``drop_invalid=True``
removes every point with a non-finite coordinate instead (the cloud is then unorganized).

Writing: x, y, z as little-endian FLOAT32 at offsets 0, 4, 8, plus ``rgb`` (FLOAT32, packed) at 12
when the cloud has colours; ``point_step`` 12 or 16, unpadded rows; ``is_dense`` is computed from
the points; an organized cloud keeps its height and width, others are one row.
"""

from __future__ import annotations

import numpy as np
from coco_core.errors import MessageError
from coco_mr_vision.pointcloud import PointCloud
from sensor_msgs.msg import PointCloud2, PointField

from .base import Converter, header_stamp, make_header, read_only, typed_array

#: PointField datatype -> numpy type (byte order applied per message)
FIELD_TYPES: dict[int, str] = {
    PointField.INT8: "i1", PointField.UINT8: "u1", PointField.INT16: "i2", PointField.UINT16: "u2",
    PointField.INT32: "i4", PointField.UINT32: "u4", PointField.FLOAT32: "f4", PointField.FLOAT64: "f8",
}

COLOR_FIELDS = ("rgb", "rgba")


class PointCloud2Converter(Converter[PointCloud2, PointCloud]):
    """``sensor_msgs/PointCloud2`` <-> :class:`PointCloud`; ``drop_invalid`` removes NaN points."""

    type_name = "sensor_msgs/msg/PointCloud2"
    coco_type = PointCloud

    def __init__(self, drop_invalid: bool = False) -> None:
        self.drop_invalid = drop_invalid

    def to_coco(self, msg: PointCloud2) -> PointCloud:
        self._check_message(msg)
        fields = {field.name: field for field in msg.fields}
        missing = [name for name in "xyz" if name not in fields]
        if missing:
            raise MessageError(f"PointCloud2 lacks field(s) {', '.join(missing)}; it has: "
                               f"{', '.join(fields) or 'no fields'}")
        height, width, point_step, row_step = msg.height, msg.width, msg.point_step, msg.row_step
        order = ">" if msg.is_bigendian else "<"
        types = {name: _field_dtype(fields[name], order) for name in "xyz"}
        color_name = next((name for name in COLOR_FIELDS if name in fields), None)
        if color_name is not None and _field_dtype(fields[color_name], order).itemsize != 4:
            raise MessageError(f"PointCloud2 field {color_name!r} must be 4 bytes (packed 0x00RRGGBB), got "
                               f"datatype {fields[color_name].datatype}")
        used = [*"xyz", color_name] if color_name else [*"xyz"]
        extent = max(fields[name].offset + (4 if name == color_name else types[name].itemsize) for name in used)
        if point_step < extent:
            raise MessageError(f"PointCloud2 point_step {point_step} is smaller than its fields "
                               f"(they need {extent} bytes)")
        if height > 1 and row_step < width * point_step:
            raise MessageError(f"PointCloud2 row_step {row_step} is smaller than width * point_step "
                               f"({width} * {point_step})")
        row_step = row_step if height > 1 else width * point_step  # one row: row_step never used
        buffer = np.frombuffer(msg.data, dtype=np.uint8)
        needed = row_step * (height - 1) + width * point_step if height and width else 0
        if buffer.size < needed:
            raise MessageError(f"PointCloud2 of {height}x{width} points (point_step {point_step}, row_step "
                               f"{row_step}) needs {needed} bytes of data, got {buffer.size}")
        count = height * width
        if count == 0:
            return PointCloud(np.empty((0, 3), np.float32), None if color_name is None else np.empty((0, 3), np.uint8),
                              header_stamp(msg.header), msg.header.frame_id)

        def column(offset: int, dtype: np.dtype) -> np.ndarray:
            return np.ndarray((height, width), dtype, buffer, offset, (row_step, point_step))

        x, y, z = (fields[name] for name in "xyz")
        spacing = y.offset - x.offset
        if types["x"] == types["y"] == types["z"] and spacing > 0 and z.offset - y.offset == spacing:
            xyz = np.ndarray((height, width, 3), types["x"], buffer, x.offset, (row_step, point_step, spacing))
        else:
            xyz = np.stack([column(fields[name].offset, types[name]) for name in "xyz"], axis=-1)
        points = xyz.reshape(count, 3).astype(np.float32, copy=False)  # a view when already float32
        if not points.flags.owndata:
            read_only(points)
        colors = None
        if color_name is not None:
            packed = column(fields[color_name].offset, np.dtype(order + "u4")).reshape(count)
            colors = np.empty((count, 3), dtype=np.uint8)
            colors[:, 0] = (packed >> 16) & 0xFF
            colors[:, 1] = (packed >> 8) & 0xFF
            colors[:, 2] = packed & 0xFF
        cloud = PointCloud(points, colors, header_stamp(msg.header), msg.header.frame_id,
                           (height, width) if height > 1 else None)
        return cloud.finite() if self.drop_invalid else cloud

    def to_ros(self, value: PointCloud) -> PointCloud2:
        self._check_value(value)
        points, colors = value.points, value.colors
        height, width = value.organized if value.organized is not None else (1, len(points))
        fields = [PointField(name=name, offset=4 * k, datatype=PointField.FLOAT32, count=1)
                  for k, name in enumerate("xyz")]
        words = np.empty((len(points), 3 if colors is None else 4), dtype="<u4")
        words[:, :3] = points.astype("<f4", copy=False).view("<u4")  # bit copies: NaN payloads kept
        if colors is not None:
            fields.append(PointField(name="rgb", offset=12, datatype=PointField.FLOAT32, count=1))
            packed = words[:, 3:].view(np.uint8)  # little-endian 0x00RRGGBB: bytes B, G, R, 0
            packed[:, :3] = colors[:, ::-1]
            packed[:, 3] = 0
        point_step = 4 * words.shape[1]
        return PointCloud2(header=make_header(value.stamp, value.frame_id), height=height, width=width,
                           fields=fields, is_bigendian=False, point_step=point_step, row_step=point_step * width,
                           data=typed_array(words, "B"), is_dense=value.is_dense)


def _field_dtype(field: PointField, order: str) -> np.dtype:
    try:
        code = FIELD_TYPES[field.datatype]
    except KeyError:
        raise MessageError(f"PointCloud2 field {field.name!r} has unknown datatype {field.datatype}") from None
    return np.dtype(code if code.endswith("1") else order + code)
