"""``std_msgs/*MultiArray`` (Float64MultiArray and the other numeric ones) <-> numpy arrays.

The layout gives the shape: one axis per ``dim`` with its ``size``; ``dim[i + 1].stride`` is the
element stride of axis ``i`` and the last axis is contiguous, as ``MultiArrayLayout`` documents, and
``data_offset`` elements are skipped first. The array is a read-only strided view of the message's
data, never a copy. A message without dims is a 1-D array of its data. A layout whose strides are
left at 0 (a common shortcut of publishers that fill in the sizes only) is read as dense row-major.

Writing: dense row-major data with one dim per axis (size, stride = product of the sizes from that
axis on), labels from the converter's ``labels`` option (empty by default), ``data_offset`` 0; a 0-d
array is written as one element. Values are cast to the message's element type with numpy's
``same_kind`` rule: integers into a float array are fine, floats into an integer array are refused.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from coco_core.errors import MessageError, WrongTypeError
from std_msgs.msg import MultiArrayDimension, MultiArrayLayout

from .base import Converter, read_only, typed_array

#: message name -> (numpy dtype, array.array typecode of its data field)
ELEMENT_TYPES: dict[str, tuple[np.dtype, str]] = {
    "Float64MultiArray": (np.dtype(np.float64), "d"),
    "Float32MultiArray": (np.dtype(np.float32), "f"),
    "Int8MultiArray": (np.dtype(np.int8), "b"),
    "UInt8MultiArray": (np.dtype(np.uint8), "B"),
    "Int16MultiArray": (np.dtype(np.int16), "h"),
    "UInt16MultiArray": (np.dtype(np.uint16), "H"),
    "Int32MultiArray": (np.dtype(np.int32), "i"),
    "UInt32MultiArray": (np.dtype(np.uint32), "I"),
    "Int64MultiArray": (np.dtype(np.int64), "q"),
    "UInt64MultiArray": (np.dtype(np.uint64), "Q"),
}

TYPE_NAMES = tuple(f"std_msgs/msg/{name}" for name in ELEMENT_TYPES)


class MultiArrayConverter(Converter[object, np.ndarray]):
    """A ``std_msgs`` numeric MultiArray <-> numpy array; ``labels`` name the axes when writing."""

    type_name = "std_msgs/msg/Float64MultiArray"
    coco_type = np.ndarray

    def __init__(self, type_name: str = "std_msgs/msg/Float64MultiArray", labels: Sequence[str] = ()) -> None:
        name = type_name.rsplit("/", 1)[-1]
        if type_name not in TYPE_NAMES:
            raise MessageError(f"no multi-array converter for {type_name!r}; supported: {', '.join(TYPE_NAMES)}")
        self.type_name = type_name  # type: ignore[misc]  # one class serves every element type
        self.dtype, self.typecode = ELEMENT_TYPES[name]
        self.labels = tuple(str(label) for label in labels)

    def to_coco(self, msg: object) -> np.ndarray:
        self._check_message(msg)
        data = np.frombuffer(msg.data, dtype=self.dtype)  # type: ignore[attr-defined]
        layout = msg.layout  # type: ignore[attr-defined]
        offset, dims = layout.data_offset, layout.dim
        if not dims:
            if offset > len(data):
                raise MessageError(f"{self.type_name}: data_offset {offset} is past the {len(data)} elements")
            return read_only(data[offset:])
        shape = tuple(dim.size for dim in dims)
        if all(dim.stride == 0 for dim in dims):
            strides = tuple(int(np.prod(shape[k + 1:], dtype=np.int64)) for k in range(len(shape)))
        else:
            strides = tuple(dims[k + 1].stride for k in range(len(dims) - 1)) + (1,)
        extent = offset + sum((size - 1) * stride for size, stride in zip(shape, strides)) + 1 \
            if all(shape) else offset
        if extent > len(data):
            described = ", ".join(f"{dim.label or '?'}: size {dim.size} stride {dim.stride}" for dim in dims)
            raise MessageError(f"{self.type_name} layout ({described}; data_offset {offset}) needs {extent} "
                               f"elements, the data has {len(data)}")
        itemsize = self.dtype.itemsize
        array = np.ndarray(shape, self.dtype, data, offset * itemsize if all(shape) else 0,
                           tuple(stride * itemsize for stride in strides))
        return read_only(array)

    def to_ros(self, value: np.ndarray) -> object:
        array = np.atleast_1d(np.asarray(value))
        if array.dtype == object:
            raise WrongTypeError(f"{type(self).__name__} publishes numeric arrays, got {type(value).__name__}")
        try:
            array = np.ascontiguousarray(array.astype(self.dtype, casting="same_kind", copy=False))
        except TypeError as error:
            raise WrongTypeError(f"cannot publish {array.dtype} values as {self.type_name}: {error}") from None
        shape = array.shape
        dims = [MultiArrayDimension(label=self.labels[k] if k < len(self.labels) else "", size=size,
                                    stride=int(np.prod(shape[k:], dtype=np.int64)))
                for k, size in enumerate(shape)]
        msg = self.message_type(layout=MultiArrayLayout(dim=dims, data_offset=0))
        msg.data = typed_array(array, self.typecode)
        return msg
