"""Recorded CDR bytes -> rclpy message objects, by a decoder generated once per message type.

rclpy's ``deserialize_message`` builds every message, nested ones included, through its Python
constructor and property setters: 25-55 us for an Imu, an Odometry or a two-transform TFMessage,
2-3.5x what the ``rosbags`` library takes to decode the same bytes into its own classes. A bag
reader that hands out rclpy messages was therefore slower than ``rosbags`` however fast it read.

Here the layout of a type (``__slots__`` and ``SLOT_TYPES``, rosidl's own description of the
generated class) is turned into Python source once: runs of fixed-size fields read by one
``struct`` format, strings and sequences by their length prefix, fixed numeric arrays as numpy
arrays and numeric sequences as ``array.array`` (rclpy's own representations), nested messages by
their own generated function; the message is made with ``__new__`` and its slots assigned directly,
as the generated ``__init__`` would leave them. The result compares equal to rclpy's (the tests
check every type of the bags they read).

The encoding is ROS 2's CDR, little endian (XCDR1): a 4-byte encapsulation header, then each value
aligned to its own size (at most 8) from the end of the header; a string is a uint32 length
(with the terminating NUL) and the bytes; a sequence a uint32 count and the elements (an empty
sequence of 8-byte values has no padding after its count: Fast CDR aligns elements, not counts).

Types whose fields this does not decode (wide strings, octets, chars, bounded arrays of booleans,
big-endian data) keep rclpy's decoder, and so does a message whose bytes this decoder cannot read
(truncated, say): rclpy then raises what it always raised.
"""

from __future__ import annotations

import array
import struct
import sys
import threading
from typing import Any, Callable

import numpy as np

from coco_core.errors import CocoError

_BASIC = {  # rosidl basic type -> (struct code, size, array typecode, numpy dtype)
    "boolean": ("?", 1, "", None),
    "int8": ("b", 1, "b", np.int8), "uint8": ("B", 1, "B", np.uint8),
    "int16": ("h", 2, "h", np.int16), "uint16": ("H", 2, "H", np.uint16),
    "int32": ("i", 4, "i", np.int32), "uint32": ("I", 4, "I", np.uint32),
    "int64": ("q", 8, "q", np.int64), "uint64": ("Q", 8, "Q", np.uint64),
    "float": ("f", 4, "f", np.float32), "double": ("d", 8, "d", np.float64),
}
_LOCK = threading.Lock()
_FUNCTIONS: dict[type, str] = {}
"""Message class -> the name of its generated function in ``_NAMESPACE``."""
_DECODERS: dict[type, Callable[[bytes], Any]] = {}
_NAMESPACE: dict[str, Any] = {"unpack_from": struct.unpack_from, "np": np, "array": array.array,
                              "new": object.__new__}


class _Unsupported(CocoError):
    """A field this decoder does not read: the type keeps rclpy's decoder (caught in this module)."""


def message_decoder(cls: type) -> Callable[[bytes], Any]:
    """CDR bytes -> a message of ``cls``: the generated decoder, or rclpy's for what it does not read
    (made once per class)."""
    found = _DECODERS.get(cls)
    if found is None:
        found = _DECODERS.setdefault(cls, _decoder(cls))
    return found


def _decoder(cls: type) -> Callable[[bytes], Any]:
    from rclpy.serialization import deserialize_message

    try:
        with _LOCK:
            function = _NAMESPACE[_generate(cls)]
    except _Unsupported:
        return lambda data: deserialize_message(data, cls)

    def decode(data: bytes) -> Any:
        view = memoryview(data)
        if len(view) < 4 or view[1] != 1:  # not little-endian CDR: rclpy's decoder says what it is
            return deserialize_message(data, cls)
        try:
            return function(view[4:], 0)[0]
        except (struct.error, ValueError, IndexError, UnicodeDecodeError):
            return deserialize_message(data, cls)  # damaged bytes: rclpy raises as it always did

    return decode


def _generate(cls: type) -> str:
    """The name of ``cls``'s decoding function, generating it (and its nested types') when needed."""
    name = _FUNCTIONS.get(cls)
    if name is not None:
        return name
    name = f"_decode_{len(_FUNCTIONS)}_{cls.__name__}"
    slots = [slot for slot in getattr(cls, "__slots__", ()) if slot != "_check_fields"]
    types = list(getattr(cls, "SLOT_TYPES", ()))
    if len(slots) != len(types):
        raise _Unsupported(f"{cls.__name__}: slots and SLOT_TYPES differ")
    lines = [f"def {name}(view, pos):", "    m = new(C)"]
    run: list[tuple[str, str, int]] = []  # fixed-size fields read together: (slot, code, size)

    def flush() -> None:
        if not run:
            return
        first = run[0][2]
        if first > 1:
            lines.append(f"    pos = (pos + {first - 1}) & -{first}")
        fmt, offset = "<", 0
        for _, code, size in run:
            padding = -offset % size
            fmt += "x" * padding + code
            offset += padding + size
        targets = ", ".join(f"m.{slot}" for slot, _, _ in run)
        lines.append(f"    {targets}{',' if len(run) == 1 else ''} = unpack_from({fmt!r}, view, pos)")
        lines.append(f"    pos += {offset}")
        run.clear()

    for slot, slot_type in zip(slots, types):
        kind = type(slot_type).__name__
        if kind == "BasicType":
            code, size, _, _ = _basic(slot_type.typename)
            if run and size > run[0][2]:  # its alignment would depend on where the run starts
                flush()
            run.append((slot, code, size))
            continue
        flush()
        lines.extend(f"    {line}" for line in _field(slot, slot_type, kind))
    flush()
    check = getattr(sys.modules.get(cls.__module__), "ros_python_check_fields", "") == "1"
    lines.append(f"    m._check_fields = {check}")
    lines.append("    return m, pos")
    exec(compile("\n".join(lines), f"<cdr decoder of {cls.__module__}.{cls.__name__}>", "exec"),
         {**_NAMESPACE, "C": cls}, _NAMESPACE)
    _FUNCTIONS[cls] = name
    return name


def _basic(typename: str) -> tuple[str, int, str, Any]:
    if typename not in _BASIC:
        raise _Unsupported(f"basic type {typename}")
    return _BASIC[typename]


def _nested(slot_type: Any) -> str:
    import importlib

    module = importlib.import_module(".".join(slot_type.namespaces))
    return _generate(getattr(module, slot_type.name))


def _string() -> list[str]:
    """Lines that leave the string at ``pos`` in ``s``."""
    return ["pos = (pos + 3) & -4", "n, = unpack_from('<I', view, pos)",
            "s = str(view[pos + 4:pos + 3 + n], 'utf-8') if n else ''", "pos += 4 + n"]


def _field(slot: str, slot_type: Any, kind: str) -> list[str]:
    """Source lines that read one field that is not a basic value into ``m.<slot>``."""
    if kind in ("UnboundedString", "BoundedString"):
        return [*_string(), f"m.{slot} = s"]
    if kind == "NamespacedType":
        return [f"m.{slot}, pos = {_nested(slot_type)}(view, pos)"]
    if kind not in ("Array", "UnboundedSequence", "BoundedSequence"):
        raise _Unsupported(kind)
    element = slot_type.value_type
    element_kind = type(element).__name__
    lines = [f"count = {slot_type.size}"] if kind == "Array" else \
        ["pos = (pos + 3) & -4", "count, = unpack_from('<I', view, pos)", "pos += 4"]
    if element_kind == "BasicType":
        code, size, typecode, dtype = _basic(element.typename)
        if not typecode:
            raise _Unsupported("arrays of booleans")
        if size > 1:  # Fast CDR aligns the elements only when there are some
            lines.append(f"if count: pos = (pos + {size - 1}) & -{size}")
        if kind == "Array":  # rclpy: a numpy array of the element's dtype
            _NAMESPACE[f"dtype_{typecode}"] = dtype
            lines.append(f"m.{slot} = np.frombuffer(view, dtype_{typecode}, count, pos).copy()")
        else:  # rclpy: an array.array of the element's typecode
            lines += [f"a = array({typecode!r})", f"a.frombytes(view[pos:pos + count * {size}])", f"m.{slot} = a"]
        return lines + [f"pos += count * {size}"]
    if element_kind in ("UnboundedString", "BoundedString"):
        return lines + ["items = []", "for _ in range(count):",
                        *(f"    {line}" for line in _string()), "    items.append(s)", f"m.{slot} = items"]
    if element_kind == "NamespacedType":
        function = _nested(element)
        return lines + ["items = []", "for _ in range(count):", f"    item, pos = {function}(view, pos)",
                        "    items.append(item)", f"m.{slot} = items"]
    raise _Unsupported(f"arrays of {element_kind}")
