"""The typed encoding between hosts (coco_core.wire): plain data, numpy arrays and registered value
types come back as they left; nothing else is built, whatever the bytes say."""

from __future__ import annotations

import enum
import os
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import msgpack
import numpy as np
import pytest

from coco_core.errors import DeclarationError, PacketError, WrongTypeError
from coco_core.hosts.messages import Heartbeat, Stage
from coco_core.messages import Call, Outcome, Result
from coco_core.stamps import Stamp, Stamped, UserStamps
from coco_core.transforms.samples import FramePose, JointSample
from coco_core.wire import ARRAY, OBJECT, Decoder, Encoder, conforms, crossing_problem, value_type


@value_type
@dataclass(frozen=True)
class Reading:
    name: str
    values: tuple[float, ...]
    array: np.ndarray | None = None


@value_type
class Level(enum.Enum):
    LOW = "low"
    HIGH = "high"


@value_type
class Pair(NamedTuple):
    left: int
    right: Level


class Unregistered:
    pass


def roundtrip(value: object) -> object:
    return Decoder().decode(Encoder().encode(value))


@pytest.mark.parametrize("value", [0, -7, 2 ** 63 - 1, 1.5, float("inf"), True, None, "é", b"\x00\xff", [1, [2]],
                                   (1, (2, "3")), {"a": (1, 2), 3: [4], (5, 6): None}])
def test_plain_data_comes_back_as_it_left(value: object) -> None:
    back = roundtrip(value)
    assert back == value and type(back) is type(value)


def test_arrays_keep_dtype_shape_and_values_and_are_views_of_the_buffer() -> None:
    values = [np.arange(12, dtype=np.float32).reshape(3, 4), np.arange(10)[::3], np.zeros((0, 3)),
              np.array([True, False]), np.complex64(1 + 2j), np.int16(-3)]
    for value in values:
        back = roundtrip(value)
        assert type(back) is type(value) and np.asarray(back).dtype == np.asarray(value).dtype
        assert np.array_equal(back, value)
    big = np.arange(100_000, dtype=np.float64)
    data = bytearray(Encoder().encode(big))
    back = Decoder().decode(data)
    assert np.shares_memory(back, np.frombuffer(data, np.uint8))  # no copy of the received bytes


def test_the_projects_value_types_come_back_checked() -> None:
    stamp = Stamp(1.5, 3, "arm.joints", (("sent", 1.6),), 7, UserStamps({"box": (1, 2)}))
    for value in [Stamped(JointSample(("a", "b"), np.array([0.1, 0.2]), 4.0), stamp),
                  FramePose("base", "bowl", np.eye(4), None), Heartbeat(Stage.STOPPING, "why", False, True),
                  Call(id=2, process="view@graphics", component="tf", operation="lookup", args=("a", "b"),
                       kwargs={"at": 1.0}),
                  Result(2, Outcome(True, [1.0, 2.0])), Reading("r", (1.0, 2)), Pair(1, Level.HIGH)]:
        back = roundtrip(value)
        assert type(back) is type(value) and repr(back) == repr(value)


def test_stamps_change_clocks_on_the_way() -> None:
    stamp = Stamp(10.0, 1, "a.b", (("made", 11.0),))
    back = Decoder(lambda t: t - 100.0).decode(Encoder(lambda t: t + 1000.0).encode(Stamped(5, stamp)))
    assert back.stamp.time == 910.0 and back.stamp.steps == (("made", 911.0),)


def test_nothing_else_can_be_sent() -> None:
    for value in [Unregistered(), lambda: None, np.array([object()]), {1, 2}, 2 ** 64]:
        with pytest.raises((WrongTypeError, OverflowError)):
            Encoder().encode(value)
    with pytest.raises(DeclarationError, match="neither a dataclass, a named tuple nor an enum"):
        value_type(Unregistered)


def test_a_pickle_never_runs(tmp_path: Path) -> None:
    marker = tmp_path / "pwned"

    class Bomb:
        def __reduce__(self) -> tuple[object, ...]:
            return os.system, (f"touch {marker}",)

    for data in [pickle.dumps(Bomb()), b"\x00\x00\x00\x00" + bytes(8) + pickle.dumps(Bomb())]:
        with pytest.raises(PacketError):
            Decoder().decode(data)
    assert not marker.exists()


def framed(packed: bytes, *buffers: bytes) -> bytes:
    """An encoded value made by hand: the table, the packed part, the buffers."""
    import struct

    return struct.pack(f"<I{len(buffers) + 1}Q", len(buffers), len(packed), *map(len, buffers)) + packed + b"".join(
        buffers)


def extension(code: int, *items: object) -> msgpack.ExtType:
    return msgpack.ExtType(code, msgpack.packb(list(items)))


@pytest.mark.parametrize("forged, why", [
    (framed(msgpack.packb(extension(OBJECT, "os.system", "touch /tmp/x"))), "not a registered value type"),
    (framed(msgpack.packb(extension(OBJECT, f"{__name__}.Reading", 5, (1.0,), None))), "whose name is a int, not str"),
    (framed(msgpack.packb(extension(OBJECT, f"{__name__}.Reading", "r"))), "of 1 fields; it has 3"),
    (framed(msgpack.packb(extension(ARRAY, "|O", [1], 0, False)), bytes(8)), "dtype object"),
    (framed(msgpack.packb(extension(ARRAY, "<f8", [1000], 0, False)), bytes(8)), "in 8 bytes"),
    (framed(msgpack.packb(extension(ARRAY, "<f8", [1], 3, False)), bytes(8)), "in buffer 3 of 1"),
    (framed(msgpack.packb(msgpack.ExtType(99, b""))), "an extension 99 that this codec does not have"),
    (framed(b"\x92\x01"), "not a value"),
    (b"\x01\x00", "not a value"),
    (framed(b"\xc1"), "not a value"),
])
def test_forged_bytes_are_refused_with_what_they_are(forged: bytes, why: str) -> None:
    with pytest.raises(PacketError, match=why):
        Decoder().decode(forged)


def test_values_nested_too_deep_are_refused() -> None:
    deep: object = 1
    for _ in range(100):
        deep = (deep,)
    with pytest.raises(WrongTypeError, match="nested deeper"):
        Encoder().encode(deep)
    forged = msgpack.packb(1)
    for _ in range(100):
        forged = msgpack.packb(msgpack.ExtType(2, b"\x91" + forged))  # a tuple holding the one before
    with pytest.raises(PacketError, match="nested deeper"):
        Decoder().decode(framed(forged))


def test_conforms_and_crossing_problem_read_annotations_and_port_types() -> None:
    assert conforms(1, float) and conforms((1.0, 2.0), tuple[float, ...]) and conforms(None, float | None)
    assert not conforms("x", float) and not conforms((1, "a"), tuple[int, int]) and not conforms([1], tuple[int])
    assert conforms({"a": 1}, dict[str, int]) and not conforms({"a": "b"}, dict[str, int])
    assert crossing_problem(Stamped | FramePose) == "" and crossing_problem(object) == ""
    assert crossing_problem(float | int | np.ndarray) == ""
    assert "test_wire.Unregistered is not a registered value type" in crossing_problem(Unregistered | float)


def test_every_value_type_of_the_installed_packages_is_in_their_entry_points() -> None:
    """A reader's process finds a type it has not imported through the entry points alone: every
    type the packages register must be listed there, under its registered name."""
    import importlib
    import pkgutil

    from coco_core import wire

    for package in ("coco_core", "coco_ros", "coco_mr_vision", "coco_mr_haptics", "coco_mr_display"):
        try:
            root = importlib.import_module(package)
        except ImportError:  # a package this test's environment does not have
            continue
        for module in pkgutil.walk_packages(root.__path__, f"{package}."):
            if ".test" not in module.name:
                try:
                    importlib.import_module(module.name)
                except ImportError:  # a module that needs what this environment lacks (a display...)
                    pass
    installed = wire.installed_value_types()
    missing = [name for name, entry in wire._BY_NAME.items()
               if entry.cls.__module__ != __name__ and (name not in installed or installed[name].load() is not entry.cls)]
    assert missing == []


def test_a_type_whose_module_was_not_imported_is_found_by_its_entry_point() -> None:
    """A reader's process that never imported coco_core.transforms.samples still reads a
    JointSample: the decoder loads its module through the package's entry point."""
    import subprocess
    import sys

    data = Encoder().encode(JointSample(("a",), np.array([0.5]), 1.0))
    reader = ("import sys\nfrom coco_core.wire import Decoder\n"
              "assert 'coco_core.transforms.samples' not in sys.modules\n"
              "print(repr(Decoder().decode(sys.stdin.buffer.read())))")
    done = subprocess.run([sys.executable, "-c", reader], input=data, capture_output=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert b"JointSample(names=('a',), positions=array([0.5]), stamp=1.0)" in done.stdout
