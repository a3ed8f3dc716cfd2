"""Canonical CDR bytes of an rclpy message, so generated bags are reproducible byte for byte.

rclpy's ``serialize_message`` (Fast CDR) leaves alignment padding uninitialised and pads the end to
8 bytes: two serialisations of equal messages can differ, and ``rosbags`` rejects a JointState that
ends with an empty ``effort`` ("CDR message size mismatch"). Here the message is converted field by
field to the ``rosbags`` (Jazzy type store) class and serialised by rosbags, which zeroes padding
and ends the buffer at the last field. rclpy reads these bytes back unchanged.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import numpy as np

_DTYPES = {
    "double": np.float64, "float": np.float32, "int8": np.int8, "uint8": np.uint8, "int16": np.int16,
    "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64,
    "octet": np.uint8, "char": np.uint8, "boolean": np.bool_,
}


@lru_cache(maxsize=1)
def _store():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def _type_name(message: Any) -> str:
    module = type(message).__module__.split(".")[0]
    return f"{module}/msg/{type(message).__name__}"


def _convert(message: Any) -> Any:
    store = _store()
    cls = store.types[_type_name(message)]
    values = {}
    for name, kind in message.get_fields_and_field_types().items():
        value = getattr(message, name)
        base = kind.split("<", 1)[1].rstrip(">") if kind.startswith("sequence<") else kind.split("[", 1)[0]
        base = base.split(",", 1)[0]
        if "/" in base:
            values[name] = [_convert(v) for v in value] if base != kind else _convert(value)
        elif base in _DTYPES and base != kind:
            values[name] = np.asarray(value, dtype=_DTYPES[base])
        elif base.startswith("string") and base != kind:
            values[name] = list(value)
        else:
            values[name] = value
    return cls(**values)


def canonical_cdr(message: Any) -> tuple[bytes, str]:
    """``(bytes, 'pkg/msg/Name')``: the message as zero-padded little-endian CDR."""
    type_name = _type_name(message)
    return bytes(_store().serialize_cdr(_convert(message), type_name)), type_name
