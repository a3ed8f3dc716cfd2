"""Declared, typed component attributes.

An attribute is declared once on the class with its type, default and constraints; the same
declaration parses the text an XML file gives, validates values set from code or at run time, and
documents the component. Errors name the component, the attribute and what was expected.
"""

from __future__ import annotations

import enum
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Generic, Sequence, TypeVar, get_args, get_origin
from .errors import AttributeValueError, FileReadError, bounded, excerpt
from .files import DATA_FILE_LIMIT, check_regular_file

if TYPE_CHECKING:
    from .component import Component

T = TypeVar("T")

_TRUE = {"true", "1", "yes", "on"}
_FALSE = {"false", "0", "no", "off"}


def _shown(value: Any) -> str:
    """``value`` as an error quotes it, cut short: a value may come from a service call or a file,
    and is never echoed whole into a log or a reply."""
    return excerpt(value) if isinstance(value, str) else bounded(repr(value), 120)


def _parse_bool(text: str) -> bool:
    word = text.strip().lower()
    if word in _TRUE:
        return True
    if word in _FALSE:
        return False
    raise AttributeValueError(f"expected a boolean (true/false/1/0/yes/no/on/off), got {_shown(text)}")


def _split_list(text: str) -> list[str]:
    # CoCo files write vectors as "1, 2,3,  5": commas and/or spaces separate the items.
    return [item for item in text.replace(",", " ").split() if item]


class Attribute(Generic[T]):
    """A typed attribute of a component, settable from XML and at run time.

    ``type_`` is ``int``, ``float``, ``bool``, ``str``, ``Path``, an ``enum.Enum`` subclass, or
    ``list[X]`` / ``tuple[X, ...]`` of one of those. ``choices``, ``min`` and ``max`` constrain the
    value; ``check`` is any further validation that returns an error text or None. ``live``: the
    component reads it while it runs (every update), so a change at run time takes effect; the ROS
    launcher offers only those as writable parameters (:mod:`coco_ros.component_parameters`).

    A float is finite unless ``finite=False`` (then the doc should say what NaN or an infinity
    means): NaN passes every ``min``/``max`` comparison, so ``stiffness:=nan`` or ``1e999`` (which
    parses as an infinity) would reach the component and fault it at run time; refusing them here,
    once, covers every component.
    """

    def __init__(
        self,
        type_: Any,
        default: T,
        doc: str = "",
        *,
        choices: Sequence[T] | None = None,
        min: float | None = None,
        max: float | None = None,
        check: Callable[[T], str | None] | None = None,
        finite: bool = True,
        live: bool = False,
    ) -> None:
        self.type = type_
        self.doc = doc
        self.choices = tuple(choices) if choices is not None else None
        self.min = min
        self.max = max
        self.check = check
        self.finite = finite
        self.live = live
        self.name = ""
        self.default = default

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, instance: Component | None, owner: type) -> Any:
        if instance is None:
            return self
        return instance._attribute_values.get(self.name, self.default)

    def __set__(self, instance: Component, value: Any) -> None:
        instance._attribute_values[self.name] = self.validate(value, instance)

    @property
    def type_name(self) -> str:
        origin = get_origin(self.type)
        if origin in (list, tuple):
            inner = get_args(self.type)[0]
            return f"list of {getattr(inner, '__name__', inner)}"
        return getattr(self.type, "__name__", str(self.type))

    def parse(self, text: str) -> T:
        """Value from the text an application file gives."""
        origin = get_origin(self.type)
        if origin in (list, tuple):
            inner = get_args(self.type)[0]
            items = [self._parse_scalar(inner, item) for item in _split_list(text)]
            return origin(items)
        return self._parse_scalar(self.type, text)

    def _parse_scalar(self, tp: Any, text: str) -> Any:
        if tp is bool:
            return _parse_bool(text)
        if isinstance(tp, type) and issubclass(tp, enum.Enum):
            try:
                return tp[text.strip()]
            except KeyError:
                raise AttributeValueError(
                    f"expected one of {', '.join(m.name for m in tp)}, got {_shown(text)}"
                ) from None
        if tp in (int, float):
            try:
                return tp(text.strip())
            except ValueError:
                raise AttributeValueError(f"expected {'an integer' if tp is int else 'a number'}, got {_shown(text)}") from None
        if tp is str:
            return text
        if tp is Path:
            return Path(text)
        raise AttributeValueError(f"attributes of type {tp!r} cannot be set from text")

    def validate(self, value: Any, component: Component | None = None) -> T:
        """Coerce ``value`` (text is parsed) and check the constraints; raise with a clear message."""
        try:
            value = self._coerce(value)
            self._check_constraints(value)
        except AttributeValueError as error:
            owner = f"{component.name}." if component is not None else ""
            raise AttributeValueError(f"attribute {owner}{self.name} ({self.type_name}): {error}") from None
        return value

    def _coerce(self, value: Any) -> Any:
        if isinstance(value, str) and self.type is not str:
            return self.parse(value)
        origin = get_origin(self.type)
        if origin in (list, tuple):
            inner = get_args(self.type)[0]
            if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
                raise AttributeValueError(f"expected a {self.type_name}, got {_shown(value)}")
            return origin(self._coerce_scalar(inner, item) for item in value)
        return self._coerce_scalar(self.type, value)

    def _coerce_scalar(self, tp: Any, value: Any) -> Any:
        if isinstance(value, str) and tp is not str:
            return self._parse_scalar(tp, value)
        if tp is float and isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        if tp is Path and isinstance(value, str):
            return Path(value)
        if tp is int and isinstance(value, bool):
            raise AttributeValueError(f"expected an integer, got {_shown(value)}")
        if isinstance(value, tp):
            return value
        if tp is int and isinstance(value, float) and value.is_integer():
            return int(value)
        raise AttributeValueError(f"expected {getattr(tp, '__name__', tp)}, got {_shown(value)}")

    def _check_constraints(self, value: Any) -> None:
        scalars = value if isinstance(value, (list, tuple)) else [value]
        for scalar in scalars:
            if self.finite and isinstance(scalar, float) and not math.isfinite(scalar):
                raise AttributeValueError(f"expected a finite number, got {_shown(scalar)}")
            if self.choices is not None and scalar not in self.choices:
                raise AttributeValueError(f"expected one of {', '.join(map(str, self.choices))}, got {_shown(scalar)}")
            if self.min is not None and scalar < self.min:
                raise AttributeValueError(f"expected >= {self.min}, got {_shown(scalar)}")
            if self.max is not None and scalar > self.max:
                raise AttributeValueError(f"expected <= {self.max}, got {_shown(scalar)}")
        if self.check is not None:
            problem = self.check(value)
            if problem:
                raise AttributeValueError(problem)

    def describe(self) -> dict[str, Any]:
        """Declaration summary for docs and ``coco-launch --list``."""
        return {"name": self.name, "type": self.type_name, "default": self.default, "doc": self.doc}


class FileAttribute(Attribute[str]):
    """An attribute naming a file that the component reads whole (a hand trajectory, camera
    intrinsics); empty: no file.

    Why a kind of its own: the name may point anywhere (``/dev/zero``, a FIFO, a folder, a 2 GB
    file), and the run must never be the first to find out. The declaration carries the file's
    limit and what it should be, so that setting the value (from an application file, hence under
    ``--check``, or from code) makes the same checks as the component's read, which goes through
    :func:`~coco_core.files.read_regular_file` with the same limit inside
    :meth:`Component.reading_attribute_file <coco_core.component.Component.reading_attribute_file>`:
    a regular file, at most ``limit`` bytes, that can be opened for reading.
    """

    def __init__(self, default: str, doc: str, *, expected: str, limit: int = DATA_FILE_LIMIT) -> None:
        super().__init__(str, default, doc)
        self.expected = expected
        """What the file should be ("a CSV file time,x,y,z"), for the errors."""
        self.limit = limit

    @property
    def type_name(self) -> str:
        return "file"

    def _check_constraints(self, value: Any) -> None:
        super()._check_constraints(value)
        if value:
            try:
                check_regular_file(value, self.limit)
            except FileReadError as error:
                raise AttributeValueError(f"{error}; expected {self.expected}") from None
