"""The surface expression: how an application file describes an implicit surface in one attribute.

    surface="difference(box(size=[0.2, 0.2, 0.1]), translate([0, 0, 0.05], sphere(0.04)))"

A small functional language, parsed here by a tokenizer and a recursive-descent parser (never
``eval``): calls of the names in :data:`FUNCTIONS` with positional and/or keyword arguments, numbers,
vectors ``[x, y, z]`` and quoted frame names ``'table'``. Metres and radians throughout. A mistake is
reported with its column and a caret under it, and an unknown name lists the valid ones, so that the
file:line the loader adds points at the exact character.

What a parse accepts is bounded, since the file may come from anywhere and the haptic loop computes
with whatever it builds: every number is finite and at most :data:`LARGEST` in magnitude (a
``sphere(1e999)`` would otherwise make every proxy and force NaN), and calls nest at most
:data:`MAX_DEPTH` deep (the parser and the tree's walks recurse once per level, so a deeper one
would end in Python's RecursionError instead of a message).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Callable

from coco_core.errors import SurfaceExpressionError, did_you_mean

from .implicit import (Box, Capsule, Cylinder, Difference, Intersection, Placed, Plane, Sphere, Surface,
                       Torus, Union, pose_from_xyz_rpy)


@dataclass(frozen=True)
class Param:
    name: str
    kind: str
    """``number``, ``vector`` (three numbers), ``surface``, ``surfaces`` (one or more, the rest of the
    positional arguments) or ``text`` (a quoted name)."""
    default: Any = None
    required: bool = True


def _required(name: str, kind: str) -> Param:
    return Param(name, kind)


def _optional(name: str, kind: str, default: Any) -> Param:
    return Param(name, kind, default, required=False)


@dataclass(frozen=True)
class Function:
    params: tuple[Param, ...]
    build: Callable[..., Surface]
    doc: str


FUNCTIONS: dict[str, Function] = {
    "sphere": Function((_required("radius", "number"),), Sphere, "sphere(radius) centred at the origin"),
    "plane": Function((_optional("normal", "vector", (0.0, 0.0, 1.0)), _optional("offset", "number", 0.0)),
                      Plane, "plane(normal=[0,0,1], offset=0): the half-space normal . p <= offset"),
    "box": Function((_required("size", "vector"),), Box, "box(size=[sx, sy, sz]) full extents, centred"),
    "cylinder": Function((_required("radius", "number"), _required("height", "number")), Cylinder,
                         "cylinder(radius, height): capped, along z, centred"),
    "capsule": Function((_required("radius", "number"), _required("height", "number")), Capsule,
                        "capsule(radius, height): segment of length height along z, rounded"),
    "torus": Function((_required("major", "number"), _required("minor", "number")), Torus,
                      "torus(major, minor) around z"),
    "union": Function((_required("surfaces", "surfaces"),), lambda surfaces: Union(surfaces),
                      "union(a, b, ...)"),
    "intersection": Function((_required("surfaces", "surfaces"),), lambda surfaces: Intersection(surfaces),
                             "intersection(a, b, ...)"),
    "difference": Function((_required("base", "surface"), _required("removed", "surfaces")),
                           lambda base, removed: Difference(base, removed), "difference(a, b, ...): a without b, ..."),
    "translate": Function((_required("xyz", "vector"), _required("surface", "surface")),
                          lambda xyz, surface: Placed(surface, pose_from_xyz_rpy(xyz)),
                          "translate([x, y, z], surface)"),
    "rotate": Function((_required("rpy", "vector"), _required("surface", "surface")),
                       lambda rpy, surface: Placed(surface, pose_from_xyz_rpy((0, 0, 0), rpy)),
                       "rotate([roll, pitch, yaw], surface) in radians, about the origin"),
    "pose": Function((_required("xyz", "vector"), _required("rpy", "vector"), _required("surface", "surface")),
                     lambda xyz, rpy, surface: Placed(surface, pose_from_xyz_rpy(xyz, rpy)),
                     "pose([x, y, z], [roll, pitch, yaw], surface)"),
    "frame": Function((_required("name", "text"), _required("surface", "surface")),
                      lambda name, surface: Placed(surface, pose_from_xyz_rpy(), frame=name),
                      "frame('name', surface): placed at a frame of the transformation graph, moved at run time"),
}
"""Every name a surface expression may call."""

LARGEST = 1e4
"""The largest magnitude of a number in an expression: 10 km or 10,000 rad is no haptic scene, and
beyond it squares of lengths lose every digit of a millimetre."""

MAX_DEPTH = 64
"""How deep calls and vectors may nest (a hand-written CSG tree is a few levels deep)."""

PRIMITIVES = ("sphere", "plane", "cylinder", "box", "capsule", "torus")

_TOKEN = re.compile(r"""
    (?P<space>\s+)
  | (?P<number>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)
  | (?P<name>[A-Za-z_][A-Za-z0-9_]*)
  | (?P<text>'[^']*'|"[^"]*")
  | (?P<punct>[()\[\],=])
""", re.VERBOSE)


@dataclass(frozen=True)
class _Token:
    kind: str
    text: str
    column: int
    """0-based offset in the expression."""


def _tokenize(source: str) -> list[_Token]:
    tokens: list[_Token] = []
    position = 0
    while position < len(source):
        match = _TOKEN.match(source, position)
        if match is None:
            raise _error(source, position, f"unexpected character {source[position]!r}")
        kind = match.lastgroup or ""
        if kind != "space":
            tokens.append(_Token(kind, match.group(), position))
        position = match.end()
    tokens.append(_Token("end", "", len(source)))
    return tokens


def _error(source: str, column: int, message: str) -> SurfaceExpressionError:
    return SurfaceExpressionError(f"surface expression, column {column + 1}: {message}\n    {source}\n"
                                  f"    {' ' * column}^")


@dataclass
class _Value:
    kind: str
    """``number``, ``vector``, ``surface`` or ``text``."""
    value: Any
    column: int


class _Parser:
    def __init__(self, source: str) -> None:
        self.source = source
        self.tokens = _tokenize(source)
        self.index = 0
        self.depth = 0

    @property
    def token(self) -> _Token:
        return self.tokens[self.index]

    def fail(self, message: str, token: _Token | None = None) -> SurfaceExpressionError:
        return _error(self.source, (token or self.token).column, message)

    def expect(self, text: str) -> _Token:
        token = self.token
        if token.text != text or token.kind not in ("punct",):
            found = "the end" if token.kind == "end" else repr(token.text)
            raise self.fail(f"expected {text!r}, found {found}")
        self.index += 1
        return token

    def parse(self) -> Surface:
        value = self.value()
        if self.token.kind != "end":
            raise self.fail(f"unexpected {self.token.text!r} after the surface (one surface per attribute: "
                            "combine several with union(...))")
        if value.kind != "surface":
            raise _error(self.source, value.column, f"expected a surface such as {', '.join(PRIMITIVES)}, "
                         f"got a {value.kind}")
        return value.value

    def value(self) -> _Value:
        token = self.token
        if token.kind == "number":
            return _Value("number", self.number(), token.column)
        if token.kind == "text":
            self.index += 1
            return _Value("text", token.text[1:-1], token.column)
        if token.text == "[":
            return self.vector()
        if token.kind == "name":
            if self.depth >= MAX_DEPTH:
                raise self.fail(f"the expression nests deeper than {MAX_DEPTH} calls")
            self.depth += 1
            value = self.call()
            self.depth -= 1
            return value
        found = "the end" if token.kind == "end" else repr(token.text)
        raise self.fail(f"expected a surface ({', '.join(PRIMITIVES)}, or union/intersection/difference/"
                        f"translate/rotate/pose/frame), a number or a vector, found {found}")

    def number(self) -> float:
        """The number token here, refused when it is not finite or larger than :data:`LARGEST`."""
        token = self.token
        number = float(token.text)
        if not math.isfinite(number) or abs(number) > LARGEST:
            raise self.fail(f"number {token.text} is out of range: numbers are metres or radians of at most "
                            f"{LARGEST:g} in magnitude")
        self.index += 1
        return number

    def vector(self) -> _Value:
        start = self.expect("[")
        items: list[float] = []
        while True:
            token = self.token
            if token.kind != "number":
                found = "the end" if token.kind == "end" else repr(token.text)
                raise self.fail(f"expected a number in the vector, found {found}")
            items.append(self.number())
            if self.token.text == "]":
                self.index += 1
                break
            self.expect(",")
        if len(items) != 3:
            raise _error(self.source, start.column, f"a vector has 3 numbers [x, y, z], this one has {len(items)}")
        return _Value("vector", tuple(items), start.column)

    def call(self) -> _Value:
        name_token = self.token
        function = FUNCTIONS.get(name_token.text)
        if function is None:
            raise self.fail(f"unknown surface function {name_token.text!r}; "
                            f"{did_you_mean(name_token.text, FUNCTIONS)}")
        self.index += 1
        self.expect("(")
        positional: list[_Value] = []
        keywords: dict[str, _Value] = {}
        if self.token.text != ")":
            while True:
                if self.token.kind == "name" and self.tokens[self.index + 1].text == "=":
                    key = self.token
                    self.index += 2
                    if key.text in keywords:
                        raise self.fail(f"argument {key.text!r} given twice", key)
                    keywords[key.text] = self.value()
                    keywords[key.text].column = key.column
                else:
                    if keywords:
                        raise self.fail("a positional argument cannot follow a keyword argument")
                    positional.append(self.value())
                if self.token.text == ")":
                    break
                if self.token.text != ",":
                    found = "the end" if self.token.kind == "end" else repr(self.token.text)
                    raise self.fail(f"expected ',' or ')' in the arguments of {name_token.text}, found {found}")
                self.index += 1
        self.expect(")")
        arguments = self.bind(name_token, function, positional, keywords)
        try:
            surface = function.build(**arguments)
        except ValueError as error:
            raise self.fail(f"{name_token.text}: {error}", name_token) from None
        return _Value("surface", surface, name_token.column)

    def bind(self, name: _Token, function: Function, positional: list[_Value],
             keywords: dict[str, _Value]) -> dict[str, Any]:
        signature = f"{name.text}: {function.doc}"
        arguments: dict[str, Any] = {}
        remaining = list(positional)
        for param in function.params:
            if param.kind == "surfaces":
                given = remaining
                remaining = []
                if param.name in keywords:
                    raise self.fail(f"{name.text}: surfaces are given by position ({signature})", name)
                if not given:
                    raise self.fail(f"{name.text} needs at least one surface for {param.name!r} ({signature})", name)
                arguments[param.name] = tuple(self.check(name, param, value, signature) for value in given)
                continue
            if remaining:
                value = remaining.pop(0)
                if param.name in keywords:
                    raise self.fail(f"{name.text}: {param.name!r} given by position and by name", name)
            elif param.name in keywords:
                value = keywords[param.name]
            elif param.required:
                raise self.fail(f"{name.text} needs {param.name!r} ({signature})", name)
            else:
                arguments[param.name] = param.default
                continue
            arguments[param.name] = self.check(name, param, value, signature)
        if remaining:
            raise _error(self.source, remaining[0].column, f"{name.text} takes {len(function.params)} "
                         f"argument(s), got {len(positional)} ({signature})")
        unknown = sorted(set(keywords) - {param.name for param in function.params})
        if unknown:
            raise _error(self.source, keywords[unknown[0]].column,
                         f"{name.text} has no argument {unknown[0]!r}; "
                         f"{did_you_mean(unknown[0], [p.name for p in function.params])}")
        return arguments

    def check(self, name: _Token, param: Param, value: _Value, signature: str) -> Any:
        wanted = "surface" if param.kind == "surfaces" else param.kind
        if value.kind != wanted:
            raise _error(self.source, value.column,
                         f"{name.text}: {param.name!r} must be a {wanted}, got a {value.kind} ({signature})")
        return value.value


def parse_surface(source: str) -> Surface:
    """The surface an expression describes; :class:`SurfaceExpressionError` when it is wrong."""
    if not source.strip():
        raise SurfaceExpressionError("surface expression is empty; expected e.g. sphere(0.05) "
                                     f"(primitives: {', '.join(PRIMITIVES)})")
    return _Parser(source).parse()


def surface_problem(source: str) -> str | None:
    """For :class:`~coco_core.attributes.Attribute`'s ``check``: the error text, or None when valid."""
    if not source.strip():
        return None
    try:
        parse_surface(source)
    except SurfaceExpressionError as error:
        return str(error)
    return None


def frames_of(surface: Surface) -> list[Placed]:
    """The placements driven by frames of the transformation graph, in the tree's order."""
    return [node for node in surface.walk() if isinstance(node, Placed) and node.frame]

