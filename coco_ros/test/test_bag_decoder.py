"""The generated CDR decoder gives the messages rclpy's ``deserialize_message`` gives: every message
type of std_msgs, geometry_msgs, sensor_msgs, nav_msgs and tf2_msgs, filled with random values
(strings of varying length shift every later field's alignment), serialised by rclpy; damaged bytes
raise as rclpy raises; types it does not read keep rclpy's decoder."""

from __future__ import annotations

import importlib
import inspect
import string

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message

from coco_ros.bag.cdr_decoder import message_decoder

PACKAGES = ("std_msgs", "geometry_msgs", "sensor_msgs", "nav_msgs", "tf2_msgs")
INTEGERS = {"int8": (-128, 127), "uint8": (0, 255), "int16": (-2**15, 2**15 - 1), "uint16": (0, 2**16 - 1),
            "int32": (-2**31, 2**31 - 1), "uint32": (0, 2**32 - 1), "int64": (-2**63, 2**63 - 1),
            "uint64": (0, 2**64 - 1)}
DTYPES = {"int8": np.int8, "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16, "int32": np.int32,
          "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64, "float": np.float32, "double": np.float64}


def message_classes() -> list[type]:
    classes = []
    for package in PACKAGES:
        module = importlib.import_module(f"{package}.msg")
        classes += [cls for _, cls in inspect.getmembers(module, inspect.isclass) if hasattr(cls, "SLOT_TYPES")]
    return classes


def random_value(slot_type, rng: np.random.Generator):
    kind = type(slot_type).__name__
    if kind == "BasicType":
        name = slot_type.typename
        if name in INTEGERS:
            low, high = INTEGERS[name]
            return int(rng.integers(low, high, endpoint=True, dtype=np.int64 if name != "uint64" else np.uint64))
        if name == "boolean":
            return bool(rng.integers(2))
        if name in ("float", "double"):
            return float(np.float32(rng.normal() * 100)) if name == "float" else float(rng.normal() * 100)
        if name == "octet":
            return bytes([int(rng.integers(256))])
        if name == "char":
            return chr(int(rng.integers(32, 127)))
        raise AssertionError(name)
    if kind in ("UnboundedString", "BoundedString"):
        length = int(rng.integers(0, 12))
        return "".join(rng.choice(list(string.ascii_letters + "é/_"), length)) if length else ""
    if kind == "NamespacedType":
        cls = getattr(importlib.import_module(".".join(slot_type.namespaces)), slot_type.name)
        return random_message(cls, rng)
    element = slot_type.value_type
    count = slot_type.size if kind == "Array" else int(rng.integers(0, 5))
    if type(element).__name__ == "BasicType" and element.typename in DTYPES:
        values = [random_value(element, rng) for _ in range(count)]
        return np.array(values, dtype=DTYPES[element.typename]) if kind == "Array" else values
    return [random_value(element, rng) for _ in range(count)]


def random_message(cls: type, rng: np.random.Generator):
    names = list(cls.get_fields_and_field_types())
    return cls(**{name: random_value(slot_type, rng) for name, slot_type in zip(names, cls.SLOT_TYPES)})


@pytest.mark.parametrize("cls", message_classes(), ids=lambda cls: f"{cls.__module__.split('.')[0]}/{cls.__name__}")
def test_decoded_like_rclpy(cls):
    rng = np.random.default_rng(abs(hash(cls.__name__)) % 2**32)
    decode = message_decoder(cls)
    for _ in range(20):
        data = serialize_message(random_message(cls, rng))
        ours, theirs = decode(data), deserialize_message(data, cls)
        assert ours == theirs, f"{cls.__name__}: {ours} != {theirs}"
        for name in cls.get_fields_and_field_types():  # the same representations (numpy, array.array, list)
            assert type(getattr(ours, name)) is type(getattr(theirs, name)), name


def test_damaged_bytes_give_what_rclpy_gives():
    """Cut anywhere: the same error as rclpy's, or, where rclpy still reads a message (a cut in the
    trailing empty sequences), the same message."""
    from sensor_msgs.msg import JointState

    data = serialize_message(JointState(name=["shoulder", "elbow"], position=[1.0, 2.0], velocity=[0.5, 0.25]))
    decode = message_decoder(JointState)
    raised = 0
    for cut in range(len(data)):
        try:
            theirs = deserialize_message(data[:cut], JointState)
        except Exception as error:  # rclpy's RMWError: ours must be the same
            raised += 1
            with pytest.raises(type(error)) as ours:
                decode(data[:cut])
            assert str(ours.value) == str(error)
        else:
            assert decode(data[:cut]) == theirs, cut
    assert raised > len(data) // 2


def test_a_type_it_does_not_read_keeps_rclpys_decoder():
    from std_msgs.msg import Byte, Char

    for message in (Byte(data=b"\x07"), Char(data=65)):
        data = serialize_message(message)
        assert message_decoder(type(message))(data) == message


def test_bag_messages_are_decoded_by_it(tmp_path):
    """What BagReader hands out as ``message`` is this decoder's, equal to rclpy's."""
    from nav_msgs.msg import Odometry

    from coco_ros.bag import BagReader, BagWriter

    rng = np.random.default_rng(3)
    written = [random_message(Odometry, rng) for _ in range(10)]
    with BagWriter(tmp_path / "bag") as writer:
        for i, message in enumerate(written):
            writer.write("/odom", message, 1_000 + i)
    with BagReader(tmp_path / "bag") as reader:
        read = [m.message for m in reader.messages()]
    assert read == written
