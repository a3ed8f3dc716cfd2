"""Values across a trust boundary: an encoding that can only build plain data and registered types.

Between the processes of one launcher values are pickled (one host is one trust domain: same user,
0600 segments). A pickle can build any object and run any function, so nothing that comes from the
network may be unpickled: a sample whose pickle calls ``os.system`` ran its command on every host.
What crosses between hosts is encoded here instead, as MessagePack (``msgpack``: a
self-describing format whose decoder builds numbers, strings, bytes, lists and dicts only) with a
few extension types:

- numpy arrays by dtype and shape (numbers and booleans only, never ``object``), their bytes out of
  band: after the packed part, so that the reader's arrays are views of the received buffer, not
  copies, as with pickle's protocol 5 before;
- tuples (a frozen dataclass keeps its tuples), enums and :class:`~coco_core.stamps.Stamp` (its
  times converted between clocks on the way, :data:`Clock`);
- the project's own value types, by the name they were registered under (:func:`value_type`): a
  dataclass, a named tuple or an enum, rebuilt by calling the class with its fields, each field
  checked against the class's annotations first (a ``JointSample`` whose positions are a string is
  refused, not handed to a component). A name that this process has not registered yet (the module
  that defines it was not imported here) is looked up among the installed packages' entry points
  of the group :data:`GROUP`, and only there: a name from the network never imports anything else;
- whatever a codec adds (:class:`Encoder`'s ``extensions``: the RGB-D stream codec's JPEG and
  Zstandard images).

An unknown name, a dtype that is not a number, a shape that its bytes do not fill, a field of the
wrong type, nesting deeper than :data:`MAX_DEPTH`: :class:`~coco_core.errors.PacketError`, never
an object of another kind. A value that cannot be encoded (a class nobody registered) raises
:class:`~coco_core.errors.WrongTypeError` naming its type; :func:`crossing_problem` tells the
same from a port's declared type before anything runs (``--check``).
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import struct
import types
import typing
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import msgpack
import numpy as np

from importlib.metadata import EntryPoint, entry_points

from .errors import DeclarationError, PacketError, WrongTypeError
from .stamps import NO_USER_STAMPS, Stamp, Stamped, UserStamps

GROUP = "coco.value_types"
"""The entry point group that lists every value type of a package (name = ``module:Class``)."""

Clock = Callable[[float], float]
"""Converts a time in seconds from one clock to another (this process's ``perf_counter`` to the
application's clock on the writer's side, back on the reader's)."""

ARRAY, TUPLE, OBJECT, ENUM, STAMP = 1, 2, 3, 4, 5
FIRST_EXTENSION = 16
"""Extension codes from here on are a codec's own (:class:`Encoder`'s ``extensions``)."""
MAX_DEPTH = 32
"""Values nested deeper than this (registered objects, tuples) are refused: no honest value is."""
MAX_DIMENSIONS = 32
ARRAY_KINDS = "biufc"
"""numpy dtype kinds that cross: booleans, integers, unsigned integers, floats, complex numbers."""


def same_clock(seconds: float) -> float:
    """The default :data:`Clock`: both sides' times are the same."""
    return seconds


@dataclass(frozen=True)
class ValueType:
    """A class whose values may cross between hosts, and how: its registered ``name``, the values
    that rebuild it (``reduce``) and what rebuilds it from them (``build``)."""

    name: str
    cls: type
    reduce: Callable[[Any], Sequence[Any]]
    build: Callable[..., Any]
    fields: tuple[str, ...] = ()
    """The names of the values ``reduce`` gives, when they are the class's annotated fields:
    checked against its annotations when they arrive."""

    @functools.cached_property
    def hints(self) -> dict[str, Any]:
        """The annotations of :attr:`fields` (empty when they cannot be resolved: then only plain
        data reaches ``build``, unchecked by field)."""
        try:
            hints = typing.get_type_hints(self.cls)
        except Exception:  # an annotation names a type imported for the type checker only
            return {}
        return {name: hints[name] for name in self.fields if name in hints}


_BY_NAME: dict[str, ValueType] = {}
_BY_CLASS: dict[type, ValueType] = {}


def value_type(cls: type | None = None, *, name: str = "", reduce: Callable[[Any], Sequence[Any]] | None = None,
               build: Callable[..., Any] | None = None) -> Any:
    """Register ``cls`` as a value type that may cross between hosts (a class decorator; put it
    above ``@dataclass``). A dataclass crosses as its ``init`` fields, a named tuple as its fields,
    an enum as its value; any other class needs ``reduce`` (the values) and ``build`` (the class
    from them). ``name`` defaults to the module and qualified name of the class. List it in its
    package's entry points too (group :data:`GROUP`, ``module.Class = module:Class``), so that a
    process that has not imported its module yet can read it."""

    def register(registered: type) -> type:
        fields: tuple[str, ...] = ()
        reducer, builder = reduce, build or registered
        if reducer is None:
            if issubclass(registered, enum.Enum):
                reducer = _enum_value
            elif dataclasses.is_dataclass(registered):
                fields = tuple(field.name for field in dataclasses.fields(registered) if field.init)
                reducer = _attributes(fields)
            elif issubclass(registered, tuple) and hasattr(registered, "_fields"):
                fields = tuple(registered._fields)
                reducer = tuple
            else:
                raise DeclarationError(f"{registered.__qualname__} is neither a dataclass, a named tuple nor an enum: "
                                       "value_type needs its reduce and build")
        key = name or f"{registered.__module__}.{registered.__qualname__}"
        known = _BY_NAME.get(key)
        if known is not None and known.cls is not registered:
            raise DeclarationError(f"value type name {key!r} is already {known.cls.__module__}.{known.cls.__qualname__}")
        entry = ValueType(key, registered, reducer, builder, fields)
        _BY_NAME[key] = entry
        _BY_CLASS[registered] = entry
        return registered

    return register if cls is None else register(cls)


def registered(cls: type) -> ValueType | None:
    """How ``cls`` crosses, if it was registered."""
    return _BY_CLASS.get(cls)


def _enum_value(member: enum.Enum) -> tuple[Any]:
    return (member.value,)


def _attributes(names: tuple[str, ...]) -> Callable[[Any], tuple[Any, ...]]:
    def reduce(value: Any) -> tuple[Any, ...]:
        return tuple(getattr(value, name) for name in names)
    return reduce


value_type(UserStamps, reduce=lambda stamps: (dict(stamps),), build=UserStamps)
value_type(Stamped)


@functools.lru_cache(maxsize=64)
def _table(parts: int) -> struct.Struct:
    """What leads an encoded value: the number of out-of-band buffers, the packed part's length,
    then each buffer's."""
    return struct.Struct(f"<I{parts + 1}Q")


_COUNT = struct.Struct("<I")


Pack = Callable[[Any], bytes]
"""Packs a value as the encoder does (what an extension packs its parts with)."""
Unpack = Callable[[bytes], Any]


class Encoder:
    """Encodes values for another host (see the module's docstring). One per sending end, used by
    one thread at a time. ``extensions`` maps a class to what makes its :class:`msgpack.ExtType`
    (codes from :data:`FIRST_EXTENSION`) of a value and :data:`Pack`, ahead of its registration."""

    def __init__(self, clock: Clock = same_clock,
                 extensions: Mapping[type, Callable[[Any, Pack], msgpack.ExtType]] = {}) -> None:
        self.clock = clock
        self.extensions = dict(extensions)
        self._buffers: list[memoryview] = []
        self._packers: list[msgpack.Packer] = []
        """One packer per level of nesting: a registered value's fields are packed while its
        container's packer is in the middle of its own work (making one per value cost a third of
        a small value's encoding)."""
        self._depth = 0

    def encode(self, value: Any) -> bytes:
        """``value`` as bytes: the table of lengths, the packed value, its arrays' bytes."""
        buffers = self._buffers
        try:
            packed = self._pack(value)
            table = _table(len(buffers)).pack(len(buffers), len(packed), *(buffer.nbytes for buffer in buffers))
            return b"".join((table, packed, *buffers))
        finally:
            buffers.clear()

    def _pack(self, value: Any) -> bytes:
        depth = self._depth
        if depth == len(self._packers):
            if depth > MAX_DEPTH:
                raise WrongTypeError(f"a value nested deeper than {MAX_DEPTH} cannot cross between hosts")
            self._packers.append(self._packer())
        self._depth = depth + 1
        try:
            return self._packers[depth].pack(value)
        except BaseException:
            self._packers[depth] = self._packer()  # one interrupted keeps what it had packed
            raise
        finally:
            self._depth = depth

    def _packer(self) -> msgpack.Packer:
        return msgpack.Packer(default=self._default, strict_types=True, use_bin_type=True, datetime=False)

    def _default(self, value: Any) -> msgpack.ExtType:
        kind = type(value)
        extension = self.extensions.get(kind)
        if extension is not None:
            return extension(value, self._pack)
        if kind is tuple:
            return msgpack.ExtType(TUPLE, self._pack(list(value)))
        if kind is Stamp:
            clock = self.clock
            return msgpack.ExtType(STAMP, self._pack([clock(value.time), value.seq, value.source,
                                                      [[name, clock(at)] for name, at in value.steps], value.it,
                                                      dict(value.user)]))
        if kind is np.ndarray or isinstance(value, np.generic):
            return self._array(value)
        entry = _BY_CLASS.get(kind)
        if entry is not None:
            code = ENUM if isinstance(value, enum.Enum) else OBJECT
            return msgpack.ExtType(code, self._pack([entry.name, *entry.reduce(value)]))
        raise WrongTypeError(f"a {kind.__module__}.{kind.__qualname__} cannot cross between hosts: only numbers, "
                             "strings, bytes, lists, tuples, dicts, numpy arrays of numbers and registered value "
                             "types (coco_core.wire.value_type) can")

    def _array(self, value: Any) -> msgpack.ExtType:
        array = np.asarray(value)
        if not array.flags.c_contiguous:
            array = np.ascontiguousarray(array)
        if array.dtype.kind not in ARRAY_KINDS:
            raise WrongTypeError(f"a numpy array of dtype {array.dtype} cannot cross between hosts: only arrays of "
                                 "numbers and booleans can")
        scalar = not isinstance(value, np.ndarray)
        self._buffers.append(array.data.cast("B") if array.nbytes else memoryview(b""))
        return msgpack.ExtType(ARRAY, self._pack([array.dtype.str, list(array.shape), len(self._buffers) - 1,
                                                  scalar]))


class Decoder:
    """Decodes what an :class:`Encoder` made (see the module's docstring); ``extensions`` maps a
    codec's extension codes to what rebuilds their values from the extension's bytes and
    :data:`Unpack`."""

    def __init__(self, clock: Clock = same_clock, extensions: Mapping[int, Callable[[bytes, Unpack], Any]] = {}
                 ) -> None:
        self.clock = clock
        self.extensions = dict(extensions)

    def decode(self, data: Any) -> Any:
        """The value encoded in ``data`` (a buffer); its arrays are views of ``data``'s memory.
        :class:`PacketError` when it is not such a value."""
        try:
            view = memoryview(data).cast("B")
            count = _COUNT.unpack_from(view)[0]
            if count > len(view) // 8:
                raise PacketError("garbage", f"{len(view)} bytes cannot hold {count} buffers")
            table = _table(count)
            _, packed, *lengths = table.unpack_from(view)
            at = table.size + packed
            if at + sum(lengths) != len(view):
                raise PacketError("garbage", f"{len(view)} bytes, where the table says {at + sum(lengths)}")
            buffers = []
            for length in lengths:
                buffers.append(view[at:at + length])
                at += length
            return _Reading(self, buffers).unpack(view[table.size:table.size + packed])
        except PacketError:
            raise
        except Exception as error:  # whatever damaged bytes make msgpack, numpy or a class raise
            raise PacketError("garbage", f"not a value ({type(error).__name__}: {error})") from None


class _Reading:
    """One :meth:`Decoder.decode`: its buffers and how deep it is."""

    def __init__(self, decoder: Decoder, buffers: list[memoryview]) -> None:
        self.decoder = decoder
        self.buffers = buffers
        self.depth = 0

    def unpack(self, data: Any) -> Any:
        return msgpack.unpackb(data, ext_hook=self._extension, raw=False, strict_map_key=False, use_list=True,
                               timestamp=0)

    def _extension(self, code: int, data: bytes) -> Any:
        self.depth += 1
        try:
            if self.depth > MAX_DEPTH:
                raise PacketError("garbage", f"values nested deeper than {MAX_DEPTH}")
            if code >= FIRST_EXTENSION:
                extension = self.decoder.extensions.get(code)
                if extension is None:
                    raise PacketError("garbage", f"an extension {code} that this codec does not have")
                return extension(data, self.unpack)
            items = self.unpack(data)
            if type(items) is not list:
                raise PacketError("garbage", f"extension {code} holds a {type(items).__name__}")
            if code == TUPLE:
                return tuple(items)
            if code == ARRAY:
                return self._array(*items)
            if code == STAMP:
                return self._stamp(*items)
            if code in (OBJECT, ENUM) and items and type(items[0]) is str:
                return _build(items[0], items[1:])
            raise PacketError("garbage", f"an unknown extension {code}")
        finally:
            self.depth -= 1

    def _array(self, dtype: str, shape: list[int], index: int, scalar: bool) -> Any:
        kind = np.dtype(dtype)
        if kind.kind not in ARRAY_KINDS:
            raise PacketError("garbage", f"an array of dtype {kind}: only numbers cross")
        if (type(shape) is not list or len(shape) > MAX_DIMENSIONS
                or not all(type(size) is int and size >= 0 for size in shape)):
            raise PacketError("garbage", f"an array of shape {shape!r}")
        if type(index) is not int or not 0 <= index < len(self.buffers):
            raise PacketError("garbage", f"an array in buffer {index!r} of {len(self.buffers)}")
        buffer = self.buffers[index]
        if int(np.prod(shape, dtype=np.int64)) * kind.itemsize != buffer.nbytes:
            raise PacketError("garbage", f"an array of shape {tuple(shape)} and dtype {kind} in {buffer.nbytes} bytes")
        array = np.frombuffer(buffer, dtype=kind).reshape(shape)
        return array[()] if scalar else array

    def _stamp(self, time: float, seq: int, source: str, steps: list[list[Any]], it: int,
               user: dict[str, Any]) -> Stamp:
        clock = self.decoder.clock
        if not (isinstance(time, float) and type(seq) is int and type(source) is str and type(it) is int
                and type(user) is dict and type(steps) is list
                and all(type(step) is list and len(step) == 2 and type(step[0]) is str and isinstance(step[1], float)
                        for step in steps)):
            raise PacketError("garbage", "a stamp whose fields are not a stamp's")
        return Stamp(clock(time), seq, source, tuple((name, clock(at)) for name, at in steps), it,
                     UserStamps(user) if user else NO_USER_STAMPS)


@functools.cache
def installed_value_types() -> dict[str, EntryPoint]:
    """The value types the installed packages declare (:data:`GROUP`), by name."""
    return {point.name: point for point in entry_points(group=GROUP)}


def _registration(name: str) -> ValueType | None:
    """The value type registered as ``name``, its module imported first when only an installed
    package's entry point names it."""
    entry = _BY_NAME.get(name)
    if entry is None and (point := installed_value_types().get(name)) is not None:
        point.load()  # its module registers it (@value_type)
        entry = _BY_NAME.get(name)
    return entry


def _build(name: str, values: list[Any]) -> Any:
    entry = _registration(name)
    if entry is None:
        raise PacketError("garbage", f"a value of type {name[:100]!r}, which is not a registered value type here "
                                     f"(entry points {GROUP})")
    hints = entry.hints
    if hints:
        if len(values) != len(entry.fields):
            raise PacketError("garbage", f"a {name} of {len(values)} fields; it has {len(entry.fields)}")
        for field, value in zip(entry.fields, values):
            hint = hints.get(field)
            if hint is not None and not conforms(value, hint):
                raise PacketError("garbage", f"a {name} whose {field} is a {type(value).__name__}, not {_name(hint)}")
    try:
        return entry.build(*values)
    except PacketError:
        raise
    except Exception as error:  # the class's own checks refused the values
        raise PacketError("garbage", f"a {name} that its class refuses: {type(error).__name__}: {error}") from None


def conforms(value: Any, hint: Any) -> bool:
    """Whether ``value`` is of the annotated type ``hint``, as far as an annotation says: a class
    (an ``int`` will do for a ``float``), ``X | Y``, ``Optional``, ``tuple[...]``, ``list[X]``,
    ``dict[K, V]`` and generic classes by their origin; anything else (``Any``, a type variable)
    accepts every value."""
    return _checker(hint)(value)


Check = Callable[[Any], bool]


def _anything(value: Any) -> bool:
    return True


@functools.lru_cache(maxsize=512)
def _checker(hint: Any) -> Check:
    """The check of ``hint`` (:func:`conforms`), made once per annotation: walking an annotation for
    every value was most of a small value's decoding."""
    if hint is Any or hint is object or isinstance(hint, typing.TypeVar):
        return _anything
    if hint is float:
        return lambda value: isinstance(value, (float, int, np.floating))
    if hint is None or hint is type(None):
        return lambda value: value is None
    origin = typing.get_origin(hint)
    arguments = typing.get_args(hint)
    if origin is None:
        return (lambda value: isinstance(value, hint)) if isinstance(hint, type) else _anything
    if origin is typing.Union or origin is types.UnionType:
        options = tuple(map(_checker, arguments))
        return lambda value: any(check(value) for check in options)
    if origin is typing.Literal:
        return lambda value: value in arguments
    if origin is tuple:
        if len(arguments) == 2 and arguments[1] is Ellipsis:
            item = _checker(arguments[0])
            return lambda value: type(value) is tuple and all(map(item, value))
        items = tuple(map(_checker, arguments))
        return lambda value: (type(value) is tuple and len(value) == len(items)
                              and all(check(part) for check, part in zip(items, value)))
    if origin is list:
        item = _checker(arguments[0]) if arguments else _anything
        return lambda value: type(value) is list and all(map(item, value))
    if origin is dict:
        key, entry = (_checker(arguments[0]), _checker(arguments[1])) if arguments else (_anything, _anything)
        return lambda value: type(value) is dict and all(key(k) and entry(v) for k, v in value.items())
    if isinstance(origin, type):
        return lambda value: isinstance(value, origin)
    return _anything


def _name(hint: Any) -> str:
    return getattr(hint, "__qualname__", None) or str(hint)


_PLAIN = (bool, int, float, str, bytes, list, tuple, dict, type(None), np.ndarray, Stamp)


def crossing_problem(declared: Any) -> str:
    """Why values of a port's ``declared`` type cannot cross between hosts ("" when they can, or
    when the declaration does not say: ``object``, ``Any``, a type variable; such values are checked
    as they are sent). ``X | Y``: each must."""
    origin = typing.get_origin(declared)
    if origin is typing.Union or origin is types.UnionType:
        return "; ".join(problem for problem in map(crossing_problem, typing.get_args(declared)) if problem)
    if origin is not None:
        declared = origin
    if declared is Any or declared is object or not isinstance(declared, type):
        return ""
    if declared in _PLAIN or issubclass(declared, np.generic) or declared in _BY_CLASS:
        return ""
    return (f"{declared.__module__}.{declared.__qualname__} is not a registered value type (coco_core.wire.value_type): "
            "its values cannot cross between hosts")
